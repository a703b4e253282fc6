"""One metric table drives every output; recordings of a single controller report."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.analysis import catalog
from pipeline.errors import ReportError
from pipeline.stages.report import run_report
from tests.analysis.bagfactory import paper_like, write_bag


def _write(root: Path, controllers: tuple[str, ...], seeds: tuple[int, ...] = (0,)) -> Path:
    rec = root / "recordings"
    rec.mkdir()
    for c in controllers:
        for s in seeds:
            write_bag(
                rec,
                paper_like(f"p-{c}-{s}", c, duration_s=0.4, motion_end_s=0.3, seed=s),
            )
    return rec


def test_single_controller_reports_without_reductions(tmp_path: Path) -> None:
    rec = _write(tmp_path, ("ctc",), seeds=(0, 1))
    result = run_report(recordings_dir=rec, out_dir=tmp_path / "reports", baseline="pid")
    text = (tmp_path / "reports" / "report.md").read_text(encoding="utf-8")
    doc = json.loads((tmp_path / "reports" / "metrics.json").read_text(encoding="utf-8"))
    assert "one controller (**ctc**): nothing to compare" in text
    assert " vs " not in text.split("## Versus the paper")[0]
    assert doc["comparisons"] == []
    assert doc["headline"] == {}
    assert set(result.summary["controller"].to_list()) == {"ctc"}


def test_two_controllers_without_the_baseline_still_fail(tmp_path: Path) -> None:
    rec = _write(tmp_path, ("ctc", "ctc_pid"))
    with pytest.raises(ReportError, match="unknown baseline controller 'pid'"):
        run_report(recordings_dir=rec, out_dir=tmp_path / "reports", baseline="pid")


def test_every_catalog_metric_reaches_metrics_json_and_the_report(tmp_path: Path) -> None:
    rec = _write(tmp_path, ("pid", "ctc"))
    run_report(recordings_dir=rec, out_dir=tmp_path / "reports", baseline="pid")
    doc = json.loads((tmp_path / "reports" / "metrics.json").read_text(encoding="utf-8"))
    text = (tmp_path / "reports" / "report.md").read_text(encoding="utf-8")
    joints = doc["episodes"]["p-ctc-0"]["joints"]
    for name in ("shoulder_pan_joint", catalog.TCP_JOINT):
        assert set(joints[name]) == {m.name for m in catalog.METRICS if m.applies_to(name)}
    assert doc["parameters"]["metric_units"] == {m.name: m.unit for m in catalog.METRICS}
    for m in catalog.METRICS:
        if m.in_tables and m.space == "joint":
            assert f"#### {m.heading}" in text, m.name
        elif m.space == "task":  # one task-space table, a row per metric
            assert f"| {m.heading} |" in text, m.name
    for name in ("shoulder_pan_joint", catalog.TCP_JOINT):
        compared = doc["comparisons"][0]["joints"][name]
        assert set(compared) == {
            f"{m}_reduction_pct"
            for m in catalog.COMPARED_METRICS
            if catalog.metric(m).applies_to(name)
        }


def test_catalog_names_are_unique_and_formats_valid() -> None:
    names = [m.name for m in catalog.METRICS]
    assert len(names) == len(set(names))
    for m in catalog.METRICS:
        format(1.5, m.fmt)  # a valid format spec
        assert m.frame in ("controller_state", "joint_states", "tcp")
