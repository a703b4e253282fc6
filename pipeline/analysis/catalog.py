"""Every per-joint metric, declared once: what it is, how it is computed and shown.

:data:`METRICS` drives the metrics computation (:mod:`pipeline.analysis.metrics`),
metrics.json, the Markdown tables, the campaign table and the figures. Adding a metric is
one :class:`Metric` entry: its Polars aggregation, evaluated per (episode, joint) group
over the frame its ``frame`` names, after the protocol (time from the motion start, true
state where recorded).

Columns an aggregation may use:

- ``controller_state`` frame: ``time_s``, ``error_rad``, ``reference_position_rad``,
  ``feedback_position_rad`` plus ``completed``, ``motion_end_s``, ``after_motion``
  (t >= motion end), ``in_final`` (inside the final window), ``violating`` (|e| outside
  the settling band after the motion end) and ``settled`` (this and every later sample
  inside it).
- ``joint_states`` frame: ``time_s``, ``velocity_rad_s``, ``effort_nm``,
  ``commanded_effort_nm``, ``effort_limit_nm`` and ``saturated`` (at the limit or clipped;
  null where no effort was recorded).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import polars as pl

from pipeline.constants import FINAL_WINDOW_S, TOPIC_CONTROLLER_STATE, TOPIC_JOINT_STATES

# A joint that moves less than this has no direction of travel: no overshoot.
MIN_TRAVEL_RAD = 1e-9
# The band |e| must stay in, after the motion end, to count as settled [rad].
SETTLING_TOLERANCE_RAD = 1e-3

Frame = Literal["controller_state", "joint_states"]


@dataclass(frozen=True)
class Metric:
    """One per-joint metric.

    Attributes:
        name: column in the metric frames, key in metrics.json and the campaign table.
        unit: SI unit as printed (``rad``, ``rad/s``, ``N m``, ``s``, ``1`` for a share).
        title: what a table heading or axis says (without the unit).
        fmt: Python format spec for a table cell (``.3e``).
        frame: which prepared frame the aggregation runs over.
        source: the recorded topic(s) it comes from, as the report says it.
        aggregate: builds the per-(episode, joint) Polars aggregation.
        needs_completed_motion: null for an episode that did not complete its motion
            (its last samples are not "at the target").
        compared: reductions between controllers are computed for it (and headlines).
        lower_is_better: a smaller value is the better controller (for win/loss).
        log_scale: figures draw it on a log axis (values span orders of magnitude).
        in_tables: shown as its own per-episode Markdown table.
        detail: how it is taken, in a table heading's parentheses ("" for none).
    """

    name: str
    unit: str
    title: str
    fmt: str
    frame: Frame
    source: str
    aggregate: Callable[[], pl.Expr]
    needs_completed_motion: bool = False
    compared: bool = False
    lower_is_better: bool = True
    log_scale: bool = False
    in_tables: bool = True
    detail: str = ""

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

    def expr(self) -> pl.Expr:
        """The aggregation, null where the motion must be complete and is not."""
        out = self.aggregate()
        if self.needs_completed_motion:
            out = pl.when(pl.col("completed").first()).then(out)
        return out.alias(self.name)


def _e() -> pl.Expr:
    return pl.col("error_rad")


def _max_abs_error() -> pl.Expr:
    return _e().abs().max()


def _rms_error() -> pl.Expr:
    return (_e() * _e()).mean().sqrt()


def _final_error() -> pl.Expr:
    return _e().abs().filter(pl.col("in_final")).mean()


def _settling_time() -> pl.Expr:
    motion_end = pl.col("motion_end_s").first()
    settled_from = pl.col("time_s").filter(pl.col("after_motion") & pl.col("settled")).min()
    return (
        pl.when(motion_end.is_null())
        .then(None)
        .when(~pl.col("violating").any())
        .then(0.0)
        .otherwise(settled_from - motion_end)
    )


def _overshoot() -> pl.Expr:
    ref = pl.col("reference_position_rad")
    goal = ref.drop_nulls().last()
    travel = goal - ref.drop_nulls().first()
    direction = pl.when(travel > 0).then(1.0).otherwise(-1.0)
    past = ((pl.col("feedback_position_rad") - goal) * direction).max().clip(lower_bound=0.0)
    return pl.when(travel.abs() > MIN_TRAVEL_RAD).then(past)


def _is_peak() -> pl.Expr:
    # First sample at the largest |v| (nulls never match: all-null gives null, not 0).
    v = pl.col("velocity_rad_s")
    return v.abs() == v.abs().max()


def _peak_velocity() -> pl.Expr:
    return pl.col("velocity_rad_s").filter(_is_peak()).first()


def _peak_velocity_time() -> pl.Expr:
    return pl.col("time_s").filter(_is_peak()).first()


def _rms_effort() -> pl.Expr:
    eff = pl.col("effort_nm")
    return (eff * eff).mean().sqrt()


def _saturation_fraction() -> pl.Expr:
    return pl.col("saturated").cast(pl.Float64).mean()


_CS = TOPIC_CONTROLLER_STATE
_JS = TOPIC_JOINT_STATES

METRICS: tuple[Metric, ...] = (
    Metric(
        "max_abs_error", "rad", "Max |error|", ".3e", "controller_state", _CS, _max_abs_error,
        compared=True, log_scale=True,
    ),
    Metric(
        "rms_error", "rad", "RMS error", ".3e", "controller_state", _CS, _rms_error,
        compared=True, log_scale=True,
    ),
    Metric(
        "final_error", "rad", "Error at the target", ".3e", "controller_state", _CS,
        _final_error, needs_completed_motion=True, compared=True, log_scale=True,
        detail=f"mean |e| over the final window, ≤ {FINAL_WINDOW_S} s",
    ),
    Metric(
        "settling_time", "s", "Settling time", ".3f", "controller_state", _CS, _settling_time,
        needs_completed_motion=True,
        detail=f"|e| ≤ {SETTLING_TOLERANCE_RAD:g} rad after the motion end",
    ),
    Metric(
        "overshoot", "rad", "Overshoot past the goal", ".2e", "controller_state", _CS,
        _overshoot, needs_completed_motion=True, log_scale=True,
    ),
    Metric(
        "peak_velocity", "rad/s", "Peak velocity", "+.3f", "joint_states", _JS,
        _peak_velocity, lower_is_better=False,
        detail="signed value at the largest |velocity|",
    ),
    Metric(
        "peak_velocity_time", "s", "Time of the peak velocity", ".2f", "joint_states", _JS,
        _peak_velocity_time, in_tables=False,
    ),
    Metric(
        "rms_effort", "N m", "RMS applied effort", ".3g", "joint_states", _JS,
        _rms_effort,
    ),
    Metric(
        "saturation_fraction", "1", "Fraction of time in torque saturation", ".3f",
        "joint_states", f"{TOPIC_JOINT_STATES} + {TOPIC_CONTROLLER_STATE}",
        _saturation_fraction,
    ),
)  # fmt: skip

BY_NAME: dict[str, Metric] = {m.name: m for m in METRICS}
METRIC_COLUMNS: tuple[str, ...] = tuple(m.name for m in METRICS)
COMPARED_METRICS: tuple[str, ...] = tuple(m.name for m in METRICS if m.compared)
# Which recorded topic each metric is computed from.
METRIC_SOURCES: dict[str, str] = {m.name: m.source for m in METRICS}


def metric(name: str) -> Metric:
    """The declaration of ``name`` (KeyError naming the known ones)."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise KeyError(f"unknown metric '{name}'; known: {', '.join(METRIC_COLUMNS)}") from None
