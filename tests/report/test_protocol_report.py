"""The report applies the protocol: true state where recorded, metrics from the motion start,
the paper only where a scenario says it is the paper's, ratios for meaningless percentages.

Bags are written by an independent writer (``mcap_ros2`` through ``bagfactory``); expected
numbers are computed here with numpy from the arrays written into them.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.stages.report import ReportResult, run_report
from tests.analysis.bagfactory import UR5_JOINTS, Episode, paper_like, write_bag


def _report(tmp_path: Path, episodes: list[Episode], name: str = "r") -> ReportResult:
    root = tmp_path / name
    for ep in episodes:
        write_bag(root / "recordings", ep)
    return run_report(recordings_dir=root / "recordings", out_dir=root / "reports")


def _doc(report: ReportResult) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((report.out_dir / "metrics.json").read_text())
    return doc


def _text(report: ReportResult) -> str:
    return (report.out_dir / "report.md").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def truth_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[ReportResult, Episode]:
    """A simulated PID episode with sensor noise and its true state, beside a CTC one
    without ground truth (as a real robot's bag)."""
    pid = paper_like("sim-pid", "pid", duration_s=0.6, motion_end_s=0.4, error_scale=1e-3)
    rng = np.random.default_rng(1)
    pid.q_true = pid.q.copy()
    pid.q = pid.q_true + rng.normal(0.0, 5e-3, pid.q.shape)  # noise 5x the tracking error
    ctc = paper_like("robot-ctc", "ctc", duration_s=0.6, motion_end_s=0.4, error_scale=5e-4)
    return _report(tmp_path_factory.mktemp("truth"), [pid, ctc]), pid


def test_error_comes_from_the_true_state_when_the_recording_has_it(truth_report) -> None:
    report, pid = truth_report
    doc = _doc(report)
    for k, joint in enumerate(UR5_JOINTS[:5]):
        got = doc["episodes"]["sim-pid"]["joints"][joint]["max_abs_error"]
        true = np.abs(pid.q_ref[:, k] - pid.q_true[:, k]).max()
        measured = np.abs(pid.q_ref[:, k] - pid.q[:, k]).max()
        assert got == pytest.approx(true, rel=1e-8)
        assert measured > 3 * true  # the noise would have dominated
    rows = [line for line in _text(report).splitlines() if line.startswith("| sim-pid ")]
    assert "true plant state" in rows[0]
    rows = [line for line in _text(report).splitlines() if line.startswith("| robot-ctc ")]
    assert "measured" in rows[0]


def test_metrics_count_from_the_motion_start_not_the_pre_roll(tmp_path: Path) -> None:
    ep = paper_like("pre-pid", "pid", duration_s=0.8, motion_end_s=0.6, error_scale=1e-3)
    ep.motion_start_s = 0.2
    t = ep.stamp_ns / 1e9
    before = t < 0.2 - 1e-9
    ep.q = ep.q.copy()
    ep.q[before] += 0.5  # a cold-start transient the protocol must not count
    doc = _doc(_report(tmp_path, [ep]))
    for k, joint in enumerate(UR5_JOINTS[:5]):
        got = doc["episodes"]["pre-pid"]["joints"][joint]["max_abs_error"]
        expected = np.abs(ep.q_ref[~before, k] - ep.q[~before, k]).max()
        assert got == pytest.approx(expected, rel=1e-8)
        assert got < 0.1


def test_versus_the_paper_only_for_scenarios_marked_as_the_papers(tmp_path: Path) -> None:
    eps = [
        paper_like(f"{sc}-{c}", c, duration_s=0.6, motion_end_s=0.4, error_scale=e, scenario=sc)
        for sc in ("paper", "other")
        for c, e in (("pid", 2e-3), ("ctc", 1e-3))
    ]
    text = _text(_report(tmp_path, eps, "marked"))
    assert "## Versus the paper: `paper`" in text
    assert "## Versus the paper: `other`" not in text
    for ep in eps:
        ep.reproduces_paper = False
    text = _text(_report(tmp_path, eps, "unmarked"))
    assert "No scenario here is marked as the paper's experiment" in text


def test_a_candidate_many_times_worse_is_shown_as_a_ratio(tmp_path: Path) -> None:
    pid = paper_like("x-pid", "pid", duration_s=0.6, motion_end_s=0.4, error_scale=1e-4)
    ctc = paper_like("x-ctc", "ctc", duration_s=0.6, motion_end_s=0.4, error_scale=3.7e-3)
    text = _text(_report(tmp_path, [pid, ctc]))
    assert "× the baseline's" in text
    assert not any(f"-{n}" in text and " %" in text for n in ("3600.0 %", "3500.0 %"))


def test_settings_breaking_the_contract_are_flagged_not_trusted(tmp_path: Path) -> None:
    from tests.analysis.bagfactory import default_settings

    ep = paper_like("odd-pid", "pid", duration_s=0.6, motion_end_s=0.4, error_scale=1e-3)
    settings = default_settings(ep)
    settings["planner"]["trajectory_duration_s"] = -1.0
    ep.settings = settings
    report = _report(tmp_path, [ep])
    (note,) = [n for e, n in report.warnings if e == "odd-pid" and "contract" in n]
    assert "planner.trajectory_duration_s: expected a finite number >= 0, got -1.0" in note
    doc = _doc(report)
    # the motion end falls back to the planned trajectory, never a negative time
    assert doc["episodes"]["odd-pid"]["motion_end_s"] == pytest.approx(0.4)
