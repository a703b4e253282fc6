"""The report on less tidy inputs: repeated seeds, colliding scenario names, the planner's
direct path, values not recorded, reader warnings, near-perfect baselines.

Expected numbers are computed here with numpy from the arrays written into the recordings.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.report.figures import scenario_slugs, slug
from pipeline.stages.report import ReportResult, run_report
from tests.analysis.bagfactory import UR5_JOINTS, Episode, default_settings, paper_like, write_bag

SEEDS = (0, 1, 2)
# Student t, 97.5 % quantile, 2 degrees of freedom (3 runs), from the printed tables.
T_975_DF2 = 4.302652729911275


def _seed_episodes() -> list[Episode]:
    """Scenario "paper" run with 3 seeds per controller; errors scale with the seed so that
    the mean of per-pair reductions differs from the reduction of the means."""
    eps = []
    for s in SEEDS:
        for ctrl, scale in (("pid", 2e-3 * (1 + s)), ("ctc", 1e-3 * (1 + 0.5 * s))):
            eps.append(
                paper_like(
                    f"paper-{ctrl}-{s}",
                    ctrl,
                    duration_s=0.6,
                    motion_end_s=0.4,
                    error_scale=scale,
                    seed=s,
                )
            )
    return eps


def _odd_episodes() -> list[Episode]:
    direct = paper_like("ab1-pid", "pid", duration_s=0.3, motion_end_s=0.2, scenario="a b")
    direct.empty_joint_state_fields = ("velocity", "effort")
    settings = default_settings(direct)
    settings["planner"] |= {"direct": True, "simplify": False, "n_waypoints": 2}
    direct.settings = settings
    searched = paper_like("ab2-pid", "pid", duration_s=0.3, motion_end_s=0.2, scenario="a/b")
    settings = default_settings(searched)
    settings["planner"] |= {
        "direct": False,
        "simplify": True,
        "n_waypoints": 5,
        "n_states_before_simplify": 23,
    }
    searched.settings = settings
    broken = paper_like("ab2-ctc", "ctc", duration_s=0.3, motion_end_s=0.2, scenario="a/b")
    broken.raw_settings = "{not json"
    return [direct, searched, broken]


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> ReportResult:
    root = tmp_path_factory.mktemp("edge")
    for ep in [*_seed_episodes(), *_odd_episodes()]:
        write_bag(root / "recordings", ep)
    return run_report(recordings_dir=root / "recordings", out_dir=root / "reports")


def _doc(report: ReportResult) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((report.out_dir / "metrics.json").read_text("utf-8"))
    return data


def _text(report: ReportResult) -> str:
    return (report.out_dir / "report.md").read_text(encoding="utf-8")


def _per_seed(metric: str) -> dict[str, np.ndarray]:
    """(seeds, joints) array of a metric per controller, from the written arrays."""
    out: dict[str, list[np.ndarray]] = {"pid": [], "ctc": []}
    for ep in _seed_episodes():
        err = ep.q_ref - ep.q
        t = ep.stamp_ns / 1e9
        if metric == "max_abs_error":
            value = np.abs(err).max(axis=0)
        elif metric == "rms_error":
            value = np.sqrt(np.mean(err**2, axis=0))
        else:
            value = np.abs(err[t >= 0.6 - 0.1 - 1e-9]).mean(axis=0)  # hold 0.2 s: window 0.1 s
        out[ep.controller].append(value)
    return {c: np.array(v) for c, v in out.items()}


# --- 11: repeated runs ---------------------------------------------------------------------------


@pytest.mark.parametrize("metric", ["max_abs_error", "rms_error", "final_error"])
def test_repeated_runs_give_mean_and_student_t_interval_per_controller(
    report: ReportResult, metric: str
) -> None:
    agg = _doc(report)["aggregates"]["paper"]["controllers"]
    for ctrl, values in _per_seed(metric).items():
        for k, joint in enumerate(UR5_JOINTS):
            stats = agg[ctrl][joint][metric]
            column = values[:, k]
            half = T_975_DF2 * np.std(column, ddof=1) / np.sqrt(len(SEEDS))
            assert stats["n"] == len(SEEDS)
            assert stats["mean"] == pytest.approx(np.mean(column), rel=1e-8)
            assert stats["ci95_half_width"] == pytest.approx(half, rel=1e-6, abs=1e-15)
            assert stats["ci95_low"] == pytest.approx(np.mean(column) - half, rel=1e-6, abs=1e-15)


def test_reductions_are_averaged_over_seed_pairs(report: ReportResult) -> None:
    cmp = _doc(report)["aggregates"]["paper"]["reductions"]["ctc vs pid"]
    assert cmp["pairing"] == "seed"
    values = _per_seed("max_abs_error")
    per_pair = (values["pid"] - values["ctc"]) / values["pid"] * 100  # (seeds, joints)
    of_means = (values["pid"].mean(0) - values["ctc"].mean(0)) / values["pid"].mean(0) * 100
    for k in range(5):  # joint 6 does not move: its errors are noise
        stats = cmp["joints"][UR5_JOINTS[k]]["max_abs_error_reduction_pct"]
        assert stats["n"] == len(SEEDS)
        assert stats["mean"] == pytest.approx(per_pair[:, k].mean(), rel=1e-6)
        half = T_975_DF2 * np.std(per_pair[:, k], ddof=1) / np.sqrt(len(SEEDS))
        assert stats["ci95_half_width"] == pytest.approx(half, rel=1e-6)
        # The test tells the two apart: averaging the runs first gives another number.
        assert abs(stats["mean"] - of_means[k]) > 1.0


def test_report_shows_the_distribution_table_for_repeated_runs(report: ReportResult) -> None:
    text = _text(report)
    section = text.split("## Scenario `paper`", 1)[1].split("\n## ", 1)[0]
    assert "Over repeated runs: mean ± 95 % confidence interval (Student t)" in section
    values = _per_seed("rms_error")
    pid = values["pid"][:, 0]
    half = T_975_DF2 * np.std(pid, ddof=1) / np.sqrt(len(SEEDS))
    assert f"{pid.mean():.3e} ± {half:.1e} (n = 3)" in section


def test_versus_the_paper_summarises_every_seed_pair_not_the_first(report: ReportResult) -> None:
    section = _text(report).split("## Versus the paper", 1)[1].split("\n## ", 1)[0]
    assert "3 PID/CTC pairs" in section and "seeds 0, 1, 2" in section
    values = _per_seed("max_abs_error")
    ctc = values["ctc"][:, 0]
    half = T_975_DF2 * np.std(ctc, ddof=1) / np.sqrt(len(SEEDS))
    row = next(line for line in section.splitlines() if line.startswith("| CTC max"))
    assert f"{ctc.mean():.3e} ± {half:.3e} (n = 3)" in row
    first_seed_only = f"| {values['ctc'][0, 0]:.3e} |"
    assert first_seed_only not in row
    per_pair = (values["pid"][:, 0] - values["ctc"][:, 0]) / values["pid"][:, 0] * 100
    row = next(line for line in section.splitlines() if line.startswith("| (PID − CTC) / PID"))
    assert f"{per_pair.mean():.1f} ± " in row


# --- 13: figure file names ---------------------------------------------------------------------


def test_scenario_names_with_the_same_slug_get_distinct_figure_files(
    report: ReportResult,
) -> None:
    assert slug("a b") == slug("a/b")
    stems = scenario_slugs(["a b", "a/b", "paper", "A"])
    assert len(set(stems.values())) == 4 and stems["paper"] == "paper" and stems["A"] == "A"
    text = _text(report)
    links = {}
    for scenario in ("a b", "a/b"):
        section = text.split(f"## Scenario `{scenario}`", 1)[1].split("\n## ", 1)[0]
        links[scenario] = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", section)
        assert len(links[scenario]) == 6
        for link in links[scenario]:
            assert (report.out_dir / link).is_file()
    assert not set(links["a b"]) & set(links["a/b"])
    drawn = {p.name for p in (report.out_dir / "figures").glob("*.png")}
    assert drawn == {Path(p).name for p in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)}
    assert len(drawn) >= 15  # 5 per scenario, plus the TCP errors where the bag has a robot


# --- 9: the planner line -----------------------------------------------------------------------


def test_planner_line_says_plainly_whether_rrtconnect_searched(report: ReportResult) -> None:
    text = _text(report)
    direct = text.split("## Scenario `a b`", 1)[1].split("\n## ", 1)[0]
    line = next(x for x in direct.splitlines() if x.startswith("- Planner:"))
    assert "direct joint-space segment" in line and "RRTConnect not needed" in line
    assert "simplify" not in line and "planner = RRTConnect" not in line
    searched = text.split("## Scenario `a/b`", 1)[1].split("\n## ", 1)[0]
    line = next(x for x in searched.splitlines() if x.startswith("- Planner:"))
    assert "RRTConnect, 5 waypoints after simplification (from 23 states)" in line


# --- 2: values not recorded ---------------------------------------------------------------------


def test_values_not_recorded_read_n_a_never_nan(report: ReportResult) -> None:
    text = _text(report)
    assert not re.search(r"\bnan\b", text, flags=re.IGNORECASE)
    section = text.split("## Scenario `a b`", 1)[1].split("\n## ", 1)[0]
    for heading in ("#### Peak velocity", "#### RMS applied effort", "#### Fraction of time"):
        block = section.split(heading, 1)[1].split("####", 1)[0]
        rows = [x for x in block.splitlines() if x.startswith("| 1 ")]
        assert rows and "n/a (not recorded)" in rows[0], heading
    joint = _doc(report)["episodes"]["ab1-pid"]["joints"]["elbow_joint"]
    for key in ("peak_velocity", "peak_velocity_time", "rms_effort", "saturation_fraction"):
        assert joint[key] is None, key
    assert joint["max_abs_error"] is not None
    errors = (report.out_dir / "plots" / "velocities.csv").read_text(encoding="utf-8")
    assert "nan" not in errors.lower()


# --- 6: reader notes -----------------------------------------------------------------------------


def test_reader_notes_are_listed_as_warnings_in_report_and_metrics(report: ReportResult) -> None:
    text = _text(report)
    warnings = text.split("## Warnings", 1)[1].split("\n## ", 1)[0]
    assert "**ab2-ctc**" in warnings and "settings is not valid JSON" in warnings
    assert "**ab1-pid**" in warnings and "no effort values" in warnings
    doc = _doc(report)
    assert any("not valid JSON" in w for w in doc["episodes"]["ab2-ctc"]["warnings"])
    assert doc["episodes"]["paper-pid-0"]["warnings"] == []
    assert ("ab2-ctc", doc["episodes"]["ab2-ctc"]["warnings"][0]) in report.warnings


# --- 10 (report side): no "-0.000" ------------------------------------------------------------


def test_values_that_round_to_zero_carry_no_sign(report: ReportResult) -> None:
    text = _text(report)
    assert not re.search(r"[-+]0\.0+\b(?!\d)", text.replace("e-0", "e~0"))


# --- 8: near-perfect baselines in every table ------------------------------------------------


def test_near_zero_baseline_gives_no_percentage_in_tables_or_json(tmp_path: Path) -> None:
    perfect = paper_like("p-ctc", "ctc", duration_s=0.6, motion_end_s=0.4, error_scale=0.0)
    perfect.q = perfect.q_ref + 1e-13
    pid = paper_like("p-pid", "pid", duration_s=0.6, motion_end_s=0.4, error_scale=2e-3)
    for ep in (perfect, pid):
        write_bag(tmp_path / "recordings", ep)
    result = run_report(
        recordings_dir=tmp_path / "recordings", out_dir=tmp_path / "reports", baseline="ctc"
    )
    text = (result.out_dir / "report.md").read_text(encoding="utf-8")
    assert not re.search(r"\d{5,}\.\d %|e\+\d+ %", text)
    section = text.split("#### Max |error| [rad]", 1)[1].split("####", 1)[0]
    assert section.count("— (divisor ≈ 0)") == 6
    doc = json.loads((result.out_dir / "metrics.json").read_text(encoding="utf-8"))
    (cmp,) = doc["comparisons"]
    tcp = cmp["joints"].pop("tcp")
    assert all(
        v["max_abs_error_reduction_pct"] is None and v["final_error_reduction_pct"] is None
        for v in cmp["joints"].values()
    )
    # the TCP of a perfect tracker is below its floor too (1 nm, 1 nrad): no percentage
    assert tcp["tcp_max_position_error_reduction_pct"] is None
    assert tcp["tcp_max_orientation_error_reduction_pct"] is None
