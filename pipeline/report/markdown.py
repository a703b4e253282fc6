"""reports/report.md: GitHub-flavoured Markdown with relative links to the figures."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
import polars as pl

from pipeline.analysis import catalog
from pipeline.analysis.aggregate import CONFIDENCE, MeanCI, mean_ci
from pipeline.analysis.episodes import robot_spec, setting, shown_status
from pipeline.analysis.metrics import ERROR_FLOOR_RAD, SETTLING_TOLERANCE_RAD, pairs
from pipeline.constants import (
    FINAL_WINDOW_S,
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
)
from pipeline.log.reader import Recording
from pipeline.report import paper
from pipeline.report.campaigns import CampaignSection
from pipeline.report.figures import FigureFile
from pipeline.report.inputs import ReportData
from pipeline.robots.spec import RobotSpec
from pipeline.settings import EpisodeSettings

REPORT_FILE = "report.md"
# Lists (episodes, warnings, findings, recordings) show at most this many rows; the rest are
# in episodes.csv / recordings.csv / metrics.json, so report.md stays bounded whatever N is.
MAX_ROWS = 40
# A campaign's mean ± CI tables are written for at most this many conditions.
MAX_CONDITION_TABLES = 4
# A scenario with more episodes than this gets no per-episode tables (only the summaries).
MAX_EPISODE_COLUMNS = 8
NA = "n/a"
NOT_RECORDED = "n/a (not recorded)"
ENDED_EARLY = "n/a (episode ended before the motion did)"
SALVAGE_CUT = "n/a (recording salvaged: cut at the damage, motion end unknown)"
_FLOOR = f"{ERROR_FLOOR_RAD:.0e}".replace("e-0", "e-")  # "1e-9"


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


# A reduction below this (the candidate more than twice the baseline) reads better as a
# ratio: "-3600 %" says less than "37x the baseline's".
RATIO_BELOW_PCT = -100.0


def _pct(x: Any) -> str:
    if x is None:
        return "— (divisor ≈ 0)"
    if float(x) < RATIO_BELOW_PCT:
        return f"{1.0 - float(x) / 100.0:.3g}× the baseline's"
    return f"{float(x):.1f} %"


def _signed(x: float, digits: int) -> str:
    """``+1.234`` / ``-1.234``; a value that rounds to zero is ``0.000`` (never ``-0.000``)."""
    text = f"{x:+.{digits}f}"
    return text[1:] if float(text) == 0.0 else text


def _ci(ci: MeanCI, fmt: Any, hw_fmt: Any = None) -> str:
    """``mean ± half width (n = k)``; ``fmt`` formats the mean (and, unless ``hw_fmt`` is
    given, the half width)."""
    if ci.mean is None:
        return NA
    if ci.half_width is None:
        return f"{fmt(ci.mean)} (n = {ci.n})"
    return f"{fmt(ci.mean)} ± {(hw_fmt or fmt)(ci.half_width)} (n = {ci.n})"


def _ci_pct(ci: MeanCI) -> str:
    if ci.mean is None:
        return "— (divisor ≈ 0)"
    if ci.mean < RATIO_BELOW_PCT:
        return f"{1.0 - ci.mean / 100.0:.3g}× the baseline's on average (n = {ci.n})"
    if ci.half_width is None:
        return f"{ci.mean:.1f} % (n = {ci.n})"
    return f"{ci.mean:.1f} ± {ci.half_width:.1f} % (n = {ci.n})"


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
    if rec.status != "ok":
        return f"{label} ({rec.status})"
    return f"{label} (salvaged)" if rec.salvaged else label


def _completed(data: ReportData, episode: str) -> bool:
    frame = data.episodes.filter(pl.col("episode") == episode)
    return bool(frame.height and frame.get_column("motion_completed")[0])


def _incomplete(data: ReportData, rec: Recording) -> str:
    """Why final error, settling time and overshoot are n/a for an episode that did not
    complete its motion."""
    end = data.episodes.filter(pl.col("episode") == rec.episode).get_column("end_s")[0]
    motion_end = rec.motion_end_s
    if motion_end is not None and (end is None or end < motion_end):
        return ENDED_EARLY
    if rec.salvaged and rec.status == "ok":
        return SALVAGE_CUT
    return f"n/a (episode {rec.status})"


def _missing(data: ReportData, rec: Recording, metric: str) -> str:
    """The text for a null metric value of one episode."""
    m = catalog.metric(metric)
    if m.needs_completed_motion and not _completed(data, rec.episode):
        return _incomplete(data, rec)
    if m.frame == "joint_states":
        return NOT_RECORDED
    if metric == "settling_time":
        return "n/a (motion end unknown)" if rec.motion_end_s is None else "never settles"
    return NA


def _count(values: Sequence[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for v in values:
        out[v] = out.get(v, 0) + 1
    return out


def _seed_span(seeds: Sequence[str]) -> str:
    """``0–49`` for the seeds 0..49 (sorted numerically where they are numbers)."""
    ordered = sorted(set(seeds), key=lambda x: (len(x), x))
    return ordered[0] if len(ordered) == 1 else f"{ordered[0]}–{ordered[-1]} ({len(ordered)})"


def _samples(joint_states: int, controller_states: int) -> str:
    """Message count; both topics' when /joint_states is decimated."""
    if joint_states == controller_states:
        return str(joint_states)
    return f"{joint_states} (/joint_states), {controller_states} (/controller_state)"


