"""Tracking metrics per episode and joint, and reductions between controllers.

The metrics themselves are declared in :mod:`pipeline.analysis.catalog`; this module
prepares the frames they aggregate over and pairs episodes for reductions. Every metric is
computed in two steps, so a recording read in time slices (a long bag, window by window)
gives the same metrics as one read whole: :func:`metric_partials` over each slice (the
rows of both frames in one contiguous time interval; the prepared columns are row-local),
then :func:`finish_metrics` over the partial rows of all slices in time order.
:func:`joint_metrics` is the one-slice case.

What each metric is: its ``definition`` in :data:`pipeline.analysis.catalog.METRICS` (every
report's Definitions section and docs/report.md print that text). The rules common to all:
e = reference - position from the frames :mod:`pipeline.analysis.protocol` prepares (true
where recorded), times from the motion start; values not recorded (empty arrays, NaN) are
nulls and a metric of nothing recorded is null; reduction % = (baseline - candidate) /
baseline x 100, null when |baseline| is below :data:`ERROR_FLOOR_RAD` or missing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import polars as pl

from pipeline.analysis.catalog import (
    BY_NAME,
    COMPARED_METRICS,
    ERROR_FLOOR_RAD,
    METRIC_COLUMNS,
    METRIC_SOURCES,
    METRICS,
    MIN_TRAVEL_RAD,
    PARTIAL_COLUMNS,
    SETTLING_TOLERANCE_RAD,
    Frame,
)
from pipeline.analysis.episodes import comparable
from pipeline.analysis.task_space import TaskSpace, tcp_errors
from pipeline.constants import FINAL_EDGE_S, FINAL_WINDOW_S
from pipeline.errors import ReportError, unknown_name_message
from pipeline.log.topics import PAIRED_COLUMNS

__all__ = [
    "COMPARED_METRICS",
    "ERROR_FLOOR_RAD",
    "METRIC_COLUMNS",
    "METRIC_SOURCES",
    "MIN_TRAVEL_RAD",
    "PARTIAL_COLUMNS",
    "SETTLING_TOLERANCE_RAD",
    "check_baseline",
    "comparisons",
    "finish_metrics",
    "joint_metrics",
    "metric_partials",
    "pairs",
    "reduction_pct",
]

SATURATION_REL_TOL = 1e-6

_KEY = ["episode", "joint"]


def _episode_columns(episodes: pl.DataFrame, final_window_s: float) -> pl.DataFrame:
    completed = (
        pl.col("motion_completed")
        if "motion_completed" in episodes.columns
        else (pl.col("status") == "ok")
        if "status" in episodes.columns
        else pl.lit(True)
    )
    return episodes.select(
        "episode",
        "motion_end_s",
        "end_s",
        completed.fill_null(False).alias("completed"),
    ).with_columns(
        pl.when(pl.col("motion_end_s").is_null())
        .then(pl.lit(final_window_s))
        .otherwise(
            pl.min_horizontal(
                pl.lit(final_window_s),
                ((pl.col("end_s") - pl.col("motion_end_s")) / 2).clip(lower_bound=0.0),
            )
        )
        .alias("final_window_s")
    )


def _time_sorted(frame: pl.DataFrame) -> pl.DataFrame:
    """``frame`` in time order, with every paired topic's column.

    Every order-dependent partial (first/last, the settling scan, the peak's time) needs
    time order within an (episode, joint) group; a stable sort keeps the joints in
    recorded order. The columns the topic rows pair with the controller state
    (:data:`pipeline.log.topics.PAIRED_COLUMNS`) are taken from the rows, so a metric can
    read a new topic's column with no edit here: a frame made without one (not read by
    :mod:`pipeline.log.reader`) gets it as nulls, "not recorded", as the reader gives a
    recording without the topic.
    """
    absent = [c for c in PAIRED_COLUMNS if c not in frame.columns]
    if absent:
        frame = frame.with_columns(pl.lit(None, pl.Float64).alias(c) for c in absent)
    if _in_time_order(frame):
        return frame  # what the stable sort would give, unchanged
    return frame.sort("episode", "time_s", maintain_order=True)


def _in_time_order(frame: pl.DataFrame) -> bool:
    """True when ``frame`` is already in (episode, time) order, no nulls nor NaN in either
    (as recorded): the stable sort would leave it as it is. False says nothing."""
    h = frame.height
    if h < 2:
        return True
    ep, t = frame.get_column("episode"), frame.get_column("time_s")
    if ep.null_count() or t.null_count():
        return False
    e0, e1, t0, t1 = ep.slice(0, h - 1), ep.slice(1), t.slice(0, h - 1), t.slice(1)
    return bool(((e0 < e1) | ((e0 == e1) & (t0 <= t1))).all())


def _prepared_controller_states(
    controller_states: pl.DataFrame,
    episodes: pl.DataFrame,
    *,
    settling_tolerance_rad: float,
    final_window_s: float,
) -> pl.DataFrame:
    """The ``controller_state`` frame of the catalog: row-local columns only, so a time
    slice is prepared the same whether or not the rest of its episode is there."""
    e = pl.col("error_rad")
    t = pl.col("time_s")
    return (
        _time_sorted(controller_states)
        .join(_episode_columns(episodes, final_window_s), on="episode", how="left")
        .with_columns(
            after_motion=(t >= pl.col("motion_end_s")),
            in_final=(t >= pl.col("end_s") - pl.col("final_window_s") - FINAL_EDGE_S),
            final_late=(t >= pl.col("end_s") - pl.col("final_window_s") / 2 - FINAL_EDGE_S),
        )
        .with_columns(
            violating=(pl.col("after_motion") & (e.abs() > settling_tolerance_rad)).fill_null(
                False
            ),
        )
    )


def _prepared_joint_states(samples: pl.DataFrame, limits: pl.DataFrame | None) -> pl.DataFrame:
    """The ``joint_states`` frame of the catalog (with the saturation flag)."""
    if limits is None:
        limits = pl.DataFrame(
            schema={"episode": pl.String, "joint": pl.String, "effort_limit_nm": pl.Float64}
        )
    eff = pl.col("effort_nm")
    cmd = pl.col("commanded_effort_nm")
    limit = pl.col("effort_limit_nm")
    at_limit = limit.is_not_null() & (eff.abs() >= limit * (1 - SATURATION_REL_TOL))
    # clipped: beyond the limit when it is known (with an actuation delay the effort of a
    # row is an earlier command, so |commanded| > |effort| is no sign of clipping)
    clipped = cmd.is_not_null() & (
        pl.when(limit.is_not_null())
        .then(cmd.abs() > limit * (1 + SATURATION_REL_TOL))
        .otherwise(cmd.abs() > eff.abs() * (1 + SATURATION_REL_TOL) + 1e-9)
    )
    return (
        _time_sorted(samples)
        .join(limits, on=_KEY, how="left", maintain_order="left")
        .with_columns(
            # Null (not counted) where no effort was recorded or the limit is unknown (a
            # bag without its robot: "0 % saturated" would be a pass it cannot give).
            saturated=pl.when(eff.is_not_null() & limit.is_not_null()).then(
                (at_limit | clipped).fill_null(False)
            ),
        )
    )


def _prepared_tcp(
    controller_states: pl.DataFrame,
    episodes: pl.DataFrame,
    task_space: Mapping[str, TaskSpace] | None,
    *,
    final_window_s: float,
) -> pl.DataFrame:
    """The ``tcp`` frame of the catalog: the TCP errors of each sample time (row-local)."""
    t = pl.col("time_s")
    return (
        tcp_errors(controller_states, task_space)
        .join(_episode_columns(episodes, final_window_s), on="episode", how="left")
        .with_columns(in_final=(t >= pl.col("end_s") - pl.col("final_window_s") - FINAL_EDGE_S))
    )


def _partials_over(frame: pl.DataFrame, which: Frame) -> pl.DataFrame:
    exprs = [e for m in METRICS if m.frame == which for e in m.partial_exprs()]
    return frame.group_by(_KEY, maintain_order=True).agg(exprs)


def metric_partials(
    samples: pl.DataFrame,
    controller_states: pl.DataFrame,
    episodes: pl.DataFrame,
    limits: pl.DataFrame | None = None,
    *,
    settling_tolerance_rad: float = SETTLING_TOLERANCE_RAD,
    final_window_s: float = FINAL_WINDOW_S,
    task_space: Mapping[str, TaskSpace] | None = None,
) -> pl.DataFrame:
    """The catalog's partials over one time slice of the recorded frames.

    A slice is the rows of both frames inside one contiguous time interval (the whole
    recording is one slice); :func:`finish_metrics` merges the partial rows of any
    number of slices into the metrics.

    Args:
        samples: tidy samples (:data:`pipeline.log.reader.SAMPLE_COLUMNS`) of the slice,
            any order.
        controller_states: tidy frame (:data:`pipeline.log.reader.CONTROLLER_STATE_COLUMNS`)
            of the same time interval.
        episodes: :func:`pipeline.analysis.episodes.episode_table` of the WHOLE episodes
            (``motion_end_s``, ``end_s``, ``motion_completed``): a slice does not know where
            its episode ends.
        limits: ``episode, joint, effort_limit_nm`` (null where unknown); None = unknown.
        settling_tolerance_rad: band |e| must stay in to count as settled [rad].
        final_window_s: longest window at the end used for the final error [s].
        task_space: per episode, the robot's FK and tool offset for the task-space
            metrics (an episode without one has no ``tcp`` row).

    Returns:
        One row per (episode, joint) present in any frame of the slice (the TCP as joint
        ``tcp``): ``episode``, ``joint``, then one column per partial
        (:meth:`Metric.partial_column`; null for the partials of a frame with no row of
        that joint in the slice).
    """
    errors = _partials_over(
        _prepared_controller_states(
            controller_states,
            episodes,
            settling_tolerance_rad=settling_tolerance_rad,
            final_window_s=final_window_s,
        ),
        "controller_state",
    )
    states = _partials_over(_prepared_joint_states(samples, limits), "joint_states")
    tcp = _partials_over(
        _prepared_tcp(controller_states, episodes, task_space, final_window_s=final_window_s),
        "tcp",
    )
    out = states.join(errors, on=_KEY, how="full", coalesce=True, maintain_order="left")
    out = pl.concat([out, tcp], how="diagonal_relaxed")
    return out.select(*_KEY, *PARTIAL_COLUMNS)


def finish_metrics(partials: pl.DataFrame) -> pl.DataFrame:
    """Metrics from the partial rows of any number of slices, concatenated in time order.

    Args:
        partials: :func:`metric_partials` of each slice, concatenated in time order
            (rows of other (episode, joint) groups may interleave).

    Returns:
        ``episode``, ``joint``, :data:`METRIC_COLUMNS`; one row per (episode, joint), in
        first-seen order.
    """
    return partials.group_by(_KEY, maintain_order=True).agg([m.finish_expr() for m in METRICS])


def joint_metrics(
    samples: pl.DataFrame,
    controller_states: pl.DataFrame,
    episodes: pl.DataFrame,
    limits: pl.DataFrame | None = None,
    *,
    settling_tolerance_rad: float = SETTLING_TOLERANCE_RAD,
    final_window_s: float = FINAL_WINDOW_S,
    task_space: Mapping[str, TaskSpace] | None = None,
) -> pl.DataFrame:
    """Metrics per episode and joint (columns ``episode``, ``joint``, :data:`METRIC_COLUMNS`;
    the task-space metrics in the rows of joint ``tcp`` of the episodes in ``task_space``).

    Error-based metrics come from ``controller_states`` (full rate), velocity and effort
    metrics from ``samples`` (``/joint_states``); see :data:`METRIC_SOURCES`. The whole
    recording is one slice: ``finish_metrics(metric_partials(...))``.

    Args:
        samples: tidy samples (:data:`pipeline.log.reader.SAMPLE_COLUMNS`), any order.
        controller_states: tidy frame (:data:`pipeline.log.reader.CONTROLLER_STATE_COLUMNS`).
        episodes: :func:`pipeline.analysis.episodes.episode_table` (``motion_end_s``,
            ``end_s``, ``motion_completed``).
        limits: ``episode, joint, effort_limit_nm`` (null where unknown); None = unknown.
        settling_tolerance_rad: band |e| must stay in to count as settled [rad].
        final_window_s: longest window at the end used for the final error [s].
        task_space: per episode, the robot's FK and tool offset (None: no TCP rows).
    """
    return finish_metrics(
        metric_partials(
            samples,
            controller_states,
            episodes,
            limits,
            settling_tolerance_rad=settling_tolerance_rad,
            final_window_s=final_window_s,
            task_space=task_space,
        )
    )


def check_baseline(episodes: pl.DataFrame, baseline: str) -> bool:
    """Whether reductions against ``baseline`` can be computed.

    Recordings of a single controller have nothing to compare: False (the report has no
    reduction section). Several controllers without the baseline: a one-line error.
    """
    present = sorted(set(episodes.get_column("controller").to_list()))
    if baseline in present:
        return True
    if len(present) <= 1:
        return False
    raise ReportError(
        unknown_name_message("baseline controller", baseline, present)
        + " (the controllers in the recordings; choose one with --baseline)"
    )


def pairs(episodes: pl.DataFrame, *, baseline: str) -> list[tuple[str, str, str]]:
    """(group, baseline episode, candidate episode) for every comparable pair.

    Episodes pair within a group (the scenario of hand-listed episodes, a campaign's
    condition: :func:`pipeline.analysis.episodes.group_key`) and robot; only "ok"
    episodes take part, and no salvaged recording cut before its motion end
    (:func:`pipeline.analysis.episodes.comparable`). When a group holds several baseline
    runs, a candidate pairs with the ones of its own seed if there are any, else with all
    of them.
    """
    ok = episodes.filter(comparable(episodes)).sort("episode")
    key = "group" if "group" in ok.columns else "scenario"
    out: list[tuple[str, str, str]] = []
    for (scenario, robot), group in ok.group_by([key, "robot"], maintain_order=True):
        rows = group.to_dicts()
        bases = [r for r in rows if r["controller"] == baseline]
        for cand in (r for r in rows if r["controller"] != baseline):
            same_seed = [b for b in bases if b["seed"] == cand["seed"]]
            for b in same_seed or bases:
                out.append((str(scenario), b["episode"], cand["episode"]))
        del robot
    return sorted(out)


def reduction_pct(
    baseline: pl.Expr, candidate: pl.Expr, *, floor: float = ERROR_FLOOR_RAD
) -> pl.Expr:
    """(baseline - candidate) / baseline x 100; null when |baseline| < ``floor`` (numerical
    noise: the ratio would be meaningless; a metric's :attr:`Metric.floor`) or either value
    is missing."""
    valid = (
        baseline.is_not_null()
        & baseline.is_not_nan()
        & (baseline.abs() >= floor)
        & candidate.is_not_null()
    )
    return pl.when(valid).then((baseline - candidate) / baseline * 100.0).otherwise(None)


def comparisons(
    metrics: pl.DataFrame,
    episodes: pl.DataFrame,
    *,
    baseline: str,
    compared: Sequence[str] = COMPARED_METRICS,
) -> pl.DataFrame:
    """One row per (pair, joint): baseline and candidate values and reduction % per metric."""
    schema: dict[str, pl.DataType | type[pl.DataType]] = {
        "scenario": pl.String,
        "baseline": pl.String,
        "candidate": pl.String,
    }
    pair_df = pl.DataFrame(pairs(episodes, baseline=baseline), schema=schema, orient="row")
    cols = ["joint", *compared]
    b = metrics.select("episode", *cols).rename({m: f"{m}_baseline" for m in compared})
    c = metrics.select("episode", *cols).rename({m: f"{m}_candidate" for m in compared})
    out = pair_df.join(
        b, left_on="baseline", right_on="episode", how="inner", maintain_order="left"
    ).join(
        c,
        left_on=["candidate", "joint"],
        right_on=["episode", "joint"],
        how="inner",
        maintain_order="left",
    )
    out = out.with_columns(
        [
            reduction_pct(
                pl.col(f"{m}_baseline"),
                pl.col(f"{m}_candidate"),
                floor=BY_NAME[m].floor if m in BY_NAME else ERROR_FLOOR_RAD,
            ).alias(f"{m}_reduction_pct")
            for m in compared
        ]
    )
    return out
