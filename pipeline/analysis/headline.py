"""The answer a report opens with: the headline numbers and one verdict per question.

A question is "does the candidate controller track better than the baseline in this group
(scenario or campaign condition)?", asked in joint space (max |error| per joint) and in
task space (the TCP's max position and orientation errors). It is decided by the
report's one rule (:func:`pipeline.analysis.verdict.compare`, through
:func:`pipeline.analysis.aggregate.reduction_aggregates`' ``verdict``): "equivalent"
within the practical margin; "lower" / "higher" / "no clear difference" by the test,
which needs :data:`pipeline.analysis.verdict.MIN_PAIRS` pairs; below that, the sign of
the mean reduction, untested (one pair: the sign of one run).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, cast

import polars as pl

from pipeline.analysis.aggregate import MeanCI
from pipeline.analysis.catalog import TCP_JOINT
from pipeline.analysis.verdict import Outcome

# The metric the headline table and the verdicts use, per space.
HEADLINE_JOINT_METRIC = "max_abs_error"
HEADLINE_TASK_METRICS = ("tcp_max_position_error", "tcp_max_orientation_error")

Direction = Literal[
    "lower",
    "higher",
    "no clear difference",
    "equivalent",
    "lower (untested)",
    "higher (untested)",
    "n/a",
]
"""Tested: lower, higher, no clear difference; equivalent: within the practical margin;
untested: too few pairs for a test, the sign of the mean reduction."""


@dataclass(frozen=True)
class Effect:
    """The paired reduction of one metric on one joint (or the TCP).

    Attributes:
        joint: the joint, or :data:`pipeline.analysis.catalog.TCP_JOINT`.
        metric: the metric (``max_abs_error``, ``tcp_max_position_error``, ...).
        reduction: the per-pair reductions (baseline − candidate) / baseline × 100 [%],
            summarised (n = pairs).
    """

    joint: str
    metric: str
    reduction: MeanCI
    outcome: Outcome = "n/a"

    @property
    def direction(self) -> Direction:
        """The candidate's error against the baseline's, by the report's one rule
        (:func:`pipeline.analysis.verdict.compare`); with too few pairs, the sign of the
        mean reduction, marked untested."""
        if self.outcome == "too few pairs":
            mean = self.reduction.mean
            if not mean:
                return "n/a" if mean is None else "no clear difference"
            return "lower (untested)" if mean > 0 else "higher (untested)"
        return _WORDS[self.outcome]


_WORDS: dict[Outcome, Direction] = {
    "better": "lower",
    "worse": "higher",
    "no clear difference": "no clear difference",
    "equivalent": "equivalent",
    "too few pairs": "n/a",
    "n/a": "n/a",
}


@dataclass(frozen=True)
class Question:
    """Candidate vs baseline in one group, joint and task space.

    Attributes:
        group: the scenario or campaign condition.
        baseline, candidate: the controllers.
        pairing: ``seed`` (same-seed pairs) or ``all`` (every baseline run with every
            candidate run).
        pairs: the most pairs any effect has.
        joint_space: :data:`HEADLINE_JOINT_METRIC` per joint, in recorded order.
        task_space: :data:`HEADLINE_TASK_METRICS` of the TCP (empty without a robot model).
    """

    group: str
    baseline: str
    candidate: str
    pairing: str
    pairs: int
    joint_space: tuple[Effect, ...]
    task_space: tuple[Effect, ...]

    def joints_by_direction(self) -> dict[Direction, list[int]]:
        """Joint numbers (1-based) by direction of the joint-space effect."""
        out: dict[Direction, list[int]] = {}
        for k, e in enumerate(self.joint_space):
            out.setdefault(e.direction, []).append(k + 1)
        return out


def _ci(row: dict[str, object]) -> MeanCI:
    def f(key: str) -> float | None:
        v = row.get(key)
        return float(v) if isinstance(v, int | float) else None

    n = row.get("n")
    return MeanCI(int(n) if isinstance(n, int) else 0, f("mean"), f("std"), f("ci95_half_width"))


def _effect(by: dict[tuple[str, str], dict[str, object]], joint: str, metric: str) -> Effect | None:
    row = by.get((joint, f"{metric}_reduction_pct"))
    if row is None:
        return None
    outcome = row.get("verdict")
    return Effect(joint, metric, _ci(row), cast(Outcome, outcome) if outcome else "n/a")


def questions(reduction_summary: pl.DataFrame, joints: dict[str, list[str]]) -> list[Question]:
    """One question per (group, candidate) of
    :func:`pipeline.analysis.aggregate.reduction_aggregates`, groups sorted.

    Args:
        reduction_summary: the paired reductions, summarised.
        joints: per group, its joints in recorded order.
    """
    out: list[Question] = []
    frame = reduction_summary.sort("scenario", maintain_order=True)
    for (group, base, cand, pairing), rows in frame.group_by(
        "scenario", "baseline", "controller", "pairing", maintain_order=True
    ):
        by = {(r["joint"], r["metric"]): r for r in rows.iter_rows(named=True)}

        joint_space = [_effect(by, j, HEADLINE_JOINT_METRIC) for j in joints.get(str(group), [])]
        task_space = [_effect(by, TCP_JOINT, m) for m in HEADLINE_TASK_METRICS]
        found = [e for e in (*joint_space, *task_space) if e is not None]
        out.append(
            Question(
                group=str(group),
                baseline=str(base),
                candidate=str(cand),
                pairing=str(pairing),
                pairs=max((e.reduction.n for e in found), default=0),
                joint_space=tuple(e for e in joint_space if e is not None),
                task_space=tuple(
                    e for e in task_space if e is not None and e.reduction.mean is not None
                ),
            )
        )
    return out


def headline_table(
    metric_summary: pl.DataFrame, columns: list[tuple[str, str]], joints: list[str]
) -> dict[tuple[str, str, str], MeanCI]:
    """(group, controller, row) -> mean ± CI of the headline metric, the rows being the
    ``joints`` (max |error| [rad]) and the TCP metrics (``tcp_max_position_error``,
    ``tcp_max_orientation_error``)."""
    wanted = {HEADLINE_JOINT_METRIC, *HEADLINE_TASK_METRICS}
    frame = metric_summary.filter(pl.col("metric").is_in(wanted))
    cols = set(columns)
    out: dict[tuple[str, str, str], MeanCI] = {}
    for r in frame.iter_rows(named=True):
        if (r["scenario"], r["controller"]) not in cols:
            continue
        row = r["joint"] if r["metric"] == HEADLINE_JOINT_METRIC else r["metric"]
        if row in joints or r["joint"] == TCP_JOINT:
            out[(r["scenario"], r["controller"], row)] = _ci(r)
    return out


# ``dvc metrics diff`` prints one line per changed scalar under a 1-line header (measured,
# docs/report.md "Headline numbers for DVC"): at most this many scalars in headline.json
# for the default experiment keep even ``--all`` within 60 lines
# (tests/report/test_headline_json.py).
HEADLINE_MAX_SCALARS = 59


def _row_key(e: Effect) -> str:
    return {
        "tcp_max_position_error": "tcp_position",
        "tcp_max_orientation_error": "tcp_orientation",
    }.get(e.metric, e.joint)


def headline_questions(qs: list[Question]) -> list[Question]:
    """The questions headline.json holds: those with an interval (two pairs or more), or
    every question when none has one.

    A baseline gain change moves every reduction against that baseline, so every scalar of
    the file changes. Each question with an interval is 2 scalars per row (6 joints and 2
    TCP rows: 16); the default experiment's two realistic-plant questions are 32, which
    with ``dvc exp show --only-changed``'s fixed columns, the changed params and the
    ``recordings`` dependency is 38 to 40 columns. The ideal plant's single pair (8
    reductions, no interval) would make it 46 to 48, over the 40 the table is held to; it
    stays in metrics.json's ``headline`` and in report.md's answer."""
    with_interval = [q for q in qs if q.pairs >= 2]
    return with_interval or qs


def headline_document(qs: list[Question]) -> dict[str, dict[str, dict[str, object]]]:
    """The small DVC metric over :func:`headline_questions`: ``<group>.<candidate>_vs_<baseline>``
    holds ``n`` (the pairs) and per ``<joint | tcp_position | tcp_orientation>`` the
    ``max_error_reduction_pct`` and, where there are two pairs or more, its
    ``ci95_half_width`` (nested dicts of scalars only: DVC shows a list as one text
    column, without a change). The reduction is the mean per-pair reduction of the max
    error (max |error| per joint, the TCP's max position and orientation errors) [%], with
    its paired 95 % half width. A row whose pairs differ from the comparison's ``n`` (a
    metric missing in some episodes) carries its own ``n``. One ``n`` per comparison, no
    null half widths: every scalar can change between experiments, and a gain change's
    ``dvc metrics diff`` stays short."""
    out: dict[str, dict[str, dict[str, object]]] = {}
    for q in headline_questions(qs):
        node: dict[str, object] = {"n": q.pairs}
        for e in (*q.joint_space, *q.task_space):
            ci = e.reduction
            row: dict[str, object] = {
                "max_error_reduction_pct": None if ci.mean is None else round(ci.mean, 4)
            }
            if ci.half_width is not None:
                row["ci95_half_width"] = round(ci.half_width, 4)
            if ci.n != q.pairs:
                row["n"] = ci.n
            node[_row_key(e)] = row
        out.setdefault(q.group, {})[f"{q.candidate}_vs_{q.baseline}"] = node
    return out