# --- sections -----------------------------------------------------------------------------------


def _salvaged_summary(data: ReportData) -> list[str]:
    """The header's line on salvaged recordings (none when there are none)."""
    rows = data.episodes.filter(pl.col("salvaged")) if data.episodes.height else data.episodes
    if not rows.height:
        return []
    cut = rows.filter(~pl.col("motion_completed")).get_column("episode").to_list()
    shown = ", ".join(f"`{e}`" for e in rows.get_column("episode").to_list()[:MAX_ROWS])
    return [
        "",
        f"**{rows.height} episode(s) salvaged** from damaged recordings (`--salvage`, read up "
        f"to the damage: {shown}); "
        + (
            f"{len(cut)} of them cut before the motion end: not compared, their max and RMS "
            "cover only the part recorded."
            if cut
            else "each reaches its motion end, so each is compared."
        )
        + " See *status* in the episode table and the warnings.",
    ]


def _intro(data: ReportData) -> list[str]:
    recs = data.recordings
    versions = sorted({_value(setting(r.settings, "package_version")) for r in recs})
    commits = sorted({_value(setting(r.settings, "git_commit")) for r in recs})
    lines = [
        "# Tracking report",
        "",
        f"{len(recs)} episode(s) read from `{data.recordings_dir.as_posix()}`"
        + (f", {len(data.skipped)} recording(s) skipped" if data.skipped else "")
        + (
            f"; baseline controller: **{data.baseline}**. "
            if data.compares
            else f"; one controller (**{', '.join(data.controllers())}**): nothing to compare, "
            "so no reductions. "
        )
        + f"Recorded by armlab-pipeline {', '.join(versions)} (git {', '.join(commits)}).",
        *_salvaged_summary(data),
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
    worst_sat = {
        r["episode"]: r["saturation_fraction"]
        for r in data.metrics.group_by("episode")
        .agg(pl.col("saturation_fraction").max())
        .iter_rows(named=True)
    }
    unsettled = _unsettled_joints(data.metrics)
    listed = {r.episode for r in data.listed}
    table_rows = [r for r in data.episodes.iter_rows(named=True) if r["episode"] in listed]
    for row in table_rows[:MAX_ROWS]:
        sat = worst_sat.get(row["episode"])
        rows.append(
            [
                row["episode"],
                row["scenario"],
                row["controller"],
                row["robot"],
                row["seed"],
                shown_status(row),
                _num(row["motion_end_s"], ".3f"),
                _num(row["end_s"], ".3f"),
                _samples(row["samples"], row["controller_samples"]),
                row["error_source"] or NA,
                _sci(row["start_abs_error_rad"], 1),
                _num(row["start_abs_effort_nm"], ".1f"),
                NA if sat is None else f"{sat * 100:.1f} %",
                unsettled.get(row["episode"], NA),
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
                "error from",
                "|e| at start [rad]",
                "|effort| at start [N m]",
                "saturated (worst joint)",
                "error at the target",
            ],
            rows,
        )
    )
    if len(table_rows) > MAX_ROWS:
        lines += ["", f"… {len(table_rows) - MAX_ROWS} more in [`episodes.csv`](episodes.csv)."]
    in_campaigns = len(data.recordings) - len(data.listed)
    if in_campaigns:
        lines += [
            "",
            f"{in_campaigns} more episodes belong to campaigns ("
            + ", ".join(f"`{c}`" for c in data.campaigns())
            + "): summarised in their sections below; every episode is in "
            "[`episodes.csv`](episodes.csv).",
        ]
    lines += [
        "",
        "Times count from the **motion start**: every episode first holds its start pose "
        "under its own controller (the pre-roll, recorded in the bag before the planned "
        "trajectory's stamp), so metrics measure tracking, not a cold start. *Error from*: "
        "the plant's true state (`/ground_truth/joint_states`, simulation) or the measured "
        "one (a real robot's bag). *At start*: the worst joint at the motion start. "
        f"*Saturated*: share of samples at the effort limit, worst joint (flagged above "
        f"{SATURATION_WARN_FRACTION * 100:.0f} %); *status* ok = stable (not diverged); "
        "*salvaged*: read with `--salvage` from a damaged file up to the damage (the share "
        "of the file, or of a `.db3`'s messages, not read); cut before its motion end, "
        "such an episode takes no part in comparisons. *Error at the target*: **not "
        "settled** on the joints whose mean |e| changes between the two halves of the "
        f"final window by more than {catalog.FINAL_DRIFT_REL:g} x it (and "
        f"{catalog.DRIFT_FLOOR_RAD:g} rad): a transient, not a steady state (a longer "
        "`hold_s` measures the steady state).",
    ]
    lines += _physical_checks(data)
    failed = [r for r in recs if r.status != "ok"]
    if failed:
        lines += ["", "### Failed episodes", ""]
        lines += [
            f"- **{r.episode}** ({r.controller}, {r.scenario}): {r.status} — {r.reason or NA}"
            for r in failed[:MAX_ROWS]
        ]
        if len(failed) > MAX_ROWS:
            lines.append(f"- … {len(failed) - MAX_ROWS} more (`status` in episodes.csv)")
        lines.append("")
        lines.append("Failed episodes are shown but take no part in the comparisons.")
    if data.skipped:
        lines += ["", "### Skipped recordings (--skip-bad)", ""]
        lines += [f"- `{s.source}`: {s.problem}" for s in data.skipped]
    warnings = data.warnings()
    if warnings:
        lines += ["", "## Warnings", ""]
        lines += [
            "Read from the recordings; the numbers below are affected where they say n/a.",
            "",
        ]
        lines += [f"- **{episode}**: {note}" for episode, note in warnings[:MAX_ROWS]]
        if len(warnings) > MAX_ROWS:
            lines.append(f"- … {len(warnings) - MAX_ROWS} more (metrics.json, each episode's "
                         "`warnings`)")  # fmt: skip
    return lines


