"""The declared layers (pipeline/layers.py) hold for every import in the package.

Every import counts: module level or inside a function, relative or absolute,
``importlib.import_module("pipeline....")`` and ``"pipeline.x.y:function"`` registry strings.
A part (top-level module or subpackage) imports only from lower layers, so no cycle runs
between parts; ``report/`` reaches no physics engine, not even through a lazy import.
"""

from __future__ import annotations

import ast
import functools
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

import pipeline
from pipeline.layers import LAYERS, PHYSICS_ENGINES, REPORT_MAY_REACH, layer_of

PACKAGE = Path(pipeline.__file__).parent
# a string naming one of our modules, optionally with ":attribute" (a registry entry)
MODULE_STRING = re.compile(r"^pipeline(\.\w+)+(:\w+)?$")


def _modules(package: Path) -> dict[str, Path]:
    """Module name -> file, for every module under ``package`` (a folder named pipeline)."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        parts = ("pipeline", *path.relative_to(package).with_suffix("").parts)
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


@functools.cache
def _statements(text: str) -> tuple[tuple[ast.AST, bool], ...]:
    """Every import statement and string constant of a source, with whether it runs only
    later (inside a function, or under ``if TYPE_CHECKING``) rather than at load time."""
    out: list[tuple[ast.AST, bool]] = []

    def visit(node: ast.AST, late: bool) -> None:
        if isinstance(node, ast.Import | ast.ImportFrom):
            out.append((node, late))
        elif isinstance(node, ast.Constant):  # a module named in a string loads when used
            out.append((node, True))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda) or (
            isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
        ):
            late = True
        for child in ast.iter_child_nodes(node):
            visit(child, late)

    visit(ast.parse(text), False)
    return tuple(out)


def _imports(
    name: str, path: Path, modules: dict[str, Path], *, late: bool = True
) -> Iterator[tuple[str, int]]:
    """(module of ours that ``name`` imports, line), for every import anywhere in its file
    (only those run at load time unless ``late``), plus the packages above it (importing
    a.b.c runs a/__init__ and a/b/__init__)."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    for node, is_late in _statements(path.read_text(encoding="utf-8")):
        if is_late and not late:
            continue
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the module's package, up level - 1
                up = package[: len(package) - (node.level - 1)]
                base = ".".join([*up, *([base] if base else [])])
            targets = [
                f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names
            ]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            # importlib.import_module("pipeline.x"), resources.files(...), "pipeline.x:f"
            targets = [node.value.partition(":")[0]] if MODULE_STRING.match(node.value) else []
        else:
            continue
        for target in targets:
            while target and target not in modules:  # import a.b.c: the longest of ours
                target = target.rpartition(".")[0]
            while target.count("."):
                yield target, getattr(node, "lineno", 0)
                target = target.rpartition(".")[0]


def _external(path: Path, *, late: bool) -> set[str]:
    """Top-level names of what a file imports (only at load time unless ``late``)."""
    out = set()
    for node, is_late in _statements(path.read_text(encoding="utf-8")):
        if is_late and not late:
            continue
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            out.add(node.module.split(".")[0])
    return out


