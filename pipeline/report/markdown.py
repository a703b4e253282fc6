"""reports/report.md: GitHub-flavoured Markdown with relative links to the figures.

This module assembles the report and writes the sections that are tables of the metric
frames (episodes, tracking, repeated runs, recordings); the others have a module each:
:mod:`pipeline.report.setup`, :mod:`pipeline.report.physical_checks`,
:mod:`pipeline.report.paper_section` and :mod:`pipeline.report.definitions`. Every number they
show is computed in :mod:`pipeline.analysis`; shared helpers are in :mod:`pipeline.report.md`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import polars as pl

from pipeline.analysis import catalog
from pipeline.analysis.aggregate import CONFIDENCE, MeanCI
from pipeline.analysis.episodes import shown_status
from pipeline.analysis.findings import (
    SATURATION_WARN_FRACTION,
    check_alerts,
    check_grid,
    physical_checks,
    unsettled_joints,
    worst_saturation,
)
from pipeline.log.reader import Recording
from pipeline.report import md
from pipeline.report.campaign_section import CampaignSection
from pipeline.report.definitions import definitions_section
from pipeline.report.figures import FigureFile
from pipeline.report.inputs import ReportData
from pipeline.report.md import (
    ENDED_EARLY,
    FLOOR,
    MAX_EPISODE_COLUMNS,
    MAX_ROWS,
    NA,
    NOT_RECORDED,
    SALVAGE_CUT,
)
from pipeline.report.paper_section import versus_paper
from pipeline.report.physical_checks import check_banner, physical_checks_section
from pipeline.report.setup import setup_section
from pipeline.report.summary_section import summary_section
from pipeline.sim.settling import SETTLING

REPORT_FILE = "report.md"
# A campaign's mean ± CI tables are written for at most this many conditions.
MAX_CONDITION_TABLES = 4


# --- helpers ------------------------------------------------------------------------------------


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
    motion_end = rec.trajectory_duration_s
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
    if m.space == "task":
        return "n/a (no robot model in the bag)"
    if m.frame == "joint_states":
        return NOT_RECORDED
    if metric == "settling_time":
        return "n/a (motion end unknown)" if rec.trajectory_duration_s is None else "never settles"
    return NA


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
    typed = [r.settings for r in recs]
    versions = sorted({md.value(s.package_version if s else None) or md.NA for s in typed})
    commits = sorted({md.value(s.git_commit if s else None) or md.NA for s in typed})
    checks = physical_checks(data.recordings, data.protocol, data.metrics)
    grid = check_grid(data.recordings, data.protocol, data.metrics, checks)
    joints = list(dict.fromkeys(c.joint for c in grid if c.joint))
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
        *check_banner(check_alerts(grid), joints),
        *summary_section(data),
        "Interactive view: [`recording.rrd`](recording.rrd), next to this file: open it with "
        "`rerun recording.rrd` (per-joint time series, the arm in 3D per controller).",
        "Numbers: [`metrics.json`](metrics.json); series for `dvc plots`: "
        "[`plots/errors.csv`](plots/errors.csv), [`plots/velocities.csv`](plots/velocities.csv).",
        "",
        "## Episodes",
        "",
    ]
    rows = []
    worst_sat = worst_saturation(data.metrics)
    unsettled = unsettled_joints(data.metrics, data.protocol)
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
                md.num(row["motion_end_s"], ".3f"),
                md.num(row["end_s"], ".3f"),
                _samples(row["samples"], row["controller_samples"]),
                row["error_source"] or NA,
                md.sci(row["start_abs_error_rad"], 1),
                md.num(row["start_abs_effort_nm"], ".1f"),
                NA if sat is None else f"{sat * 100:.1f} %",
                unsettled.get(row["episode"], NA),
            ]
        )
    lines.append(
        md.table(
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
        "under its own controller until settled, at most the scenario's `preroll_s` (the "
        "pre-roll, recorded in the bag before the planned "
        "trajectory's stamp), so metrics measure tracking, not a cold start. *Error from*: "
        "the plant's true state (`/ground_truth/joint_states`, simulation) or the measured "
        "one (a real robot's bag). *At start*: the worst joint at the motion start. "
        f"*Saturated*: share of samples at the effort limit, worst joint (flagged above "
        f"{SATURATION_WARN_FRACTION * 100:.0f} %); *status* ok = stable (not diverged); "
        "*salvaged*: read with `--salvage` from a damaged file up to the damage (the share "
        "of the file, or of a `.db3`'s messages, not read); cut before its motion end, "
        "such an episode takes no part in comparisons. *Error at the target*: **settled** "
        "when the hold's last window meets the settling criterion the pre-roll ends on "
        f"(on every joint, e moves less than {SETTLING.error_change_rad:g} rad, |qd| < "
        f"{SETTLING.velocity_rad_s:g} rad/s, the integral term moving less than "
        f"{SETTLING.integral_rad:g} rad, for {SETTLING.window_s:g} s); the hold goes on "
        "until then, up to the scenario's `hold_max_s`. **Not settled (hold capped)**: a "
        "transient, not a steady state: it takes part in no verdict. In bags that do not "
        "record it: not settled on the joints whose mean |e| changes between the two "
        f"halves of the final window by more than {catalog.FINAL_DRIFT_REL:g} x it (and "
        f"{catalog.DRIFT_FLOOR_RAD:g} rad).",
    ]
    lines += physical_checks_section(checks, grid)
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


# The compared metrics: aggregate and per-episode tables with reductions (joint space: a
# table per metric; task space: one table, a row per metric, of the TCP rows).
_ERROR_TITLES = tuple(
    (m.name, m.heading) for m in catalog.METRICS if m.compared and m.space == "joint"
)
_TCP_METRICS = tuple(m for m in catalog.METRICS if m.compared and m.space == "task")
_TCP_HEADING = "Task space: tool centre point (TCP)"


def _has_tcp(data: ReportData, episodes: Sequence[str]) -> bool:
    return any(data.metric(e, catalog.TCP_JOINT, m.name) is not None
               for e in episodes for m in _TCP_METRICS)  # fmt: skip


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
                row.append(md.mean_ci(ci, lambda x: f"{x:.3e}", lambda x: f"{x:.1e}"))
            for c in candidates:
                ci = cell(
                    reductions.filter(
                        (pl.col("controller") == c)
                        & (pl.col("joint") == joint)
                        & (pl.col("metric") == f"{metric}_reduction_pct")
                    )
                )
                row.append(md.mean_ci_pct(ci))
            rows.append(row)
        lines += [f"##### {title}", "", md.table(header, rows), ""]
    if not _has_tcp(data, [r.episode for r in recs]):
        return lines
    header = ["TCP metric", *controllers]
    header += [f"{c} vs {data.baseline} (per pair)" for c in candidates]
    rows = []
    for m in _TCP_METRICS:
        row = [m.heading]
        for c in controllers:
            ci = cell(
                summary.filter(
                    (pl.col("controller") == c)
                    & (pl.col("joint") == catalog.TCP_JOINT)
                    & (pl.col("metric") == m.name)
                )
            )
            row.append(md.mean_ci(ci, lambda x: f"{x:.3g}", lambda x: f"{x:.1g}"))
        for c in candidates:
            ci = cell(
                reductions.filter(
                    (pl.col("controller") == c)
                    & (pl.col("joint") == catalog.TCP_JOINT)
                    & (pl.col("metric") == f"{m.name}_reduction_pct")
                )
            )
            row.append(md.mean_ci_pct(ci))
        rows.append(row)
    lines += [f"##### {_TCP_HEADING}", "", md.table(header, rows), ""]
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
                row.append(_missing(data, r, metric) if v is None else md.sci(v))
            row += [md.pct(_reduction(data, b, c, joint, metric)) for b, c in pairs]
            rows.append(row)
        lines += [f"{level} {title}", "", md.table(header, rows), ""]
    if _has_tcp(data, [r.episode for r in recs]):
        header = ["TCP metric", *[_head(data, r) for r in recs]]
        header += [f"{data.label(c)} vs {data.label(b)}" for b, c in pairs]
        rows = []
        for m in _TCP_METRICS:
            row = [m.heading]
            for r in recs:
                v = _metric(data, r.episode, catalog.TCP_JOINT, m.name)
                row.append(_missing(data, r, m.name) if v is None else format(v, m.fmt))
            row += [md.pct(_reduction(data, b, c, catalog.TCP_JOINT, m.name)) for b, c in pairs]
            rows.append(row)
        lines += [f"{level} {_TCP_HEADING}", "", md.table(header, rows), ""]
    if pairs or repeated:
        lines.append(
            "Reduction = (baseline − candidate) / baseline × 100 (positive: the candidate "
            f"has the smaller error); '—' when |baseline| < {FLOOR} rad "
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
        lines += [f"#### {m.heading}", "", md.table(header, rows), ""]
    return lines


def _provenance(data: ReportData) -> list[str]:
    rows = [
        [
            rec.episode,
            f"`{rec.mcap_path.as_posix()}`",
            f"{rec.size_bytes:,}" if rec.sha256 else "-",
            f"`{rec.sha256}`" if rec.sha256 else "no bag (metric partial)",
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
        md.table(["episode", "file", "bytes", "SHA-256"], rows),
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
        lines += setup_section(data, scenario)
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
            setup = setup_section(data, conditions[0])
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
    lines += versus_paper(data)
    lines += definitions_section()
    lines += _provenance(data)
    return "\n".join(lines).rstrip("\n") + "\n"