SATURATION_WARN_FRACTION = 0.05
"""Warn when a joint's effort sits at its limit for more than this share of the samples."""
GOAL_MISS_RAD = 1e-2
"""A completed episode whose error at the target exceeds this never reached its goal."""
_STIFFNESS_GAINS = ("pid", "pd_gravity")  # controller types whose kp is in N m/rad


def _stiffness_nm_per_rad(st: EpisodeSettings, spec: RobotSpec | None) -> list[float] | None:
    """Per-joint position stiffness [N m/rad] of the controller's proportional term:
    ``kp`` itself for the decentralized laws, ``M_n(goal)_jj * kp`` for the model-based
    ones (their kp is an acceleration gain [1/s^2])."""
    kp = st.controller.gains.get("kp")
    if not (isinstance(kp, list) and all(isinstance(k, int | float) for k in kp)):
        return None
    if st.controller.type in _STIFFNESS_GAINS:
        return [float(k) for k in kp]
    if spec is None or not spec.has_dynamics or len(st.planner.goal) != spec.dof:
        return None
    mass = _mass_diagonal(spec, tuple(float(g) for g in st.planner.goal))
    return [float(k) * mass[j] for j, k in enumerate(kp)]


@functools.lru_cache(maxsize=256)
def _mass_diagonal(spec: RobotSpec, q: tuple[float, ...]) -> tuple[float, ...]:
    """diag M_n(q) of the nominal model (a campaign shares robot and goal: computed once)."""
    import pinocchio as pin

    from pipeline.model.urdf import build_pinocchio_model

    model = build_pinocchio_model(spec)
    mass = pin.crba(model, model.createData(), np.asarray(q, dtype=float))
    return tuple(float(mass[j, j]) for j in range(len(q)))


def _physical_checks(data: ReportData) -> list[str]:
    """Physically broken setups, per episode: contact, saturation, a missed goal, a gain
    too small against the configured friction. Never hidden, never fatal; a finding shared
    by several episodes (same gains and friction over seeds) is listed once."""
    found: dict[str, list[str]] = {}
    metrics = {(r["episode"], r["joint"]): r for r in data.metrics.iter_rows(named=True)}
    for rec in data.recordings:
        view = data.protocol.get(rec.episode)
        st = view.settings if view is not None else None
        start = view.motion_start_s if view is not None else 0.0

        def add(text: str, episode: str = rec.episode) -> None:
            found.setdefault(text, []).append(episode)

        if st is not None:
            for c in st.safety.contacts:
                add(
                    f"{c.kind} contact {c.bodies[0]} – {c.bodies[1]}, "
                    f"{c.max_depth_m * 1e3:.2f} mm deep, t = {c.first_ns * 1e-9 - start:.3f} to "
                    f"{c.last_ns * 1e-9 - start:.3f} s from the motion start ({c.samples} samples)"
                )
        stiffness = _stiffness_nm_per_rad(st, robot_spec(rec)) if st is not None else None
        for j, joint in enumerate(rec.joint_names):
            m = metrics.get((rec.episode, joint), {})
            sat = m.get("saturation_fraction")
            if sat is not None and sat > SATURATION_WARN_FRACTION:
                add(
                    f"{joint} saturated {sat * 100:.1f} % of the time (above "
                    f"{SATURATION_WARN_FRACTION * 100:.0f} %): its gains ask for more torque "
                    "than the motor has"
                )
            final = m.get("final_error")
            if final is not None and final > GOAL_MISS_RAD:
                add(
                    f"{joint} never reaches its goal (error at the target {final:.3g} rad > "
                    f"{GOAL_MISS_RAD:g} rad)"
                )
            friction = st.plant.frictionloss if st is not None else ()
            if stiffness is None or j >= len(friction) or j >= len(stiffness):
                continue
            if stiffness[j] > 0 and friction[j] / stiffness[j] > SETTLING_TOLERANCE_RAD:
                assert st is not None
                add(
                    f"`{st.controller.type}` on {joint}: proportional stiffness "
                    f"{stiffness[j]:.3g} N m/rad against {friction[j]:.3g} N m of friction, a "
                    f"dead band of {friction[j] / stiffness[j]:.3g} rad (> the "
                    f"{SETTLING_TOLERANCE_RAD:g} rad settling band): without integral action "
                    "the joint may stop anywhere in it; with it, only after the integral "
                    "breaks the friction away"
                )
    lines = ["", "## Physical checks", ""]
    if not found:
        stable = sum(1 for r in data.recordings if r.status == "ok")
        return [
            *lines,
            f"No contact during execution, no joint saturated more than "
            f"{SATURATION_WARN_FRACTION * 100:.0f} % of the time, every completed episode "
            f"reached its goal within {GOAL_MISS_RAD:g} rad, no gain below the configured "
            f"friction's dead band; {stable} of {len(data.recordings)} episodes stable "
            "(not diverged).",
        ]
    for text, episodes in list(found.items())[:MAX_ROWS]:
        who = (
            ", ".join(episodes)
            if len(episodes) <= 3
            else (f"{episodes[0]} … {episodes[-1]} ({len(episodes)} episodes)")
        )
        lines.append(f"- **{who}**: {text}")
    if len(found) > MAX_ROWS:
        lines.append(
            f"- … {len(found) - MAX_ROWS} more findings (per episode: `saturation_fraction` "
            "and `final_error` in metrics.json, contacts in each bag's settings)"
        )
    return lines