def _part(module: str) -> str | None:
    """``pipeline.robots.spec`` -> ``robots``; the root package itself -> None."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def part_edges(package: Path) -> dict[tuple[str, str], list[str]]:
    """(importing part, imported part) -> where, as ``pipeline/x/y.py:line``."""
    modules = _modules(package)
    edges: dict[tuple[str, str], list[str]] = {}
    for name, path in modules.items():
        src = _part(name)
        for target, line in _imports(name, path, modules):
            dst = _part(target)
            if src and dst and src != dst:
                where = f"{path.relative_to(package.parent).as_posix()}:{line} -> {target}"
                edges.setdefault((src, dst), []).append(where)
    return edges


def upward(edges: dict[tuple[str, str], list[str]], layers: dict[str, int]) -> list[str]:
    """Every import into the same or a higher layer (or of an undeclared part), with where."""
    bad = []
    for (src, dst), where in sorted(edges.items()):
        if src not in layers or dst not in layers or layers[dst] >= layers[src]:
            bad.append(f"{src} -> {dst} ({len(where)}x, e.g. {where[0]})")
    return bad


def cycles(edges: dict[tuple[str, str], list[str]]) -> list[set[str]]:
    """Parts that import each other, directly or around a loop (strongly connected sets)."""
    graph: dict[str, set[str]] = {}
    for src, dst in edges:
        graph.setdefault(src, set()).add(dst)
        graph.setdefault(dst, set())

    def reach(start: str) -> set[str]:
        seen, todo = set(), [start]
        while todo:
            for nxt in graph[todo.pop()] - seen:
                seen.add(nxt)
                todo.append(nxt)
        return seen

    reachable = {p: reach(p) for p in graph}
    found: list[set[str]] = []
    for p in sorted(graph):
        loop = {q for q in reachable[p] if p in reachable[q]} | {p}
        if len(loop) > 1 and loop not in found:
            found.append(loop)
    return found


def physics_paths(package: Path, start: str, allowed: frozenset[str]) -> list[str]:
    """Import chains from ``start``'s modules to a physics engine: ``start``'s own imports
    wherever they are (functions too), and what each module they reach loads at import time
    (not followed into the ``allowed`` parts)."""
    modules = _modules(package)
    parent: dict[str, str | None] = {m: None for m in modules if _part(m) == start}
    todo = list(parent)
    out = []
    while todo:
        name = todo.pop()
        own = _part(name) == start
        for engine in sorted(_external(modules[name], late=own) & set(PHYSICS_ENGINES)):
            chain, at = [engine], name
            while at is not None:
                chain.append(at)
                at = parent[at]
            out.append(" <- ".join(chain))
        for target, _ in _imports(name, modules[name], modules, late=own):
            if target not in parent and _part(target) not in allowed:
                parent[target] = name
                todo.append(target)
    return out


def test_every_part_of_the_package_is_in_exactly_one_layer():
    declared = [p for _, parts in LAYERS for p in parts]
    assert len(declared) == len(set(declared)), f"declared twice: {declared}"
    present = {_part(m) for m in _modules(PACKAGE)} - {None}
    assert present == set(declared), (
        f"in no layer: {sorted(present - set(declared))}; "
        f"declared but absent: {sorted(set(declared) - present)}"
    )


def test_no_import_goes_to_the_same_or_a_higher_layer():
    edges = part_edges(PACKAGE)
    assert ("stages", "experiment") in edges, "the walk found no imports: it is broken"
    bad = upward(edges, layer_of())
    assert not bad, "imports against pipeline/layers.py: " + "; ".join(bad)


def test_no_import_cycle_runs_between_parts_of_the_package():
    loops = cycles(part_edges(PACKAGE))
    assert not loops, f"parts importing each other: {loops}"


def test_report_reaches_no_physics_engine_even_lazily():
    paths = physics_paths(PACKAGE, "report", REPORT_MAY_REACH)
    assert not paths, "report/ loads a physics engine: " + "; ".join(paths)


@pytest.mark.skipif(bool(REPORT_MAY_REACH), reason=f"report/ still reaches {REPORT_MAY_REACH}")
def test_importing_every_report_module_loads_no_physics_engine():
    """The same, by a real import in a fresh interpreter."""
    names = sorted(m for m in _modules(PACKAGE) if _part(m) == "report")
    code = (
        "import sys; "
        + "".join(f"import {m}; " for m in names)
        + f"print(sorted(set({list(PHYSICS_ENGINES)!r}) & set(sys.modules)))"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == "[]", f"importing report/ loaded {run.stdout.strip()}"


def test_executors_run_episodes_without_the_record_stage():
    modules = _modules(PACKAGE)
    for name in [m for m in modules if m.startswith("pipeline.stages.executors")]:
        imported = {t for t, _ in _imports(name, modules[name], modules)}
        assert "pipeline.stages.record" not in imported, name


# the checker itself: an upward import added to a copy of the package is caught


@pytest.fixture(scope="module")
def package_copy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    dst = tmp_path_factory.mktemp("tree") / "pipeline"
    shutil.copytree(PACKAGE, dst, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    return dst


@pytest.mark.parametrize(
    "statement",
    [
        "from pipeline.stages import record",
        "import pipeline.stages.record",
        "from ..stages import record",
        "importlib.import_module('pipeline.stages.record')",
        "LOADER = 'pipeline.stages.record:record_scenario'",
    ],
    ids=["from", "import", "relative", "import_module", "registry-string"],
)
def test_an_upward_import_inside_a_function_fails_the_check(package_copy: Path, statement: str):
    spec = package_copy / "robots" / "spec.py"
    original = spec.read_text(encoding="utf-8")
    try:
        spec.write_text(original + f"\n\ndef _late():\n    {statement}\n", encoding="utf-8")
        edges = part_edges(package_copy)
        bad = upward(edges, layer_of())
        assert any(b.startswith("robots -> stages") and "robots/spec.py" in b for b in bad), bad
        assert any({"robots", "stages"} <= loop for loop in cycles(edges))
    finally:
        spec.write_text(original, encoding="utf-8")
    assert not upward(part_edges(package_copy), layer_of())


@pytest.mark.parametrize(
    ("where", "added", "chain"),
    [
        ("report/md.py", "def _late():\n    import mujoco\n", "mujoco <- pipeline.report.md"),
        ("analysis/catalog.py", "import pinocchio\n", "pinocchio <- pipeline.analysis.catalog"),
    ],
    ids=["lazy-in-report", "load-time-below-report"],
)
def test_a_physics_import_reached_from_report_fails_the_check(
    package_copy: Path, where: str, added: str, chain: str
):
    target = package_copy / where
    original = target.read_text(encoding="utf-8")
    try:
        target.write_text(original + "\n\n" + added, encoding="utf-8")
        paths = physics_paths(package_copy, "report", REPORT_MAY_REACH)
        assert any(p.startswith(chain) and p.count("pipeline.report.") == 1 for p in paths), paths
    finally:
        target.write_text(original, encoding="utf-8")
    assert not physics_paths(package_copy, "report", REPORT_MAY_REACH)


def test_a_new_part_outside_every_layer_is_an_upward_import():
    edges = {("stages", "newpart"): ["x.py:1"], ("robots", "errors"): ["y.py:1"]}
    assert upward(edges, layer_of()) == ["stages -> newpart (1x, e.g. x.py:1)"]
