"""Runtime dependencies are what ``pipeline/`` imports: no more, no fewer."""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# runtime dependencies used as programs, not imported
TOOLS = {"dvc": "the stage graph runs through `dvc repro` (make demo)"}
# modules whose distribution importlib.metadata cannot name (installed outside site-packages)
OWNERS = {"pinocchio": ["pin"]}


def _dist(requirement: str) -> str:
    name = re.match(r"[A-Za-z0-9_.-]+", requirement)
    assert name is not None, requirement
    return re.sub(r"[-_.]+", "-", name.group()).lower()


def _imported_modules() -> dict[str, set[str]]:
    """Third-party modules ``pipeline/`` imports -> the distributions that may provide them."""
    modules: set[str] = set()
    for path in (REPO / "pipeline").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                modules.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules.add(node.module.split(".")[0])
    third_party = modules - set(sys.stdlib_module_names) - {"pipeline"}
    owners = {**packages_distributions(), **OWNERS}
    return {m: {_dist(d) for d in owners.get(m, [m])} for m in third_party}


def test_runtime_dependencies_are_what_the_package_imports() -> None:
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    runtime = {_dist(r) for r in project["dependencies"]}
    extras = {_dist(r) for reqs in project["optional-dependencies"].values() for r in reqs}
    imported = _imported_modules()
    undeclared = sorted(m for m, dists in imported.items() if not dists & (runtime | extras))
    assert undeclared == [], "imported by pipeline/ but not a declared dependency"
    provided = set().union(*imported.values())
    assert sorted(runtime - provided - set(TOOLS)) == [], "declared but pipeline/ never imports it"
