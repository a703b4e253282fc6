"""What `pipeline report` writes: links, metrics.json, CSVs, the .rrd."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import polars as pl
import pytest

from pipeline.report import entities as ent
from pipeline.report import paper
from pipeline.stages.report import ReportResult, run_report
from tests.analysis.bagfactory import paper_like, write_bag

RERUN = Path(sys.executable).with_name("rerun")


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> ReportResult:
    root = tmp_path_factory.mktemp("rep")
    write_bag(root / "recordings", paper_like("pid_paper", "pid", error_scale=3.3e-3))
    write_bag(root / "recordings", paper_like("ctc_paper", "ctc", error_scale=1.8e-3))
    diverged = paper_like("lqr_paper", "lqr", duration_s=1.0, error_scale=0.5)
    diverged.status, diverged.reason = "diverged", "joint velocity above 50 rad/s at t = 0.9 s"
    write_bag(root / "recordings", diverged)
    return run_report(recordings_dir=root / "recordings", out_dir=root / "reports")


def test_every_image_the_report_links_exists(report: ReportResult) -> None:
    text = (report.out_dir / "report.md").read_text(encoding="utf-8")
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert len(links) == 5
    for link in links:
        assert not Path(link).is_absolute()
        assert (report.out_dir / link).is_file(), link
    for link in re.findall(r"(?<!!)\[[^\]]*\]\(([^)]+)\)", text):
        assert (report.out_dir / link).is_file(), link


def test_metrics_json_has_the_stable_keys(report: ReportResult) -> None:
    doc = json.loads((report.out_dir / "metrics.json").read_text(encoding="utf-8"))
    assert set(doc["episodes"]) == {"pid_paper", "ctc_paper", "lqr_paper"}
    assert doc["episodes"]["lqr_paper"]["status"] == "diverged"
    ep = doc["episodes"]["ctc_paper"]
    assert (ep["controller"], ep["scenario"], ep["robot"]) == ("ctc", "paper", "ur5")
    joint = ep["joints"]["shoulder_pan_joint"]
    for key in (
        "max_abs_error",
        "rms_error",
        "final_error",
        "settling_time",
        "peak_velocity",
        "rms_effort",
        "saturation_fraction",
    ):
        assert key in joint
    assert len(ep["recording"]["sha256"]) == 64
    (cmp,) = doc["comparisons"]
    assert (cmp["scenario"], cmp["baseline"], cmp["candidate"]) == (
        "paper",
        "pid_paper",
        "ctc_paper",
    )
    red = cmp["joints"]["shoulder_pan_joint"]["max_abs_error_reduction_pct"]
    assert red == pytest.approx((3.3 - 1.8) / 3.3 * 100, rel=1e-3)


def test_series_csvs_are_long_form(report: ReportResult) -> None:
    for name in ("errors.csv", "velocities.csv"):
        frame = pl.read_csv(report.out_dir / "plots" / name)
        assert frame.columns == ["time_s", "episode", "joint", "value"]
        assert set(frame.get_column("episode").unique()) == {"pid_paper", "ctc_paper", "lqr_paper"}


def test_report_puts_our_numbers_beside_the_paper_with_both_formulas(
    report: ReportResult,
) -> None:
    text = (report.out_dir / "report.md").read_text(encoding="utf-8")
    section = text.split("## Versus the paper", 1)[1]
    assert "(PID − CTC) / PID" in section and "(PID − CTC) / CTC" in section
    assert f"{paper.PAPER_JOINT1_MAX_ERROR_RAD['pid']:.3e}" in section
    assert "47.4 %" in section and "95.1 %" in section
    assert "-2.30" in section
    # Every recording is listed with its SHA-256.
    doc = json.loads((report.out_dir / "metrics.json").read_text(encoding="utf-8"))
    for ep in doc["episodes"].values():
        assert ep["recording"]["sha256"] in text


def test_rrd_passes_rerun_verify(report: ReportResult) -> None:
    proc = subprocess.run(
        [str(RERUN), "rrd", "verify", str(report.out_dir / "recording.rrd")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr


def test_rrd_holds_the_series_and_arm_entities(report: ReportResult) -> None:
    proc = subprocess.run(
        [str(RERUN), "rrd", "stats", str(report.out_dir / "recording.rrd")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    printed = subprocess.run(
        [str(RERUN), "rrd", "print", str(report.out_dir / "recording.rrd")],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    for path in (
        ent.series_path("shoulder_pan_joint", "error", "ctc_paper"),
        ent.reference_path("wrist_3_joint", "paper"),
        ent.arm_path("pid_paper"),
        ent.ee_path_path("ctc_paper"),
    ):
        assert path in printed, path


def test_metrics_json_is_byte_identical_across_runs(report: ReportResult, tmp_path: Path) -> None:
    recordings = report.out_dir.parent / "recordings"
    copy = tmp_path / "recordings"
    shutil.copytree(recordings, copy)
    again = run_report(recordings_dir=copy, out_dir=tmp_path / "reports")
    first = (report.out_dir / "metrics.json").read_bytes()
    assert (again.out_dir / "metrics.json").read_bytes() == first
    assert (again.out_dir / "plots" / "errors.csv").read_bytes() == (
        report.out_dir / "plots" / "errors.csv"
    ).read_bytes()


def test_diverged_episode_is_listed_with_its_reason_and_not_compared(
    report: ReportResult,
) -> None:
    text = (report.out_dir / "report.md").read_text(encoding="utf-8")
    failed = text.split("### Failed episodes", 1)[1].split("##", 1)[0]
    assert "lqr_paper" in failed and "joint velocity above 50 rad/s at t = 0.9 s" in failed
    doc = json.loads((report.out_dir / "metrics.json").read_text(encoding="utf-8"))
    assert all(c["candidate"] != "lqr_paper" for c in doc["comparisons"])
