"""The experiment protocol applied to a recording before any metric: settled start, true state.

- **Settled start.** A recording starts with a pre-roll: the controller holds the start
  pose until ``protocol.motion_start_s``. Metrics count from the motion start, so the
  frames are cut there and their ``time_s`` restarts at 0 (what every metric and figure
  then calls "the start"). The state at the motion start is kept per episode.
- **Ground truth.** Where a recording carries the plant's true state
  (``/ground_truth/joint_states``), tracking error, position and velocity are the true
  ones (reference - true position); the measured ones stay beside them as
  ``measured_*`` columns. A real robot's bag has no ground truth: its measured state is
  used and the report says so.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import polars as pl

from pipeline.log.reader import Recording
from pipeline.settings import EpisodeSettings

ERROR_SOURCE_TRUE = "true plant state"
ERROR_SOURCE_MEASURED = "measured"


@dataclass(frozen=True)
class ProtocolView:
    """A recording as the metrics see it, and what was done to get there.

    Attributes:
        recording: frames cut at the motion start, time from it, true state where recorded.
        settings: the recording's typed settings (None: absent or not following the
            contract; the reader's notes say which).
        error_source: :data:`ERROR_SOURCE_TRUE` or :data:`ERROR_SOURCE_MEASURED`.
        motion_start_s: the pre-roll cut from the recording's start [s] (0 if none).
        start_abs_error_rad: max over joints of |e| at the motion start (None if unknown).
        start_abs_effort_nm: max over joints of |applied effort| at the motion start.
    """

    recording: Recording
    settings: EpisodeSettings | None
    error_source: str
    motion_start_s: float
    start_abs_error_rad: float | None
    start_abs_effort_nm: float | None


def _true_state(frame: pl.DataFrame, *, error: bool) -> pl.DataFrame:
    """Swap the measured columns for the true ones (rows without truth keep measured)."""
    has = pl.col("true_position_rad").is_not_null()
    out = frame
    if "feedback_position_rad" in frame.columns:
        out = out.with_columns(
            pl.col("feedback_position_rad").alias("measured_position_rad"),
            pl.when(has)
            .then(pl.col("true_position_rad"))
            .otherwise(pl.col("feedback_position_rad"))
            .alias("feedback_position_rad"),
        )
    if "position_rad" in frame.columns:
        out = out.with_columns(
            pl.col("position_rad").alias("measured_position_rad"),
            pl.col("velocity_rad_s").alias("measured_velocity_rad_s"),
            pl.when(has)
            .then(pl.col("true_position_rad"))
            .otherwise(pl.col("position_rad"))
            .alias("position_rad"),
            pl.when(pl.col("true_velocity_rad_s").is_not_null())
            .then(pl.col("true_velocity_rad_s"))
            .otherwise(pl.col("velocity_rad_s"))
            .alias("velocity_rad_s"),
        )
    if error:
        out = out.with_columns(
            pl.col("error_rad").alias("measured_error_rad"),
            pl.when(has)
            .then(pl.col("reference_position_rad") - pl.col("true_position_rad"))
            .otherwise(pl.col("error_rad"))
            .alias("error_rad"),
        )
    return out


def _from_motion_start(frame: pl.DataFrame, start_s: float, eps_s: float) -> pl.DataFrame:
    if start_s <= 0:
        return frame
    return frame.filter(pl.col("time_s") >= start_s - eps_s).with_columns(
        (pl.col("time_s") - start_s).alias("time_s")
    )


@dataclass(frozen=True)
class Protocol:
    """The protocol's frame transform for one recording, applicable to any time slice of
    its frames (a window of a long recording) as to the whole.

    Attributes:
        motion_start_s: the pre-roll cut [s] (0: none).
        eps_s: half a control period [s]: a sample this close before the motion start is
            the motion start's.
    """

    motion_start_s: float
    eps_s: float

    def frames(
        self, samples: pl.DataFrame, controller_states: pl.DataFrame
    ) -> tuple[pl.DataFrame, pl.DataFrame]:
        """``samples`` and ``controller_states`` cut at the motion start, time from it, true
        state where recorded (every frame gets the same columns, ``measured_*`` beside the
        ones metrics use, so recordings with and without ground truth concatenate)."""
        start, eps = self.motion_start_s, self.eps_s
        return (
            _from_motion_start(_true_state(samples, error=True), start, eps),
            _from_motion_start(_true_state(controller_states, error=True), start, eps),
        )


def protocol_of(rec: Recording) -> tuple[Protocol, EpisodeSettings | None, list[str]]:
    """The protocol for ``rec``, its typed settings and the notes the protocol adds (none:
    the reader already noted settings that break the contract).

    The control period is the recording's (``rec.control_period_s``) where the reader
    gives it (a long recording read in windows), else the frames' median step.
    """
    settings = rec.settings
    start_s = settings.protocol.motion_start_s if settings is not None else 0.0
    if rec.control_period_s is not None:
        eps_s = 0.5 * rec.control_period_s if rec.control_period_s > 0 else 1e-9
    else:
        n = max(len(rec.joint_names), 1)
        times = rec.controller_states.get_column("time_s").to_numpy()[::n]
        eps_s = 0.5 * float(np.median(np.diff(times))) if times.size > 1 else 1e-9
    return Protocol(start_s, eps_s), settings, []


def start_state(
    samples: pl.DataFrame, controller_states: pl.DataFrame
) -> tuple[float | None, float | None]:
    """max over joints of |e| and of |applied effort| at the first time of protocol-applied
    frames (None where a frame is empty or has no value)."""
    first = (
        controller_states.filter(pl.col("time_s") == pl.col("time_s").min())
        if controller_states.height
        else controller_states
    )
    start_err = first.get_column("error_rad").abs().max() if first.height else None
    first_js = (
        samples.filter(pl.col("time_s") == pl.col("time_s").min()) if samples.height else samples
    )
    start_effort = first_js.get_column("effort_nm").abs().max() if first_js.height else None
    return (
        float(start_err) if isinstance(start_err, int | float) else None,
        float(start_effort) if isinstance(start_effort, int | float) else None,
    )


def protocol_view(
    rec: Recording,
    *,
    start: tuple[float | None, float | None] | None = None,
    counts: tuple[int, int] | None = None,
) -> tuple[ProtocolView, list[str]]:
    """Apply the protocol to ``rec`` (see the module doc); returns the view and notes.

    For a recording read in windows (decimated frames), ``start`` (the exact
    :func:`start_state`) and ``counts`` (``/joint_states`` and ``/controller_state``
    messages after the cut) come from its windows; its ``end_s`` is moved to the motion
    start's time origin.
    """
    protocol, settings, notes = protocol_of(rec)
    samples, cs = protocol.frames(rec.samples, rec.controller_states)
    start_err, start_effort = start if start is not None else start_state(samples, cs)
    start_s = protocol.motion_start_s
    moved: dict[str, Any] = {}
    if rec.end_s is not None:
        end_s = rec.end_s - start_s if start_s > 0 else rec.end_s
        moved["end_s"] = end_s if end_s >= -protocol.eps_s else None
    if counts is not None:
        moved["sample_count"], moved["controller_sample_count"] = counts
    view = ProtocolView(
        recording=dataclasses.replace(
            rec, controller_states=cs, samples=samples, notes=(*rec.notes, *notes), **moved
        ),
        settings=settings,
        error_source=ERROR_SOURCE_TRUE if rec.has_ground_truth else ERROR_SOURCE_MEASURED,
        motion_start_s=start_s,
        start_abs_error_rad=start_err,
        start_abs_effort_nm=start_effort,
    )
    return view, notes
