"""reports/report.md: GitHub-flavoured Markdown with relative links to the figures."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import polars as pl

from pipeline.analysis.episodes import setting
from pipeline.analysis.metrics import (
    SETTLING_TOLERANCE_RAD,
)
from pipeline.constants import FINAL_WINDOW_S
from pipeline.log.reader import Recording
from pipeline.report import paper
from pipeline.report.figures import FigureFile
from pipeline.report.inputs import ReportData

REPORT_FILE = "report.md"
NA = "n/a"


# --- formatting ------------------------------------------------------------------------------


def _sci(x: Any, digits: int = 3) -> str:
    return NA if x is None else f"{float(x):.{digits}e}"


def _num(x: Any, fmt: str = ".3g") -> str:
    if x is None or x == NA:
        return NA
    if isinstance(x, bool):
        return str(x).lower()
    if isinstance(x, int | float):
        return format(float(x), fmt)
    return str(x)


def _pct(x: Any) -> str:
    if x is None:
        return "— (divisor ≈ 0)"
    return f"{float(x):.1f} %" if abs(float(x)) < 1e4 else f"{float(x):.3g} %"


def _value(x: Any) -> str:
    """A setting of any shape, shown compactly."""
    if x is None or x == NA:
        return NA
    if isinstance(x, list | tuple):
        if len(x) > 1 and all(v == x[0] for v in x):
            return f"{_value(x[0])} (all joints)"
        return "[" + ", ".join(_value(v) for v in x) + "]"
    if isinstance(x, dict):
        return ", ".join(f"{k} = {_value(v)}" for k, v in x.items()) or NA
    if isinstance(x, float):
        return format(x + 0.0, ".4g")  # + 0.0: no "-0"
    return str(x)


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    def esc(cell: str) -> str:
        return cell.replace("|", "\\|")

    lines = ["| " + " | ".join(esc(h) for h in header) + " |"]
    lines.append("|" + "|".join(" --- " for _ in header) + "|")
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _metric(data: ReportData, episode: str, joint: str | None, column: str) -> Any:
    return data.metric(episode, joint, column)


def _reduction(data: ReportData, base: str, cand: str, joint: str, metric: str) -> Any:
    frame = data.comparisons.filter(
        (pl.col("baseline") == base) & (pl.col("candidate") == cand) & (pl.col("joint") == joint)
    )
    return frame.get_column(f"{metric}_reduction_pct")[0] if frame.height else None


def _pairs_in(data: ReportData, scenario: str) -> list[tuple[str, str]]:
    frame = data.comparisons.filter(pl.col("scenario") == scenario)
    return sorted(set(zip(frame["baseline"].to_list(), frame["candidate"].to_list(), strict=True)))


def _head(data: ReportData, rec: Recording) -> str:
    label = data.label(rec.episode)
    return f"{label} (diverged)" if rec.status != "ok" else label


# --- sections -----------------------------------------------------------------------------------


def _intro(data: ReportData) -> list[str]:
    recs = data.recordings
    versions = sorted({_value(setting(r.settings, "package_version")) for r in recs})
    commits = sorted({_value(setting(r.settings, "git_commit")) for r in recs})
    lines = [
        "# Tracking report",
        "",
        f"{len(recs)} episode(s) read from `{data.recordings_dir.as_posix()}`"
        + (f", {len(data.skipped)} recording(s) skipped" if data.skipped else "")
        + f"; baseline controller: **{data.baseline}**. "
        f"Recorded by armlab-pipeline {', '.join(versions)} (git {', '.join(commits)}).",
        "",
        "Interactive view: [`recording.rrd`](recording.rrd), next to this file: open it with "
        "`rerun recording.rrd` (per-joint time series, the arm in 3D per controller).",
        "Numbers: [`metrics.json`](metrics.json); series for `dvc plots`: "
        "[`plots/errors.csv`](plots/errors.csv), [`plots/velocities.csv`](plots/velocities.csv).",
        "",
        "## Episodes",
        "",
    ]
    rows = []
    for row in data.episodes.iter_rows(named=True):
        rows.append(
            [
                row["episode"],
                row["scenario"],
                row["controller"],
                row["robot"],
                row["seed"],
                row["status"],
                _num(row["motion_end_s"], ".3f"),
                _num(row["end_s"], ".3f"),
                str(row["samples"]),
            ]
        )
    lines.append(
        _table(
            [
                "episode",
                "scenario",
                "controller",
                "robot",
                "seed",
                "status",
                "motion end [s]",
                "end [s]",
                "samples",
            ],
            rows,
        )
    )
    failed = [r for r in recs if r.status != "ok"]
    if failed:
        lines += ["", "### Failed episodes", ""]
        lines += [
            f"- **{r.episode}** ({r.controller}, {r.scenario}): {r.status} — {r.reason or NA}"
            for r in failed
        ]
        lines.append("")
        lines.append("Failed episodes are shown but take no part in the comparisons.")
    if data.skipped:
        lines += ["", "### Skipped recordings (--skip-bad)", ""]
        lines += [f"- `{s.source}`: {s.problem}" for s in data.skipped]
    return lines


# Settings shown first, in this order, when present; any others follow as recorded.
_PLANNER_KEYS = (
    "planner",
    "planning_time_s",
    "time_limit_s",
    "path_length_rad",
    "trajectory_duration_s",
    "velocity_scaling",
    "acceleration_scaling",
)
_PLANT_KEYS = (
    "damping",
    "frictionloss",
    "armature",
    "payload_kg",
    "noise",
    "physics_dt_s",
    "control_period_s",
)


def _settings_line(node: Any, first: Sequence[str], *, skip: Sequence[str] = ()) -> str:
    """``key = value`` for a settings dict: the known keys first, then the rest."""
    if not isinstance(node, dict) or not node:
        return NA
    keys = [k for k in first if k in node]
    keys += [k for k in node if k not in keys and k not in skip]
    return "; ".join(f"{k} = {_value(node[k])}" for k in keys)


def _setup(data: ReportData, scenario: str) -> list[str]:
    recs = data.in_scenario(scenario)
    first = recs[0]
    s = first.settings
    sc = setting(s, "scenario", default={})
    planner = setting(s, "planner", default={})

    def pose(key: str) -> str:
        # The planner records the joint-space start/goal it used; the scenario may hold a
        # Cartesian goal instead.
        value = setting(planner, key, default=None)
        return _value(value if value is not None else setting(sc, key))

    obstacles = setting(sc, "obstacles", default=[])
    lines = [
        "### Setup",
        "",
        f"- Robot: **{first.robot}** ({len(first.joint_names)} joints: "
        f"{', '.join(first.joint_names)}), DH convention "
        f"{_value(setting(s, 'robot', 'convention'))}.",
        f"- Start [rad]: {pose('start')}; goal [rad]: {pose('goal')}; "
        f"obstacles: {len(obstacles) if isinstance(obstacles, list) else NA}; "
        f"hold after the motion: {_value(setting(sc, 'hold_s'))} s.",
        f"- Planner: {_settings_line(planner, _PLANNER_KEYS, skip=('start', 'goal'))}.",
        f"- Plant: {_settings_line(setting(s, 'plant', default={}), _PLANT_KEYS)}.",
        "",
        "Controllers:",
        "",
    ]
    rows = []
    for rec in recs:
        ctrl = setting(rec.settings, "controller", default={})
        gains = setting(ctrl, "gains", default=None)
        shown = _value(gains) if gains is not None else _settings_line(ctrl, (), skip=("name",))
        rows.append([rec.episode, rec.controller, shown, rec.meta("seed"), rec.status])
    lines.append(_table(["episode", "controller", "gains and settings", "seed", "status"], rows))
    return lines


def _error_tables(data: ReportData, scenario: str) -> list[str]:
    recs = data.in_scenario(scenario)
    joints = recs[0].joint_names
    pairs = _pairs_in(data, scenario)
    lines: list[str] = []
    titles = (
        ("max_abs_error", "Max |error| [rad]"),
        ("rms_error", "RMS error [rad]"),
        (
            "final_error",
            f"Error at the target [rad] (mean |e| over the final window, ≤ {FINAL_WINDOW_S} s)",
        ),
    )
    for metric, title in titles:
        header = ["joint", *[_head(data, r) for r in recs]]
        header += [f"{data.label(c)} vs {data.label(b)}" for b, c in pairs]
        rows = []
        for k, joint in enumerate(joints):
            row = [f"{k + 1} {joint}"]
            row += [_sci(_metric(data, r.episode, joint, metric)) for r in recs]
            row += [_pct(_reduction(data, b, c, joint, metric)) for b, c in pairs]
            rows.append(row)
        lines += [f"#### {title}", "", _table(header, rows), ""]
    if pairs:
        lines.append(
            "Reduction = (baseline − candidate) / baseline × 100 (positive: the candidate "
            "has the smaller error)."
        )
        lines.append("")
    return lines


def _other_tables(data: ReportData, scenario: str) -> list[str]:
    recs = data.in_scenario(scenario)
    joints = recs[0].joint_names
    rows = []
    for k, joint in enumerate(joints):
        row = [f"{k + 1} {joint}"]
        for r in recs:
            v = _metric(data, r.episode, joint, "peak_velocity")
            t = _metric(data, r.episode, joint, "peak_velocity_time")
            row.append(NA if v is None else f"{v:+.3f} (t = {t:.2f} s)")
        rows.append(row)
    lines = [
        "#### Peak velocity [rad/s] (signed value at the largest |velocity|)",
        "",
        _table(["joint", *[_head(data, r) for r in recs]], rows),
        "",
    ]
    for metric, title, fmt in (
        (
            "settling_time",
            f"Settling time [s] (|e| ≤ {SETTLING_TOLERANCE_RAD:g} rad after the motion end)",
            ".3f",
        ),
        ("overshoot", "Overshoot past the goal [rad]", ".2e"),
        ("rms_effort", "RMS applied effort [N m]", ".3g"),
        ("saturation_fraction", "Fraction of time in torque saturation", ".3f"),
    ):
        rows = []
        for k, joint in enumerate(joints):
            row = [f"{k + 1} {joint}"]
            for r in recs:
                v = _metric(data, r.episode, joint, metric)
                row.append(
                    ("never settles" if metric == "settling_time" else NA)
                    if v is None
                    else format(v, fmt)
                )
            rows.append(row)
        lines += [f"#### {title}", "", _table(["joint", *[_head(data, r) for r in recs]], rows), ""]
    return lines


def _paper_pair(data: ReportData) -> tuple[Recording, Recording] | None:
    """(PID, CTC) episodes to put beside the paper: scenario "paper" first."""
    for scenario in sorted(data.scenarios(), key=lambda s: (s != "paper", s)):
        recs = [r for r in data.in_scenario(scenario) if r.status == "ok"]
        pid = [r for r in recs if r.controller.lower() == paper.PAPER_BASELINE]
        ctc = [r for r in recs if r.controller.lower() == paper.PAPER_CANDIDATE]
        if pid and ctc:
            return pid[0], ctc[0]
    return None


# Below this a joint error is numerical noise (a perfect-model CTC settles to ~1e-13 rad);
# dividing by it gives meaningless percentages like 1e10 %, so such ratios are not shown.
ERROR_FLOOR_RAD = 1e-9


def _red(base: Any, cand: Any, by: Any) -> Any:
    if base is None or cand is None or by is None or abs(float(by)) < ERROR_FLOOR_RAD:
        return None
    return (float(base) - float(cand)) / float(by) * 100.0


def _versus_paper(data: ReportData) -> list[str]:
    lines = ["## Versus the paper", ""]
    pair = _paper_pair(data)
    if pair is None:
        return [
            *lines,
            "No scenario has both a `pid` and a `ctc` episode that completed, so there is "
            "nothing to put beside the paper.",
            "",
        ]
    pid, ctc = pair
    joints = pid.joint_names
    lines += [
        f"Ours: scenario **{pid.scenario}**, episodes `{pid.episode}` (PID) and "
        f"`{ctc.episode}` (CTC). Paper: {paper.PAPER_SOURCE}.",
        "",
        "Two reduction formulas appear in the paper: the joint-1 figure (45.9 %) is "
        "(PID − CTC) / PID × 100, while Table 3's percentages are (PID − CTC) / CTC × 100. "
        "Both are shown for our numbers; the rest of this report uses "
        "(baseline − candidate) / baseline × 100.",
        "",
        "#### Joint 1 maximum tracking error",
        "",
    ]
    j1 = joints[0]
    ours_pid = _metric(data, pid.episode, j1, "max_abs_error")
    ours_ctc = _metric(data, ctc.episode, j1, "max_abs_error")
    pp, pc = paper.PAPER_JOINT1_MAX_ERROR_RAD["pid"], paper.PAPER_JOINT1_MAX_ERROR_RAD["ctc"]
    rows = [
        ["CTC max |e| [rad]", _sci(pc), _sci(ours_ctc)],
        ["PID max |e| [rad]", _sci(pp), _sci(ours_pid)],
        [
            "(PID − CTC) / PID",
            f"{paper.PAPER_JOINT1_MAX_ERROR_REDUCTION_PCT:.1f} % (printed)",
            _pct(_red(ours_pid, ours_ctc, ours_pid)),
        ],
        ["(PID − CTC) / CTC", _pct(_red(pp, pc, pc)), _pct(_red(ours_pid, ours_ctc, ours_ctc))],
    ]
    lines += [_table(["joint 1", "paper", "ours"], rows), ""]
    lines += ["#### Error at the target (paper Table 3), ×1e-5 rad", ""]
    rows = []
    for k in range(len(paper.PAPER_FINAL_ERROR_REDUCTION_PCT)):
        joint = joints[k] if k < len(joints) else None
        pc_k = paper.PAPER_FINAL_ERROR_RAD["ctc"][k]
        pp_k = paper.PAPER_FINAL_ERROR_RAD["pid"][k]
        oc = _metric(data, ctc.episode, joint, "final_error") if joint else None
        op = _metric(data, pid.episode, joint, "final_error") if joint else None
        rows.append(
            [
                str(k + 1),
                f"{pc_k * 1e5:.4f}",
                f"{pp_k * 1e5:.4f}",
                f"{paper.PAPER_FINAL_ERROR_REDUCTION_PCT[k]:.1f} %",
                _pct(_red(pp_k, pc_k, pp_k)),
                NA if oc is None else f"{oc * 1e5:.4f}",
                NA if op is None else f"{op * 1e5:.4f}",
                _pct(_red(op, oc, oc)),
                _pct(_red(op, oc, op)),
            ]
        )
    lines += [
        _table(
            [
                "joint",
                "paper CTC",
                "paper PID",
                "paper printed (PID−CTC)/CTC",
                "paper recomputed (PID−CTC)/PID",
                "ours CTC",
                "ours PID",
                "ours (PID−CTC)/CTC",
                "ours (PID−CTC)/PID",
            ],
            rows,
        ),
        "",
        f"Ours: mean |e| over the final window (≤ {FINAL_WINDOW_S} s, see Definitions). "
        "The paper does not say how its value was taken.",
        "",
        "#### Peak joint velocities [rad/s]",
        "",
    ]
    rows = []
    for number in sorted(paper.PAPER_PEAK_VELOCITY_RAD_S["ctc"]):
        joint = joints[number - 1] if number - 1 < len(joints) else None
        oc = _metric(data, ctc.episode, joint, "peak_velocity") if joint else None
        op = _metric(data, pid.episode, joint, "peak_velocity") if joint else None
        rows.append(
            [
                f"{number} {joint or ''}".strip(),
                f"{paper.PAPER_PEAK_VELOCITY_RAD_S['ctc'][number]:+.2f}",
                NA if oc is None else f"{oc:+.2f}",
                f"{paper.PAPER_PEAK_VELOCITY_RAD_S['pid'][number]:+.2f}",
                NA if op is None else f"{op:+.2f}",
            ]
        )
    lines += [_table(["joint", "paper CTC", "ours CTC", "paper PID", "ours PID"], rows), ""]
    return lines


def _definitions() -> list[str]:
    return [
        "## Definitions",
        "",
        "- error e(t) = reference − measured joint position [rad] (as recorded on "
        "`/controller_state`).",
        "- max |error|: largest |e| over the episode; RMS error: sqrt(mean e²) over the episode.",
        f"- error at the target: mean |e| over the last min({FINAL_WINDOW_S} s, hold / 2) of the "
        "episode, hold = episode end − motion end (motion end = the planned trajectory's "
        "duration); the last sample alone when there is no hold.",
        f"- settling time: from the motion end until |e| stays within {SETTLING_TOLERANCE_RAD:g} "
        "rad for the rest of the episode; 'never settles' when the last sample is outside.",
        "- overshoot: how far the measured position passes the goal in the direction of travel "
        "(n/a for a joint that does not move).",
        "- peak velocity: the measured velocity of largest magnitude, with its sign.",
        "- RMS effort: sqrt(mean applied effort²); saturation: share of samples where |applied "
        "effort| is at the joint's effort limit or |commanded| exceeds |applied|.",
        "- reduction % = (baseline − candidate) / baseline × 100; shown as '—' when the "
        "divisor is 0 (in the paper comparison: below 1e-9 rad, i.e. numerical noise).",
        "",
    ]


def _provenance(data: ReportData) -> list[str]:
    rows = [
        [
            rec.episode,
            f"`{rec.mcap_path.as_posix()}`",
            f"{rec.size_bytes:,}",
            f"`{rec.sha256}`",
        ]
        for rec in data.recordings
    ]
    return [
        "## Recordings",
        "",
        "Every number and figure above comes from these files:",
        "",
        _table(["episode", "file", "bytes", "SHA-256"], rows),
        "",
    ]


def render_report(
    data: ReportData,
    figures: dict[str, list[FigureFile]],
    *,
    omitted_figures: Sequence[str] = (),
) -> str:
    """The whole report.md text."""
    lines = _intro(data)
    lines.append("")
    for scenario in data.scenarios():
        lines += [f"## Scenario `{scenario}`", ""]
        lines += _setup(data, scenario)
        lines += ["", "### Tracking", ""]
        lines += _error_tables(data, scenario)
        lines += _other_tables(data, scenario)
        if scenario in figures:
            lines += ["### Figures", ""]
            for fig in figures[scenario]:
                lines += [f"**{fig.caption}**", "", f"![{fig.caption}]({fig.relpath})", ""]
    if omitted_figures:
        lines += [
            f"Figures were drawn for the first {len(figures)} scenarios only; none for: "
            + ", ".join(omitted_figures)
            + ".",
            "",
        ]
    lines += _versus_paper(data)
    lines += _definitions()
    lines += _provenance(data)
    return "\n".join(lines).rstrip("\n") + "\n"
