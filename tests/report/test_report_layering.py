"""The metric definitions said once (the catalog) and shown everywhere. What report/ may
import is tests/test_layers.py's (no physics engine, not even through another part)."""

from __future__ import annotations

from pathlib import Path

import pytest

import pipeline
from pipeline.analysis import catalog
from pipeline.report.definitions import definitions_section

PACKAGE = Path(pipeline.__file__).parent
DOCS = PACKAGE.parent / "docs" / "report.md"


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
