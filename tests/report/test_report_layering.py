"""The report formats, the analysis decides: what report/ may import, and the metric
definitions said once (the catalog) and shown everywhere."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import pipeline
from pipeline.analysis import catalog
from pipeline.report.definitions import definitions_section

PACKAGE = Path(pipeline.__file__).parent
DOCS = PACKAGE.parent / "docs" / "report.md"
# Physics engines and rigid-body models are analysis (or simulation), never formatting.
FORBIDDEN = ("pinocchio", "mujoco")


def _imported_modules(path: Path) -> set[str]:
    """Every module a file imports, at any depth (inside functions too)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module is not None and node.level == 0:
            found.add(node.module)
    return found


@pytest.mark.parametrize("path", sorted((PACKAGE / "report").rglob("*.py")), ids=lambda p: p.name)
def test_report_modules_import_no_physics_engine(path: Path) -> None:
    bad = sorted(m for m in _imported_modules(path) if m.split(".")[0] in FORBIDDEN)
    assert not bad, f"{path.relative_to(PACKAGE.parent)} imports {bad}: that is analysis"


def test_the_import_check_sees_an_import_inside_a_function(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text("def f():\n    import pinocchio as pin\n    from mujoco import MjModel\n")
    assert {"pinocchio", "mujoco"} <= _imported_modules(src)


@pytest.mark.parametrize(
    "metric", [m for m in catalog.METRICS if m.definition], ids=lambda m: m.name
)
def test_docs_hold_every_catalog_definition(metric: catalog.Metric) -> None:
    assert metric.definition in DOCS.read_text(encoding="utf-8"), (
        f"docs/report.md lacks the catalog definition of {metric.name}: {metric.definition!r}"
    )


def test_report_definitions_render_every_catalog_definition_once() -> None:
    text = "\n".join(definitions_section())
    for m in catalog.METRICS:
        if m.definition:
            assert text.count(m.definition) == 1, m.name


def test_every_metric_shown_in_tables_has_a_definition() -> None:
    missing = [m.name for m in catalog.METRICS if m.in_tables and not m.definition]
    assert not missing