def _unsettled_joints(metrics: pl.DataFrame) -> dict[str, str]:
    """Per episode, "settled" or "not settled: <joints>" (joints whose error at the target
    still moves in its last windows, ``catalog.not_settled``); none where unknown."""
    if not {"final_error", "final_drift"} <= set(metrics.columns):
        return {}
    flagged = metrics.with_columns(
        flag=catalog.not_settled(pl.col("final_error"), pl.col("final_drift"))
    ).filter(pl.col("flag").is_not_null())
    out: dict[str, str] = {}
    for row in (
        flagged.group_by("episode", maintain_order=True)
        .agg(pl.col("joint").filter(pl.col("flag")))
        .iter_rows(named=True)
    ):
        joints = row["joint"]
        out[row["episode"]] = "settled" if not joints else "not settled: " + ", ".join(joints)
    return out


# Settings shown first, in this order, when present; any others follow as recorded.
_PLANNER_KEYS = (
    "planner",
    "time_limit_s",
    "path_length_rad",
    "trajectory_duration_s",
    "velocity_scaling",
    "acceleration_scaling",
)
_PLANT_KEYS = (
    "exact",
    "damping",
    "frictionloss",
    "armature",
    "nominal_armature",
    "payload_kg",
    "position_noise_std_rad",
    "velocity_noise_std_rad_s",
    "uncertainty",
    "physics_dt_s",
    "integrator",
    "control_period_s",
)


def _settings_line(node: Any, first: Sequence[str], *, skip: Sequence[str] = ()) -> str:
    """``key = value`` for a settings dict: the known keys first, then the rest."""
    if not isinstance(node, dict) or not node:
        return NA
    keys = [k for k in first if k in node and k not in skip]
    keys += [k for k in node if k not in keys and k not in skip]
    return "; ".join(f"{k} = {_value(node[k])}" for k in keys) or NA


# Planner settings that the planner line states in words.
_PATH_KEYS = ("planner", "direct", "simplify", "n_waypoints", "n_states_before_simplify")


def _planner_line(planner: Any) -> str:
    """What the planner did, in words, then its settings.

    ``direct`` = the straight joint-space segment start -> goal was collision-free, so it
    is the path: RRTConnect did not search and there was nothing to simplify.
    """
    if not isinstance(planner, dict) or not planner:
        return NA
    skip: tuple[str, ...] = ("start", "goal")
    head = None
    direct = planner.get("direct")
    if direct is True:
        head = "direct joint-space segment start → goal (collision-free; RRTConnect not needed)"
        skip += _PATH_KEYS
    elif direct is False:
        name = _value(planner.get("planner", "RRTConnect"))
        n = _value(planner.get("n_waypoints"))
        raw = planner.get("n_states_before_simplify")
        if planner.get("simplify"):
            head = f"{name}, {n} waypoints after simplification" + (
                f" (from {_value(raw)} states)" if raw is not None else ""
            )
        else:
            head = f"{name}, {n} waypoints (not simplified)"
        skip += _PATH_KEYS
    rest = _settings_line(planner, _PLANNER_KEYS, skip=skip)
    if head is None:
        return rest
    return head if rest == NA else f"{head}; {rest}"


def _setup(data: ReportData, scenario: str) -> list[str]:
    recs = data.in_group(scenario)
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
        f"- Planner: {_planner_line(planner)}.",
        f"- Plant: {_settings_line(setting(s, 'plant', default={}), _PLANT_KEYS, skip=('links',))}"
        + (
            "; link masses, centres of mass and inertias (and the armature above) drawn per "
            "episode seed, recorded in each bag's `settings.plant.links`."
            if _exact(data, scenario) is False
            else ": the controllers' nominal model **is** the plant, so model-based terms are "
            "exact by construction."
            if _exact(data, scenario)
            else "."
        ),
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
    if len(rows) > MAX_EPISODE_COLUMNS:
        # one row per controller and gains: seeds and statuses summarised
        grouped: dict[tuple[str, str], list[list[str]]] = {}
        for row in rows:
            grouped.setdefault((row[1], row[2]), []).append(row)
        rows = [
            [
                f"{len(members)} episodes",
                ctrl,
                shown,
                _seed_span([m[3] for m in members]),
                ", ".join(f"{k}: {v}" for k, v in _count([m[4] for m in members]).items()),
            ]
            for (ctrl, shown), members in grouped.items()
        ]
    lines.append(_table(["episode", "controller", "gains and settings", "seed", "status"], rows))
    return lines


