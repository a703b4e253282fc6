"""The suite runs on two pytest-xdist workers (`make test`): what must not run side by side
is marked so (tests/conftest.py sends each xdist group to one worker)."""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def _needs_real_ray(func: ast.FunctionDef) -> bool:
    """The test calls ``pytest.importorskip("ray")``: it starts a real local Ray instance."""
    for node in ast.walk(func):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "importorskip"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and node.args[0].value == "ray"
        ):
            return True
    return False


def _groups(func: ast.FunctionDef) -> set[str]:
    out = set()
    for deco in func.decorator_list:
        if (
            isinstance(deco, ast.Call)
            and isinstance(deco.func, ast.Attribute)
            and deco.func.attr == "xdist_group"
            and deco.args
            and isinstance(deco.args[0], ast.Constant)
        ):
            out.add(str(deco.args[0].value))
    return out


def test_every_test_that_starts_ray_is_in_the_ray_group() -> None:
    # two local Ray instances at once on 2 cores would each wait on the other's start-up
    found, unmarked = [], []
    for path in sorted(TESTS.rglob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.FunctionDef)
                and node.name.startswith("test_")
                and _needs_real_ray(node)
            ):
                name = f"{path.relative_to(TESTS)}::{node.name}"
                found.append(name)
                if "ray" not in _groups(node):
                    unmarked.append(name)
    assert len(found) >= 3, found  # the scan sees the Ray tests there are
    assert unmarked == [], f'add @pytest.mark.xdist_group("ray") to {unmarked}'
