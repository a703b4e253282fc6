"""What `pipeline report` writes: links, metrics.json, CSVs, the .rrd."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from pipeline.analysis import paper_claims as paper
from pipeline.report import entities as ent
from pipeline.stages.report import ReportResult, run_report
from tests.analysis.bagfactory import UR5_JOINTS, paper_like, write_bag

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
    assert len(links) == 6  # the paper's Figs. 5-8, efforts, TCP errors
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
        assert frame.columns == ["time_s", "controller", "episode", "joint", "value"]
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


# --- our numbers in report.md, checked against numpy on the arrays written ---------------------


def _cells(line: str) -> list[str]:
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line)[1:-1]]


def _table_after(text: str, heading: str) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the first Markdown table after ``heading``."""
    block = text.split(heading, 1)[1].lstrip("\n")
    lines = []
    for line in block.splitlines():
        if not line.startswith("|"):
            if lines:
                break
            continue
        lines.append(line)
    return _cells(lines[0]), [_cells(line) for line in lines[2:]]


def _fixture_episodes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(error, time) per controller, rebuilt from the fixture's deterministic generator."""
    out = {}
    for name, ctrl, scale, duration in (
        ("pid_paper", "pid", 3.3e-3, 3.0),
        ("ctc_paper", "ctc", 1.8e-3, 3.0),
        ("lqr_paper", "lqr", 0.5, 1.0),
    ):
        ep = paper_like(name, ctrl, duration_s=duration, error_scale=scale)
        out[ctrl] = (ep.q_ref - ep.q, ep.stamp_ns / 1e9)
    return out


def test_report_tables_hold_the_numpy_values_of_each_controller(report: ReportResult) -> None:
    text = (report.out_dir / "report.md").read_text(encoding="utf-8")
    section = text.split("## Scenario `paper`", 1)[1]
    eps = _fixture_episodes()
    final_window = {c: t >= t[-1] - 0.5 - 1e-9 for c, (_, t) in eps.items()}
    expected = {
        "#### Max |error| [rad]": {c: np.abs(e).max(axis=0) for c, (e, _) in eps.items()},
        "#### RMS error [rad]": {c: np.sqrt(np.mean(e**2, axis=0)) for c, (e, _) in eps.items()},
        "#### Error at the target": {
            c: np.abs(e[final_window[c]]).mean(axis=0) for c, (e, _) in eps.items() if c != "lqr"
        },
    }
    for heading, per_controller in expected.items():
        header, rows = _table_after(section, heading)
        assert len(rows) == 6
        for k, row in enumerate(rows):
            for controller, values in per_controller.items():
                column = next(i for i, h in enumerate(header) if h.split(" ")[0] == controller)
                assert float(row[column]) == pytest.approx(values[k], rel=6e-4, abs=1e-12), (
                    heading,
                    controller,
                    k,
                )
            reduction = header.index("ctc vs pid")
            pid, ctc = per_controller["pid"][k], per_controller["ctc"][k]
            if abs(pid) >= 1e-9:
                assert row[reduction] == f"{(pid - ctc) / pid * 100:.1f} %"
            else:
                assert row[reduction].startswith("—")


def test_versus_the_paper_holds_the_numpy_values_of_pid_and_ctc(report: ReportResult) -> None:
    text = (report.out_dir / "report.md").read_text(encoding="utf-8")
    section = text.split("## Versus the paper", 1)[1]
    eps = _fixture_episodes()
    (e_pid, t_pid), (e_ctc, _) = eps["pid"], eps["ctc"]
    _, rows = _table_after(section, "#### Joint 1 maximum tracking error")
    by_label = {r[0]: r for r in rows}
    pid1, ctc1 = np.abs(e_pid[:, 0]).max(), np.abs(e_ctc[:, 0]).max()
    assert float(by_label["CTC max |e| [rad]"][2]) == pytest.approx(ctc1, rel=6e-4)
    assert float(by_label["PID max |e| [rad]"][2]) == pytest.approx(pid1, rel=6e-4)
    assert by_label["(PID − CTC) / PID"][2] == f"{(pid1 - ctc1) / pid1 * 100:.1f} %"
    assert by_label["(PID − CTC) / CTC"][2] == f"{(pid1 - ctc1) / ctc1 * 100:.1f} %"
    header, rows = _table_after(section, "#### Error at the target (paper Table 3)")
    final = t_pid >= 2.5 - 1e-9
    for k, row in enumerate(rows):
        pid_k, ctc_k = np.abs(e_pid[final, k]).mean(), np.abs(e_ctc[final, k]).mean()
        assert float(row[header.index("ours PID")]) == pytest.approx(pid_k * 1e5, abs=6e-5)
        assert float(row[header.index("ours CTC")]) == pytest.approx(ctc_k * 1e5, abs=6e-5)


def test_diverged_short_episode_shows_no_final_error_and_keeps_its_max(
    report: ReportResult,
) -> None:
    text = (report.out_dir / "report.md").read_text(encoding="utf-8")
    section = text.split("## Scenario `paper`", 1)[1]
    header, rows = _table_after(section, "#### Error at the target")
    column = header.index("lqr (diverged)")
    assert all(r[column] == "n/a (episode ended before the motion did)" for r in rows)
    header, rows = _table_after(section, "#### Settling time")
    assert all(r[header.index("lqr (diverged)")].startswith("n/a (episode") for r in rows)
    doc = json.loads((report.out_dir / "metrics.json").read_text(encoding="utf-8"))
    e_lqr, _ = _fixture_episodes()["lqr"]
    joints = doc["episodes"]["lqr_paper"]["joints"]
    for k, joint in enumerate(joints[name] for name in UR5_JOINTS):
        assert joint["final_error"] is None
        assert joint["settling_time"] is None and joint["overshoot"] is None
        assert joint["max_abs_error"] == pytest.approx(np.abs(e_lqr[:, k]).max(), rel=1e-8)
    assert doc["episodes"]["lqr_paper"]["motion_completed"] is False


def test_a_clean_run_has_no_warnings_section(report: ReportResult) -> None:
    text = (report.out_dir / "report.md").read_text(encoding="utf-8")
    assert "## Warnings" not in text
    assert "Over repeated runs" not in text  # one run per controller: single-episode tables
    doc = json.loads((report.out_dir / "metrics.json").read_text(encoding="utf-8"))
    assert all(ep["warnings"] == [] for ep in doc["episodes"].values())
    assert doc["aggregates"] == {}