# The compared metrics: aggregate and per-episode tables with reductions.
_ERROR_TITLES = tuple((m.name, m.heading) for m in catalog.METRICS if m.compared)


def _aggregate_tables(data: ReportData, scenario: str) -> list[str]:
    """Mean ± 95 % CI over the repeated runs of each controller, and reductions per pair."""
    recs = data.in_group(scenario)
    joints = recs[0].joint_names
    controllers = list(dict.fromkeys(r.controller for r in recs if r.status == "ok"))
    summary = data.metric_summary.filter(pl.col("scenario") == scenario)
    reductions = data.reduction_summary.filter(pl.col("scenario") == scenario)
    candidates = list(dict.fromkeys(reductions.get_column("controller").to_list()))
    pairing = dict(
        zip(reductions["controller"].to_list(), reductions["pairing"].to_list(), strict=True)
    )

    def cell(frame: pl.DataFrame) -> MeanCI:
        if not frame.height:
            return MeanCI(0, None, None, None)
        r = frame.row(0, named=True)
        return MeanCI(r["n"], r["mean"], r["std"], r["ci95_half_width"])

    runs = data.runs
    lines = [
        f"#### Over repeated runs: mean ± {CONFIDENCE * 100:.0f} % confidence interval (Student t)",
        "",
        "Runs per controller (completed episodes): "
        + ", ".join(f"{c}: {runs.get((scenario, c), 0)}" for c in controllers)
        + ". Reductions are computed per pair — baseline and candidate of the same seed "
        "where the scenario has such pairs, else every baseline run against every candidate "
        "run — and then averaged.",
        "",
    ]
    for metric, title in _ERROR_TITLES:
        header = ["joint", *controllers]
        header += [
            f"{c} vs {data.baseline} (per {'seed ' if pairing[c] == 'seed' else ''}pair)"
            for c in candidates
        ]
        rows = []
        for k, joint in enumerate(joints):
            row = [f"{k + 1} {joint}"]
            for c in controllers:
                ci = cell(
                    summary.filter(
                        (pl.col("controller") == c)
                        & (pl.col("joint") == joint)
                        & (pl.col("metric") == metric)
                    )
                )
                row.append(_ci(ci, lambda x: f"{x:.3e}", lambda x: f"{x:.1e}"))
            for c in candidates:
                ci = cell(
                    reductions.filter(
                        (pl.col("controller") == c)
                        & (pl.col("joint") == joint)
                        & (pl.col("metric") == f"{metric}_reduction_pct")
                    )
                )
                row.append(_ci_pct(ci))
            rows.append(row)
        lines += [f"##### {title}", "", _table(header, rows), ""]
    return lines


def _error_tables(data: ReportData, scenario: str) -> list[str]:
    recs = data.in_scenario(scenario)
    joints = recs[0].joint_names
    repeated = data.repeated(scenario)
    # With repeated runs the per-pair reductions are summarised above, not listed.
    pairs = [] if repeated else _pairs_in(data, scenario)
    lines: list[str] = _aggregate_tables(data, scenario) if repeated else []
    level = "#####" if repeated else "####"
    if len(recs) > MAX_EPISODE_COLUMNS:
        return [
            *lines,
            f"Per-episode values of the {len(recs)} episodes: metrics.json (`episodes`) and "
            "[`episodes.csv`](episodes.csv).",
            "",
        ]
    if repeated:
        lines += ["#### Per episode", ""]
    for metric, title in _ERROR_TITLES:
        header = ["joint", *[_head(data, r) for r in recs]]
        header += [f"{data.label(c)} vs {data.label(b)}" for b, c in pairs]
        rows = []
        for k, joint in enumerate(joints):
            row = [f"{k + 1} {joint}"]
            for r in recs:
                v = _metric(data, r.episode, joint, metric)
                row.append(_missing(data, r, metric) if v is None else _sci(v))
            row += [_pct(_reduction(data, b, c, joint, metric)) for b, c in pairs]
            rows.append(row)
        lines += [f"{level} {title}", "", _table(header, rows), ""]
    if pairs or repeated:
        lines.append(
            "Reduction = (baseline − candidate) / baseline × 100 (positive: the candidate "
            f"has the smaller error); '—' when |baseline| < {_FLOOR} rad "
            "(numerical noise)."
        )
        lines.append("")
    return lines


def _cell(data: ReportData, rec: Recording, m: catalog.Metric, joint: str) -> str:
    """One metric value as its catalog format says; a companion ``<name>_time`` metric
    (the peak's time) is shown beside it."""
    v = _metric(data, rec.episode, joint, m.name)
    if v is None:
        return _missing(data, rec, m.name)
    text = format(float(v) + 0.0, m.fmt)
    if m.fmt.startswith("+") and float(text) == 0.0:
        text = text[1:]  # never "-0.000" or "+0.000"
    at = catalog.BY_NAME.get(f"{m.name}_time")
    t = _metric(data, rec.episode, joint, at.name) if at is not None else None
    return text if t is None else f"{text} (t = {t:.2f} s)"


