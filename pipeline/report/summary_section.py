"""The report's opening: the answer first (headline table, one verdict per question).

Every number comes from :mod:`pipeline.analysis.headline`; this module words it.
"""

from __future__ import annotations

from typing import get_args

from pipeline.analysis import headline as summary
from pipeline.analysis.aggregate import CONFIDENCE, MeanCI
from pipeline.analysis.catalog import BY_NAME
from pipeline.analysis.verdict import (
    ALPHA,
    EQUIVALENCE_REL,
    MIN_PAIRS,
    resolution_text,
)
from pipeline.report import md
from pipeline.report.inputs import ReportData

# The headline table shows at most this many (group, controller) columns.
MAX_HEADLINE_COLUMNS = 8
# At most this many verdict lines (the rest: the sections below and metrics.json).
MAX_QUESTIONS = 8

_TASK_ROWS = {
    "tcp_max_position_error": "TCP max position error [mm]",
    "tcp_max_orientation_error": "TCP max orientation error [mrad]",
}


def _columns(data: ReportData) -> list[tuple[str, str]]:
    cols: list[tuple[str, str]] = []
    for group in data.groups():
        for c in dict.fromkeys(r.controller for r in data.in_group(group) if r.status == "ok"):
            cols.append((group, c))
    return cols


def _cell(ci: MeanCI | None, fmt: str) -> str:
    if ci is None or ci.mean is None:
        return md.NA
    if ci.half_width is None:
        return format(ci.mean, fmt)
    return f"{format(ci.mean, fmt)} ± {ci.half_width:.1e}"


def _joints(data: ReportData, group: str) -> list[str]:
    recs = data.in_group(group)
    return list(recs[0].joint_names) if recs else []


def _numbers(joints: list[int]) -> str:
    return ", ".join(str(k) for k in joints)


def _effect(e: summary.Effect, unit_name: str) -> str:
    ci = e.reduction
    if ci.mean is None:
        return f"{unit_name}: n/a"
    size = md.pct(ci.mean)
    if ci.half_width is not None and ci.mean >= md.RATIO_BELOW_PCT:
        size = f"{ci.mean:.1f} ± {ci.half_width:.1f} %"
    return f"{unit_name} {e.direction} ({size})"


_DIRECTIONS: tuple[summary.Direction, ...] = tuple(
    d for d in get_args(summary.Direction) if d != "n/a"
)


def _question(q: summary.Question) -> str:
    pairs = (
        f"{q.pairs} seed pair{'s' if q.pairs != 1 else ''}"
        if q.pairing == "seed"
        else f"{q.pairs} pairs (runs do not share seeds: every baseline run with every "
        "candidate run)"
    )
    by = q.joints_by_direction()
    joint_parts = [f"{d} on joint{'s' if len(by[d]) > 1 else ''} {_numbers(by[d])}"
                   for d in _DIRECTIONS if by.get(d)]  # fmt: skip
    task = (
        "; ".join(_effect(e, BY_NAME[e.metric].title.removeprefix("TCP ")) for e in q.task_space)
        if q.task_space
        else "n/a (no robot model in the bag)"
    )
    single = (
        "; one pair, no test: the sign of one run"
        if q.pairs == 1
        else f"; too few pairs for a test (fewer than {MIN_PAIRS}): signs untested"
        if q.pairs < MIN_PAIRS
        else ""
    )
    return (
        f"- **{q.candidate} vs {q.baseline}** in `{q.group}` ({pairs}{single}): "
        f"joint space, max |error| {'; '.join(joint_parts) or 'n/a'}; "
        f"task space (TCP), {task}."
    )


def summary_section(data: ReportData) -> list[str]:
    """The headline table and the verdicts, before every detail."""
    cols = _columns(data)
    shown = cols[:MAX_HEADLINE_COLUMNS]
    joints: list[str] = []
    for group, _ in shown:
        joints += [j for j in _joints(data, group) if j not in joints]
    cells = summary.headline_table(data.metric_summary, shown, joints)
    many_groups = len({g for g, _ in shown}) > 1
    header = ["max |error|", *[f"{g}: {c}" if many_groups else c for g, c in shown]]
    rows = [
        [f"{k + 1} {j} [rad]", *[_cell(cells.get((g, c, j)), ".2e") for g, c in shown]]
        for k, j in enumerate(joints)
    ]
    has_tcp = any(key[2] in _TASK_ROWS for key in cells)
    if has_tcp:
        rows += [
            [label, *[_cell(cells.get((g, c, m)), ".3g") for g, c in shown]]
            for m, label in _TASK_ROWS.items()
        ]
    lines = [
        "## Answer",
        "",
        "Max |error| per joint"
        + (" and at the tool centre point (TCP)" if has_tcp else "")
        + ", per "
        + ("group and " if many_groups else "")
        + f"controller: the mean over completed runs, ± the {CONFIDENCE * 100:.0f} % "
        "interval where a controller ran several times.",
        "",
        md.table(header, rows),
    ]
    if len(cols) > len(shown):
        lines += ["", f"… {len(cols) - len(shown)} more columns: metrics.json (`aggregates`)."]
    joints_of = {g: _joints(data, g) for g in data.groups()}
    qs = summary.questions(data.reduction_summary, joints_of)
    lines += ["", "### Verdicts", ""]
    if not qs:
        lines.append(
            "One controller only, or no completed baseline/candidate pair: nothing to compare."
        )
    else:
        lines.append(
            f"Does the candidate have a lower max error than the baseline **{data.baseline}**? "
            "One rule for every comparison of this report (the win/loss tables and the "
            "paper's claims use it too): *equivalent* when the difference is within the "
            f"practical margin (the larger of the encoder's resolution, {resolution_text()}, "
            f"and {EQUIVALENCE_REL * 100:.0f} % of the baseline); "
            f"else, from {MIN_PAIRS} pairs, a two-sided Wilcoxon signed-rank test of the "
            f"per-pair differences (Mann-Whitney U when seeds do not pair), *lower* / "
            f"*higher* when p < {ALPHA:g}, else *no clear difference*; with fewer pairs no "
            "test: the sign of the mean per-pair reduction (baseline − candidate) / "
            "baseline, marked *untested*."
        )
        lines.append("")
        lines += [_question(q) for q in qs[:MAX_QUESTIONS]]
        if len(qs) > MAX_QUESTIONS:
            lines.append(f"- … {len(qs) - MAX_QUESTIONS} more: see the sections below.")
    return [*lines, ""]
