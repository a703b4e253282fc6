"""Every per-joint metric, declared once: what it is, how it is computed and shown.

:data:`METRICS` drives the metrics computation (:mod:`pipeline.analysis.metrics`),
metrics.json, the Markdown tables, the campaign table and the figures. Adding a metric is
one :class:`Metric` entry.

A metric is computed in two steps so that it can run over a recording read in time
slices (a long bag decoded window by window) as well as over a whole one, with one
definition:

- ``partials``: named Polars aggregations evaluated per (episode, joint) over one time
  slice (the rows of one contiguous time interval, in time order) of the prepared frame
  its ``frame`` names, after the protocol (time from the motion start, true state where
  recorded). A whole episode is one slice.
- ``finish``: one Polars aggregation over the partial rows of every slice of an
  (episode, joint), in time order, that gives the metric. It reads a partial through the
  accessor it is given (``p("sum_sq")``); every partial is null in a slice that holds no
  row of the metric's frame, so a finish must ignore nulls (max, min, sum and
  ``drop_nulls`` do).

The finish of a one-slice run and of any slicing agree exactly (max, min, first, last)
or up to the rounding of a sum split into slices (~1e-15 relative).

Columns a partial may use (row-local only: no window over the whole episode, a slice
does not see its neighbours):

- ``controller_state`` frame: ``time_s``, ``error_rad``, ``reference_position_rad``,
  ``feedback_position_rad`` plus ``completed``, ``motion_end_s``, ``after_motion``
  (t >= motion end), ``in_final`` (inside the final window), ``final_late`` (inside
  its second half) and ``violating`` (|e| outside the
  settling band after the motion end).
- ``joint_states`` frame: ``time_s``, ``velocity_rad_s``, ``effort_nm``,
  ``commanded_effort_nm``, ``effort_limit_nm`` and ``saturated`` (at the limit or clipped;
  null where no effort was recorded).
- both frames also carry the columns of the topics paired with the controller state
  (:data:`pipeline.log.topics.PAIRED_COLUMNS`, from the rows of
  :data:`pipeline.log.topics.TOPICS`: ``true_position_rad``, ``true_velocity_rad_s``),
  null where the recording lacks the topic: a metric of a new topic's column needs no
  other edit.
- ``tcp`` frame (task space, joint :data:`pipeline.analysis.task_space.TCP`):
  ``time_s``, ``position_error_mm``, ``orientation_error_mrad`` (FK of the reference vs the
  position the joint metrics use) plus ``completed`` and ``in_final`` as above.

A metric of the ``tcp`` frame is a task-space metric (:attr:`Metric.space`): its value is in
the rows of the pseudo-joint ``tcp``, a joint-space metric's in the joints' rows.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import polars as pl

from pipeline.constants import FINAL_WINDOW_S, TOPIC_CONTROLLER_STATE, TOPIC_JOINT_STATES

# A joint that moves less than this has no direction of travel: no overshoot.
MIN_TRAVEL_RAD = 1e-9
# Below this a joint error is numerical noise (a perfect-model CTC settles to ~1e-13 rad);
# a reduction relative to it would read 1e10 %, so none is given.
ERROR_FLOOR_RAD = 1e-9
# The same for the TCP: 1 nm [mm] and 1 nrad [mrad].
TCP_FLOOR = 1e-6
# The band |e| must stay in, after the motion end, to count as settled [rad].
SETTLING_TOLERANCE_RAD = 1e-3

# The error at the target is "not settled" when the mean |e| over the final window's second
# half differs from the one over its first half by more than this share of the error at
# the target, and by more than
# DRIFT_FLOOR_RAD (below it, numerical noise: a perfect-model CTC settles to ~1e-13 rad).
FINAL_DRIFT_REL = 0.1
DRIFT_FLOOR_RAD = 1e-6

Frame = Literal["controller_state", "joint_states", "tcp"]
Space = Literal["joint", "task"]
# The pseudo-joint of the task-space rows (= pipeline.analysis.task_space.TCP).
TCP_JOINT = "tcp"
# A finish reads the partial ``key`` of its own metric as ``p(key)``.
PartialColumn = Callable[[str], pl.Expr]

# The partial a metric that needs a completed motion gets, and the column it comes from.
_COMPLETED = "completed"


@dataclass(frozen=True)
class Metric:
    """One per-joint metric.

    Attributes:
        name: column in the metric frames, key in metrics.json and the campaign table.
        unit: SI unit as printed (``rad``, ``rad/s``, ``N m``, ``s``, ``1`` for a share).
        title: what a table heading or axis says (without the unit).
        fmt: Python format spec for a table cell (``.3e``).
        frame: which prepared frame the partials run over.
        source: the recorded topic(s) it comes from, as the report says it.
        partials: builds the named per-(episode, joint) aggregations over one time slice.
        finish: builds the aggregation over the partial rows of all slices (in time order)
            that gives the metric; its argument reads a partial by name.
        needs_completed_motion: null for an episode that did not complete its motion
            (its last samples are not "at the target").
        compared: reductions between controllers are computed for it (and headlines).
        lower_is_better: a smaller value is the better controller (for win/loss).
        log_scale: figures draw it on a log axis (values span orders of magnitude).
        in_tables: shown as its own per-episode Markdown table (the TCP's metrics share
            one table).
        detail: how it is taken, in a table heading's parentheses ("" for none).
        definition: what it is, as every report's Definitions section and docs/report.md
            say it (``term: meaning``); "" for a companion metric its metric's definition
            covers (``peak_velocity_time``).
        floor: below this a baseline value is numerical noise: no reduction % against it
            [the metric's unit].
    """

    name: str
    unit: str
    title: str
    fmt: str
    frame: Frame
    source: str
    partials: Callable[[], dict[str, pl.Expr]]
    finish: Callable[[PartialColumn], pl.Expr]
    needs_completed_motion: bool = False
    compared: bool = False
    lower_is_better: bool = True
    log_scale: bool = False
    in_tables: bool = True
    detail: str = ""
    definition: str = ""
    floor: float = ERROR_FLOOR_RAD

    def __post_init__(self) -> None:
        if self.needs_completed_motion and self.frame == "joint_states":
            raise ValueError(f"{self.name}: ``completed`` is not a joint_states frame column")
        if _COMPLETED in self.partials():
            raise ValueError(f"{self.name}: the partial name '{_COMPLETED}' is reserved")

    @property
    def space(self) -> Space:
        """``task`` for a TCP metric (rows of joint :data:`TCP_JOINT`), else ``joint``."""
        return "task" if self.frame == "tcp" else "joint"

    def applies_to(self, joint: str) -> bool:
        """Whether this metric has a value in the rows of ``joint``."""
        return (joint == TCP_JOINT) == (self.space == "task")

    @property
    def is_time(self) -> bool:
        """A time [s]: rounded to decimals, not significant digits, in metrics.json."""
        return self.unit == "s"

    @property
    def label(self) -> str:
        """``title [unit]`` (no brackets for a share)."""
        return self.title if self.unit == "1" else f"{self.title} [{self.unit}]"

    @property
    def heading(self) -> str:
        """A table heading: the label, then the detail in parentheses."""
        return f"{self.label} ({self.detail})" if self.detail else self.label

    def partial_column(self, key: str) -> str:
        """The column of the partial ``key`` in a partials frame (``rms_error.sum_sq``)."""
        return f"{self.name}.{key}"

    def partial_exprs(self) -> list[pl.Expr]:
        """The per-slice aggregations, named by :meth:`partial_column` (plus ``completed``
        when the metric needs a completed motion)."""
        parts = self.partials()
        if self.needs_completed_motion:
            parts[_COMPLETED] = pl.col(_COMPLETED).first()
        return [expr.alias(self.partial_column(key)) for key, expr in parts.items()]

    def finish_expr(self) -> pl.Expr:
        """The metric from its partials, null where the motion must be complete and is not."""

        def p(key: str) -> pl.Expr:
            return pl.col(self.partial_column(key))

        out = self.finish(p)
        if self.needs_completed_motion:
            out = pl.when(p(_COMPLETED).drop_nulls().first()).then(out)
        return out.alias(self.name)


def _e() -> pl.Expr:
    return pl.col("error_rad")


def _squares(col: str) -> dict[str, pl.Expr]:
    x = pl.col(col)
    return {"sum_sq": (x * x).sum(), "n": x.count()}


def _root_mean(p: PartialColumn) -> pl.Expr:
    # Null (not 0, not NaN) when no slice holds a value.
    n = p("n").sum()
    return pl.when(n > 0).then((p("sum_sq").sum() / n).sqrt())


def _max_abs_error() -> dict[str, pl.Expr]:
    return {"max": _e().abs().max()}


def _max_abs_error_finish(p: PartialColumn) -> pl.Expr:
    return p("max").max()


def _final_error() -> dict[str, pl.Expr]:
    final = _e().abs().filter(pl.col("in_final"))
    return {"sum": final.sum(), "n": final.count()}


def _final_drift() -> dict[str, pl.Expr]:
    final = pl.col("in_final")
    early = _e().abs().filter(final & ~pl.col("final_late"))
    late = _e().abs().filter(final & pl.col("final_late"))
    return {"sum_early": early.sum(), "n_early": early.count(), "sum_late": late.sum(),
            "n_late": late.count()}  # fmt: skip


def _final_drift_finish(p: PartialColumn) -> pl.Expr:
    n_early, n_late = p("n_early").sum(), p("n_late").sum()
    return pl.when((n_early > 0) & (n_late > 0)).then(
        p("sum_late").sum() / n_late - p("sum_early").sum() / n_early
    )


def not_settled(final_error: pl.Expr, final_drift: pl.Expr) -> pl.Expr:
    """The error at the target still moves in its last windows (null where either is)."""
    return final_drift.abs() > pl.max_horizontal(
        final_error.abs() * FINAL_DRIFT_REL, pl.lit(DRIFT_FLOOR_RAD)
    )


def _mean(p: PartialColumn) -> pl.Expr:
    n = p("n").sum()
    return pl.when(n > 0).then(p("sum").sum() / n)


def _settling_time() -> dict[str, pl.Expr]:
    t = pl.col("time_s")
    violating = pl.col("violating")
    # Inside the band from this row to the end of the slice.
    calm = (violating.cast(pl.UInt32).cum_sum() == violating.sum()) & ~violating
    return {
        "motion_end_s": pl.col("motion_end_s").first(),
        "last_violation_s": t.filter(violating).max(),
        # The first after-motion time after the slice's last violation (its first
        # after-motion time when nothing in it violates).
        "settled_from_s": t.filter(pl.col("after_motion") & calm).min(),
    }


def _settling_time_finish(p: PartialColumn) -> pl.Expr:
    # Settled from the first after-motion time after the episode's last violation: in the
    # slice that holds it or, when that slice ends violating, in a later one.
    motion_end = p("motion_end_s").drop_nulls().first()
    violation = p("last_violation_s").is_not_null()
    slice_no = pl.int_range(pl.len())
    last_violating_slice = slice_no.filter(violation).max()
    settled_from = p("settled_from_s").filter(slice_no >= last_violating_slice).min()
    return (
        pl.when(motion_end.is_null())
        .then(None)
        .when(~violation.any())
        .then(0.0)
        .otherwise(settled_from - motion_end)
    )


def _overshoot() -> dict[str, pl.Expr]:
    ref = pl.col("reference_position_rad").drop_nulls()
    fb = pl.col("feedback_position_rad")
    return {"start": ref.first(), "goal": ref.last(), "fb_max": fb.max(), "fb_min": fb.min()}


def _overshoot_finish(p: PartialColumn) -> pl.Expr:
    goal = p("goal").drop_nulls().last()
    travel = goal - p("start").drop_nulls().first()
    # max((fb - goal) * direction) is max(fb) - goal or goal - min(fb): rounding is monotone.
    past = pl.when(travel > 0).then(p("fb_max").max() - goal).otherwise(goal - p("fb_min").min())
    return pl.when(travel.abs() > MIN_TRAVEL_RAD).then(past.clip(lower_bound=0.0))


def _at_peak(col: str) -> dict[str, pl.Expr]:
    # The slice's largest |v| and ``col`` at its first sample (nulls never match: all-null
    # gives null, not 0).
    v = pl.col("velocity_rad_s")
    return {"abs_max": v.abs().max(), col: pl.col(col).filter(v.abs() == v.abs().max()).first()}


def _first_at_peak(col: str) -> Callable[[PartialColumn], pl.Expr]:
    def finish(p: PartialColumn) -> pl.Expr:
        # The first slice reaching the overall largest |v| holds its first sample.
        return p(col).filter(p("abs_max") == p("abs_max").max()).first()

    return finish


def _max_of(col: str) -> Callable[[], dict[str, pl.Expr]]:
    return lambda: {"max": pl.col(col).abs().max()}


def _final_of(col: str) -> Callable[[], dict[str, pl.Expr]]:
    def parts() -> dict[str, pl.Expr]:
        final = pl.col(col).abs().filter(pl.col("in_final"))
        return {"sum": final.sum(), "n": final.count()}

    return parts


def _saturation_fraction() -> dict[str, pl.Expr]:
    sat = pl.col("saturated")
    return {"sum": sat.cast(pl.Float64).sum(), "n": sat.count()}


_CS = TOPIC_CONTROLLER_STATE
_JS = TOPIC_JOINT_STATES
_CS_CODE, _JS_CODE = f"`{_CS}`", f"`{_JS}`"
_TCP_SOURCE = f"{_CS} (FK)"
_TCP_FK = (
    "FK (the recording's robot model, Pinocchio) of the reference and of the position the "
    "joint errors use (true where recorded), at the tool centre point (TCP: the flange "
    "unless `--tool-offset` moves it)"
)


def _tcp_metrics(quantity: str, unit: str, col: str, what: str) -> tuple[Metric, ...]:
    """Max, RMS and final of one TCP error (position or orientation)."""
    return (
        Metric(
            f"tcp_max_{quantity}_error", unit, f"TCP max {quantity} error", ".3g", "tcp",
            _TCP_SOURCE, _max_of(col), _max_abs_error_finish, compared=True, log_scale=True,
            in_tables=False,
            floor=TCP_FLOOR,
            definition=f"TCP {quantity} error: {what} between the {_TCP_FK}; max, RMS and "
            "the error at the target (final window) as for a joint",
        ),
        Metric(
            f"tcp_rms_{quantity}_error", unit, f"TCP RMS {quantity} error", ".3g", "tcp",
            _TCP_SOURCE, lambda: _squares(col), _root_mean, compared=True, log_scale=True,
            in_tables=False,
            floor=TCP_FLOOR,
        ),
        Metric(
            f"tcp_final_{quantity}_error", unit, f"TCP {quantity} error at the target", ".3g",
            "tcp", _TCP_SOURCE, _final_of(col), _mean, needs_completed_motion=True, in_tables=False,
            compared=True, log_scale=True, floor=TCP_FLOOR,
            detail=f"mean over the final window, ≤ {FINAL_WINDOW_S} s",
        ),
    )  # fmt: skip


METRICS: tuple[Metric, ...] = (
    Metric(
        "max_abs_error", "rad", "Max |error|", ".3e", "controller_state", _CS,
        _max_abs_error, _max_abs_error_finish,
        compared=True, log_scale=True,
        definition="max |error|: largest |e| over the episode",
    ),
    Metric(
        "rms_error", "rad", "RMS error", ".3e", "controller_state", _CS,
        lambda: _squares("error_rad"), _root_mean,
        compared=True, log_scale=True,
        definition="RMS error: sqrt(mean e²) over the episode",
    ),
    Metric(
        "final_error", "rad", "Error at the target", ".3e", "controller_state", _CS,
        _final_error, _mean, needs_completed_motion=True, compared=True, log_scale=True,
        detail=f"mean |e| over the final window, ≤ {FINAL_WINDOW_S} s",
        definition=(
            f"error at the target: mean |e| over the last min({FINAL_WINDOW_S} s, hold / 2) "
            "of the episode, hold = episode end − motion end (motion end = the planned "
            "trajectory's duration); the last sample alone when there is no hold"
        ),
    ),
    Metric(
        "final_drift", "rad", "Drift of the error at the target", ".2e", "controller_state",
        _CS, _final_drift, _final_drift_finish, needs_completed_motion=True, in_tables=False,
        detail="final window's second half minus its first; not settled when it is over "
        f"{FINAL_DRIFT_REL:g} x the error at the target and {DRIFT_FLOOR_RAD:g} rad",
        definition=(
            "drift of the error at the target: mean |e| over the final window's second half "
            "minus over its first half; the error at the target is flagged 'not settled' "
            f"where |drift| > {FINAL_DRIFT_REL:g} × the error at the target and > "
            f"{DRIFT_FLOOR_RAD:g} rad (its last windows still move: a transient, not a "
            "steady state)"
        ),
    ),
    Metric(
        "settling_time", "s", "Settling time", ".3f", "controller_state", _CS,
        _settling_time, _settling_time_finish,
        needs_completed_motion=True,
        detail=f"|e| ≤ {SETTLING_TOLERANCE_RAD:g} rad after the motion end",
        definition=(
            f"settling time: from the motion end until |e| stays within "
            f"{SETTLING_TOLERANCE_RAD:g} rad for the rest of the episode; 'never settles' "
            "when the last sample is outside"
        ),
    ),
    Metric(
        "overshoot", "rad", "Overshoot past the goal", ".2e", "controller_state", _CS,
        _overshoot, _overshoot_finish, needs_completed_motion=True, log_scale=True,
        definition=(
            "overshoot: how far the position (true where recorded, else "
            "`feedback.positions`) passes the goal in the direction of travel (n/a for a "
            "joint that does not move)"
        ),
    ),
    Metric(
        "peak_velocity", "rad/s", "Peak velocity", "+.3f", "joint_states", _JS,
        lambda: _at_peak("velocity_rad_s"), _first_at_peak("velocity_rad_s"),
        lower_is_better=False,
        detail="signed value at the largest |velocity|",
        definition=(
            "peak velocity: the velocity of largest magnitude, with its sign (true where "
            f"recorded, else {_JS_CODE})"
        ),
    ),
    Metric(
        "peak_velocity_time", "s", "Time of the peak velocity", ".2f", "joint_states", _JS,
        lambda: _at_peak("time_s"), _first_at_peak("time_s"), in_tables=False,
    ),
    Metric(
        "rms_effort", "N m", "RMS applied effort", ".3g", "joint_states", _JS,
        lambda: _squares("effort_nm"), _root_mean,
        definition=f"RMS effort: sqrt(mean applied effort²) ({_JS_CODE} `effort`)",
    ),
    Metric(
        "saturation_fraction", "1", "Fraction of time in torque saturation", ".3f",
        "joint_states", f"{TOPIC_JOINT_STATES} + {TOPIC_CONTROLLER_STATE}",
        _saturation_fraction, _mean,
        definition=(
            f"saturation: share of {_JS_CODE} samples where |applied effort| is at the "
            f"joint's effort limit or |commanded| ({_CS_CODE} `output.effort`) exceeds "
            "|applied|"
        ),
    ),
    *_tcp_metrics("position", "mm", "position_error_mm", "|p_ref − p|"),
    *_tcp_metrics(
        "orientation", "mrad", "orientation_error_mrad", "the rotation angle of R_refᵀ R"
    ),
)  # fmt: skip

BY_NAME: dict[str, Metric] = {m.name: m for m in METRICS}
METRIC_COLUMNS: tuple[str, ...] = tuple(m.name for m in METRICS)
COMPARED_METRICS: tuple[str, ...] = tuple(m.name for m in METRICS if m.compared)
# The compared metrics of the joints and of the TCP.
JOINT_COMPARED: tuple[str, ...] = tuple(
    m.name for m in METRICS if m.compared and m.space == "joint"
)
TASK_COMPARED: tuple[str, ...] = tuple(m.name for m in METRICS if m.compared and m.space == "task")
# The columns of a partials frame after ``episode, joint``, in catalog order.
PARTIAL_COLUMNS: tuple[str, ...] = tuple(
    e.meta.output_name() for m in METRICS for e in m.partial_exprs()
)
# Which recorded topic each metric is computed from.
METRIC_SOURCES: dict[str, str] = {m.name: m.source for m in METRICS}


def metric(name: str) -> Metric:
    """The declaration of ``name`` (KeyError naming the known ones)."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise KeyError(f"unknown metric '{name}'; known: {', '.join(METRIC_COLUMNS)}") from None