def _other_tables(data: ReportData, scenario: str) -> list[str]:
    recs = data.in_scenario(scenario)
    joints = recs[0].joint_names
    lines: list[str] = []
    if len(recs) > MAX_EPISODE_COLUMNS:
        return lines
    for m in catalog.METRICS:
        if m.compared or not m.in_tables:
            continue
        rows = [
            [f"{k + 1} {joint}", *[_cell(data, r, m, joint) for r in recs]]
            for k, joint in enumerate(joints)
        ]
        header = ["joint", *[_head(data, r) for r in recs]]
        lines += [f"#### {m.heading}", "", _table(header, rows), ""]
    return lines


def _paper_scenarios(data: ReportData) -> list[str]:
    """Groups (scenarios, campaign conditions) whose recordings say they reproduce the
    paper (settings contract)."""
    group = data.episodes.select("episode", "group").rows_by_key("episode", unique=True)
    marked = {
        group[rec.episode][0]
        for rec in data.recordings
        if (view := data.protocol.get(rec.episode)) is not None
        and view.settings is not None
        and view.settings.protocol.reproduces_paper
    }
    return sorted(marked)


def _exact(data: ReportData, scenario: str) -> bool | None:
    """Whether the scenario's plant is the nominal model (None: unknown)."""
    flags = {
        view.settings.plant.exact
        for rec in data.in_group(scenario)
        if (view := data.protocol.get(rec.episode)) is not None and view.settings is not None
    }
    return flags.pop() if len(flags) == 1 else None


def _paper_pairs(
    data: ReportData, only: str | None = None
) -> tuple[str, list[tuple[str, str]]] | None:
    """(scenario, [(PID episode, CTC episode), ...]) to put beside the paper.

    Scenario "paper" first, else the first with both controllers completed. Pairs as in
    the comparisons: a CTC run with the PID run of its seed when there is one, else
    with every PID run.
    """
    eps = data.episodes.with_columns(pl.col("controller").str.to_lowercase())
    eps = eps.filter(pl.col("controller").is_in([paper.PAPER_BASELINE, paper.PAPER_CANDIDATE]))
    found = pairs(eps, baseline=paper.PAPER_BASELINE)
    for scenario in sorted(data.groups(), key=lambda s: (s != "paper", s)):
        if only is not None and scenario != only:
            continue
        chosen = [(b, c) for sc, b, c in found if sc == scenario]
        if chosen:
            return scenario, chosen
    return None


def _red(base: Any, cand: Any, by: Any) -> Any:
    if base is None or cand is None or by is None or abs(float(by)) < ERROR_FLOOR_RAD:
        return None
    return (float(base) - float(cand)) / float(by) * 100.0


def _versus_paper(data: ReportData) -> list[str]:
    marked = _paper_scenarios(data)
    if not marked:
        return [
            "## Versus the paper",
            "",
            "No scenario here is marked as the paper's experiment (`reproduces_paper: true` "
            "in params), so nothing is compared with the paper's numbers.",
            "",
        ]
    out: list[str] = []
    for scenario in marked:
        out += _versus_paper_one(data, scenario)
    return out


def _versus_paper_one(data: ReportData, only: str) -> list[str]:
    exact = _exact(data, only)
    kind = (
        "ideal plant: the nominal model is the plant, so CTC's model terms are exact by "
        "construction"
        if exact
        else "realistic plant: it differs from the nominal model (see its setup)"
        if exact is False
        else "plant unknown"
    )
    lines = [f"## Versus the paper: `{only}` ({kind})", ""]
    found = _paper_pairs(data, only)
    if found is None:
        return [
            *lines,
            "No scenario has both a `pid` and a `ctc` episode that completed, so there is "
            "nothing to put beside the paper.",
            "",
        ]
    scenario, pair_list = found
    pid_eps = list(dict.fromkeys(b for b, _ in pair_list))
    ctc_eps = list(dict.fromkeys(c for _, c in pair_list))
    joints = data.recording(pid_eps[0]).joint_names
    n_pairs = len(pair_list)

    def per_episode(episodes: list[str], joint: str | None, metric: str) -> MeanCI:
        if joint is None:
            return MeanCI(0, None, None, None)
        return mean_ci(_metric(data, e, joint, metric) for e in episodes)

    def per_pair(joint: str | None, metric: str, divide_by: str) -> MeanCI:
        """(PID − CTC) / (PID or CTC) × 100 of each pair, summarised."""
        if joint is None:
            return MeanCI(0, None, None, None)
        values = []
        for b, c in pair_list:
            vp, vc = _metric(data, b, joint, metric), _metric(data, c, joint, metric)
            values.append(_red(vp, vc, vp if divide_by == "pid" else vc))
        return mean_ci(values)

    def pct(ci: MeanCI, divide_by: str = "pid") -> str:
        """A percentage, or, where one controller is more than twice the other, the ratio
        by name ("CTC 4.0× PID's"): -3600 % or +3600 % say less."""
        mean = ci.mean
        if mean is not None and divide_by == "pid" and mean < RATIO_BELOW_PCT:
            return f"CTC {1.0 - mean / 100.0:.3g}× PID's" + ("" if n_pairs == 1 else " (mean)")
        if mean is not None and divide_by == "ctc" and mean > -RATIO_BELOW_PCT:
            return f"PID {1.0 + mean / 100.0:.3g}× CTC's" + ("" if n_pairs == 1 else " (mean)")
        return _pct(mean) if n_pairs == 1 else _ci_pct(ci)

    def val(ci: MeanCI, fmt: Any, hw_fmt: Any = None) -> str:
        if ci.mean is None:
            return NA
        return fmt(ci.mean) if n_pairs == 1 else _ci(ci, fmt, hw_fmt)

    def vel(x: float) -> str:
        return _signed(x, 2)

    def vel_hw(x: float) -> str:
        return f"{x:.2f}"

    if n_pairs == 1:
        ((pid, ctc),) = pair_list
        ours = f"episodes `{pid}` (PID) and `{ctc}` (CTC)"
    else:
        seeds = sorted({data.recording(c).meta("seed") for c in ctc_eps}, key=lambda x: (len(x), x))
        ours = (
            f"{n_pairs} PID/CTC pairs ({len(pid_eps)} PID and {len(ctc_eps)} CTC runs, "
            f"seeds {', '.join(seeds)}): mean ± {CONFIDENCE * 100:.0f} % confidence interval "
            "(Student t) over the runs, reductions per pair"
        )

    def verdict(ci: MeanCI) -> str:
        """Does "CTC below PID" hold: by the CI when there are several pairs."""
        if ci.mean is None:
            return "n/a"
        if ci.half_width is None:
            return "holds" if ci.mean > 0 else "does not hold"
        if ci.mean - ci.half_width > 0:
            return "holds"
        if ci.mean + ci.half_width < 0:
            return "does not hold"
        return "inconclusive"

    def by_verdict(metric: str) -> str:
        groups: dict[str, list[str]] = {}
        for k, joint in enumerate(joints[:5]):  # the paper's claims are about joints 1-5
            groups.setdefault(verdict(per_pair(joint, metric, "pid")), []).append(str(k + 1))
        return "; ".join(f"{v} on joint{'s' if len(js) > 1 else ''} {', '.join(js)}"
                         for v, js in groups.items())  # fmt: skip

    j1_ci = per_pair(joints[0], "max_abs_error", "pid")
    claims = [
        [
            "CTC's max tracking error on joint 1 is smaller than PID's (45.9 % smaller)",
            f"{verdict(j1_ci)}: {pct(j1_ci)} smaller",
        ],
        [
            "CTC's max tracking error is smaller on joints 1-5 (Figs. 6-7)",
            by_verdict("max_abs_error"),
        ],
        [
            "CTC's error at the target is smaller on joints 1-5 (Table 3)",
            by_verdict("final_error"),
        ],
    ]
    lines += [
        f"Ours: scenario **{scenario}**, {ours}. Paper: {paper.PAPER_SOURCE}.",
        "",
        "**The paper's claims here** (a claim *holds* when CTC is below PID; with several "
        "seed pairs, when the whole confidence interval of the paired reduction is above "
        "zero; *inconclusive* when it straddles zero):",
        "",
        _table(["claim", "here"], claims),
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
    pp, pc = paper.PAPER_JOINT1_MAX_ERROR_RAD["pid"], paper.PAPER_JOINT1_MAX_ERROR_RAD["ctc"]
    rows = [
        ["CTC max |e| [rad]", _sci(pc), val(per_episode(ctc_eps, j1, "max_abs_error"), _sci)],
        ["PID max |e| [rad]", _sci(pp), val(per_episode(pid_eps, j1, "max_abs_error"), _sci)],
        [
            "(PID − CTC) / PID",
            f"{paper.PAPER_JOINT1_MAX_ERROR_REDUCTION_PCT:.1f} % (printed)",
            pct(per_pair(j1, "max_abs_error", "pid")),
        ],
        [
            "(PID − CTC) / CTC",
            _pct(_red(pp, pc, pc)),
            pct(per_pair(j1, "max_abs_error", "ctc"), "ctc"),
        ],
    ]
    lines += [_table(["joint 1", "paper", "ours"], rows), ""]
    lines += ["#### Error at the target (paper Table 3), ×1e-5 rad", ""]

    def e5(x: float) -> str:
        return f"{x * 1e5:.4f}"

    rows = []
    for k in range(len(paper.PAPER_FINAL_ERROR_REDUCTION_PCT)):
        joint = joints[k] if k < len(joints) else None
        pc_k = paper.PAPER_FINAL_ERROR_RAD["ctc"][k]
        pp_k = paper.PAPER_FINAL_ERROR_RAD["pid"][k]
        rows.append(
            [
                str(k + 1),
                f"{pc_k * 1e5:.4f}",
                f"{pp_k * 1e5:.4f}",
                f"{paper.PAPER_FINAL_ERROR_REDUCTION_PCT[k]:.1f} %",
                _pct(_red(pp_k, pc_k, pp_k)),
                val(per_episode(ctc_eps, joint, "final_error"), e5),
                val(per_episode(pid_eps, joint, "final_error"), e5),
                pct(per_pair(joint, "final_error", "ctc"), "ctc"),
                pct(per_pair(joint, "final_error", "pid")),
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
        rows.append(
            [
                f"{number} {joint or ''}".strip(),
                f"{paper.PAPER_PEAK_VELOCITY_RAD_S['ctc'][number]:+.2f}",
                val(per_episode(ctc_eps, joint, "peak_velocity"), vel, vel_hw),
                f"{paper.PAPER_PEAK_VELOCITY_RAD_S['pid'][number]:+.2f}",
                val(per_episode(pid_eps, joint, "peak_velocity"), vel, vel_hw),
            ]
        )
    lines += [_table(["joint", "paper CTC", "ours CTC", "paper PID", "ours PID"], rows), ""]
    return lines


def _definitions() -> list[str]:
    cs, js = f"`{TOPIC_CONTROLLER_STATE}`", f"`{TOPIC_JOINT_STATES}`"
    return [
        "## Definitions",
        "",
        "- error e(t) = reference − true joint position [rad] where the recording carries "
        f"the plant's true state (`{TOPIC_GROUND_TRUTH}`, simulation), else reference − "
        f"measured position as recorded on {cs} (`error.positions`; a real robot's bag); "
        "the *error from* column of the episode table says which. Every error-based number "
        f"(max, RMS, at the target, settling, overshoot) uses every {cs} message, at its "
        f"full rate; velocities (true where recorded) and efforts come from {js} (which may "
        "be decimated). Times count from the motion start: the pre-roll before it (the "
        "controller holding the start pose) takes no part.",
        "- max |error|: largest |e| over the episode; RMS error: sqrt(mean e²) over the episode.",
        f"- error at the target: mean |e| over the last min({FINAL_WINDOW_S} s, hold / 2) of the "
        "episode, hold = episode end − motion end (motion end = the planned trajectory's "
        "duration); the last sample alone when there is no hold.",
        f"- settling time: from the motion end until |e| stays within {SETTLING_TOLERANCE_RAD:g} "
        "rad for the rest of the episode; 'never settles' when the last sample is outside.",
        "- overshoot: how far the position (true where recorded, else `feedback.positions`) "
        "passes the goal in the direction of travel (n/a for a joint that does not move).",
        f"- '{ENDED_EARLY}': the episode failed or its recording stops before the motion end, "
        "so its last samples are not at the target: error at the target, settling time and "
        "overshoot are not given (max and RMS are, over what was recorded).",
        f"- '{SALVAGE_CUT}': a salvaged recording (`--salvage`) whose motion end is not "
        "recorded: where it stops is where the file is damaged, not the episode's end.",
        f"- peak velocity: the velocity of largest magnitude, with its sign (true where "
        f"recorded, else {js}).",
        "- reduction: (baseline − candidate) / baseline × 100 %; a candidate more than twice "
        'the baseline is shown as a ratio ("3.7× the baseline\'s") instead of a large '
        "negative percentage.",
        f"- RMS effort: sqrt(mean applied effort²) ({js} `effort`); saturation: share of "
        f"{js} samples where |applied effort| is at the joint's effort limit or |commanded| "
        f"({cs} `output.effort`) exceeds |applied|.",
        f"- '{NOT_RECORDED}': the recording carries no such values (empty arrays are legal "
        "in ROS messages); they are never read as zeros.",
        "- reduction % = (baseline − candidate) / baseline × 100; shown as '—' when "
        f"|divisor| < {_FLOOR} rad (numerical noise: a perfect-model CTC settles "
        "to ~1e-13 rad), the same in metrics.json (null) and every table.",
        f"- repeated runs (several seeds of a scenario and controller): mean ± "
        f"{CONFIDENCE * 100:.0f} % confidence interval, t(0.975, n − 1) · s / √n with the sample "
        "standard deviation s, and n; reductions are computed per seed pair first.",
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
        for rec in data.recordings[:MAX_ROWS]
    ]
    more = len(data.recordings) - len(rows)
    return [
        "## Recordings",
        "",
        "Every number and figure above comes from these files"
        + (
            f" (the first {len(rows)} of {len(data.recordings)}; every one in "
            "[`recordings.csv`](recordings.csv))"
            if more
            else ""
        )
        + ":",
        "",
        _table(["episode", "file", "bytes", "SHA-256"], rows),
        "",
    ]


def render_report(
    data: ReportData,
    figures: dict[str, list[FigureFile]],
    *,
    omitted_figures: Sequence[str] = (),
    campaigns: Sequence[CampaignSection] = (),
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
    for section in campaigns:
        conditions = [
            g for g in data.groups() if g == section.name or g.startswith(f"{section.name}/")
        ]
        head, rest = list(section.lines[:4]), list(section.lines[4:])
        if conditions:
            # robot, plant, planner and gains as run (those of the first condition)
            setup = _setup(data, conditions[0])
            setup[0] = f"### Setup (`{conditions[0]}`)"
            head += [*setup, ""]
        lines += [*head, *rest, ""]
        for group in conditions[:MAX_CONDITION_TABLES]:
            if data.repeated(group):
                lines += [f"### `{group}`", "", *_aggregate_tables(data, group)]
        if len(conditions) > MAX_CONDITION_TABLES:
            lines += [
                f"Mean ± CI tables for the first {MAX_CONDITION_TABLES} conditions only; the "
                f"rest: metrics.json (`aggregates`, `headline`) and `{section.table_path}`.",
                "",
            ]
    lines += _versus_paper(data)
    lines += _definitions()
    lines += _provenance(data)
    return "\n".join(lines).rstrip("\n") + "\n"
