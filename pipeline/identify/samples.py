"""Recordings -> the aligned joint samples identification fits: q, qd, qdd and torque.

Positions come from the plant's true state (``/ground_truth/joint_states``) when the
recording has it, else the measured ``/joint_states``; the torque is ``/joint_states``
effort, which our recordings fill with the *applied* torque (the command after
saturation, held over the following control period). A recording without efforts is
refused: the controller's commanded effort is not what the motors applied.

Two ways to get velocities and accelerations:

- ``cutoff_hz > 0`` (real data): a zero-phase Butterworth low-pass (``filtfilt``, order
  :data:`FILTER_ORDER`) of positions, velocities (when recorded) and torques alike
  ("parallel filtering", so filtering distorts both sides of ``tau = Y theta`` the same
  way), central differences for the derivatives, the filter's edge transients cut, then
  decimation to about ten samples per cutoff period. The Coulomb columns, the one term
  that is no smooth function of the filtered signals, are filtered alike
  (:meth:`JointSamples.coulomb`). Our recordings' effort is the torque held over the
  following period (zero-order hold: ``tau[k]`` acts over ``[t_k, t_k+1]``); the torque
  *at* ``t_k`` is then the mean of ``tau[k-1]`` and ``tau[k]`` (``effort_held``), which
  aligns it with the states sampled at ``t_k`` (a real robot's log stamps the effort it
  measured at the sample: left as is).
- ``cutoff_hz == 0`` (exact): the recorded velocities and the forward difference
  ``qdd_k = (qd_{k+1} - qd_k) / dt``: exactly the acceleration the plant's semi-implicit
  Euler step applied with torque ``tau_k`` over ``[t_k, t_{k+1}]``, so noise-free
  simulated data satisfies the model to rounding.

A real robot's log repeats samples and stamps them unevenly. Repeated samples are
dropped: a second message with the same stamp (the first is kept), and a message whose
positions, velocities and efforts all equal the previous one's while the joints move (a
driver republishing a stale state). Stamps then further than :data:`JITTER_TOL` of the
median period from it are resampled onto a grid of the median period (linear
interpolation). :class:`JointSamples` counts each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import polars as pl
from numpy.typing import NDArray
from scipy import signal

from pipeline.errors import IdentificationError
from pipeline.identify.model_file import TransitionSpeed, coulomb_shape
from pipeline.log.reader import Recording
from pipeline.robots.spec import RobotSpec

F64 = NDArray[np.float64]

FILTER_ORDER = 4
"""Butterworth order; ``filtfilt`` doubles it and cancels the phase."""
SAMPLES_PER_CUTOFF = 10
"""After filtering, keep about this many samples per cutoff period (decimation)."""
JITTER_TOL = 0.01
"""Sample periods further than this share from the median are resampled onto a grid."""


@dataclass(frozen=True)
class JointSamples:
    """One recording's samples for identification, joints in the robot's order.

    Attributes:
        source: the recording as given.
        sha256: SHA-256 of its storage file.
        q, qd, qdd: (N, dof) [rad], [rad/s], [rad/s^2].
        tau_nm: (N, dof) applied torque [N m].
        dt_s: sample period after decimation [s].
        truth: positions came from the plant's true state (simulation).
        repeated_stamps: messages dropped for repeating an earlier message's stamp.
        repeated_values: messages dropped for repeating the previous values while moving.
        resampled: uneven stamps were resampled onto the median period's grid.
        period_range_s: the shortest and longest stamp period after the drops [s].
        effort_held: the effort is a torque held over the following sample period (our
            recordings), so the torque at a sample is the mean of the two held values
            around it (filtered samples only; see the module docstring).
        raw_qd: (M, dof) filtered samples: the velocity before filtering, at the full
            rate (recorded, else differentiated positions) [rad/s]; None: exact samples.
        filter_ba: the low-pass's (b, a) coefficients (filtered samples).
        kept: (start, stop, step) of the full-rate samples kept after the filter.
    """

    source: str
    sha256: str
    q: F64
    qd: F64
    qdd: F64
    tau_nm: F64
    dt_s: float
    truth: bool
    repeated_stamps: int = 0
    repeated_values: int = 0
    resampled: bool = False
    period_range_s: tuple[float, float] = (0.0, 0.0)
    effort_held: bool = False
    raw_qd: F64 | None = None
    filter_ba: tuple[F64, F64] | None = None
    kept: tuple[int, int, int] = (0, 0, 1)

    def stuck_share(self, speed_rad_s: float) -> F64 | None:
        """(N, dof) per kept sample, the low-passed indicator of the unfiltered velocity
        being below ``speed_rad_s``: how much of the filtered torque there comes from
        samples where the joint sticks (None: exact samples)."""
        if self.raw_qd is None or self.filter_ba is None:
            return None
        stuck = (np.abs(self.raw_qd) < speed_rad_s).astype(float)
        b, a = self.filter_ba
        start, stop, step = self.kept
        share = signal.filtfilt(b, a, stuck, axis=0)[start:stop:step]
        return np.asarray(np.abs(share), dtype=float)

    def coulomb(self, transition_speed_rad_s: TransitionSpeed) -> F64 | None:
        """The Coulomb regressor columns, filtered like the torque (None: exact samples,
        ``sign(qd)`` as is).

        ``fc sign(qd)`` is the one term of ``tau = Y theta`` that is no smooth function
        of the filtered signals: the low-passed torque changes over a cutoff period
        around a reversal while ``sign`` of the filtered velocity jumps there, which
        biases Coulomb up and viscous down. So the column is ``sign`` (or
        ``tanh(qd / v_s)``) of the unfiltered velocity, low-passed, cut and decimated
        exactly as the torque (parallel filtering: ``filter(Y) theta = filter(Y theta)``).
        """
        if self.raw_qd is None or self.filter_ba is None:
            return None
        column = coulomb_shape(self.raw_qd, transition_speed_rad_s)
        b, a = self.filter_ba
        start, stop, step = self.kept
        return np.asarray(signal.filtfilt(b, a, column, axis=0)[start:stop:step], dtype=float)


def _column(frame: pl.DataFrame, name: str, joints: tuple[str, ...], n: int) -> F64 | None:
    """(n, dof) array of a tidy column in ``joints`` order; None when all null."""
    if name not in frame.columns or frame[name].null_count() == frame.height:
        return None
    wide = frame.pivot(on="joint", index="stamp_ns", values=name, aggregate_function="first")
    wide = wide.sort("stamp_ns")
    out = wide.select(list(joints)).to_numpy().astype(float)
    if out.shape[0] != n:
        raise IdentificationError(f"column {name}: {out.shape[0]} stamps, expected {n}")
    return np.asarray(out, dtype=float)


def joint_samples(recording: Recording, spec: RobotSpec, *, cutoff_hz: float) -> JointSamples:
    """Aligned q, qd, qdd, torque of one recording (see the module docstring).

    Raises:
        IdentificationError: a joint of the robot is missing, no efforts, efforts or
            positions with gaps, too few samples, or a cutoff above the Nyquist rate.
    """
    where = str(recording.source)
    missing = [j for j in spec.joint_names if j not in recording.joint_names]
    if missing:
        raise IdentificationError(
            f"{where}: no joint {missing[0]} of robot '{spec.name}' (the recording has "
            f"{', '.join(recording.joint_names)}); is it a recording of another robot?"
        )
    if recording.decimation != 1:
        raise IdentificationError(f"{where}: read decimated (too large); cannot identify from it")
    frame = recording.samples.filter(pl.col("joint").is_in(list(spec.joint_names)))
    joints = spec.joint_names
    first_joint = frame.filter(pl.col("joint") == joints[0])["stamp_ns"].to_numpy()
    stamps = np.unique(frame["stamp_ns"].to_numpy())
    n = stamps.size
    repeated_stamps = int(first_joint.size - np.unique(first_joint).size)
    truth = recording.has_ground_truth and frame["true_position_rad"].null_count() == 0
    q = _column(frame, "true_position_rad" if truth else "position_rad", joints, n)
    qd = _column(frame, "true_velocity_rad_s" if truth else "velocity_rad_s", joints, n)
    tau = _column(frame, "effort_nm", joints, n)
    if tau is None:
        raise IdentificationError(
            f"{where}: /joint_states has no efforts: identification needs the applied torque"
        )
    assert q is not None  # the reader requires positions
    for name, arr in (("effort", tau), ("position", q)):
        if not np.isfinite(arr).all():
            raise IdentificationError(f"{where}: /joint_states {name} has gaps (NaN or missing)")
    if qd is not None and not np.isfinite(qd).all():
        qd = None  # partly missing velocities: differentiate positions instead
    same = np.all(q[1:] == q[:-1], axis=1) & np.all(tau[1:] == tau[:-1], axis=1)
    if qd is not None:
        same &= np.all(qd[1:] == qd[:-1], axis=1) & np.any(qd[:-1] != 0, axis=1)
    else:  # without velocities a standing arm repeats legitimately: keep every sample
        same = np.zeros_like(same)
    keep = np.concatenate([[True], ~same])
    repeated_values = int(same.sum())
    if repeated_values:
        stamps, q, tau = stamps[keep], q[keep], tau[keep]
        qd = None if qd is None else qd[keep]
        n = stamps.size
    if n < 16:
        raise IdentificationError(f"{where}: {n} samples, too short to identify from")
    t_s = (stamps - stamps[0]) * 1e-9
    periods = np.diff(t_s)
    dt_s = float(np.median(periods))
    if not dt_s > 0:
        raise IdentificationError(f"{where}: sample stamps do not increase")
    resampled = bool(np.abs(periods - dt_s).max() > JITTER_TOL * dt_s)
    if resampled:
        grid = np.arange(0.0, t_s[-1] + 0.5 * dt_s, dt_s)
        q, tau = _resample(t_s, q, grid), _resample(t_s, tau, grid)
        qd = None if qd is None else _resample(t_s, qd, grid)
    sha = recording.sha256
    counts = {
        "repeated_stamps": repeated_stamps,
        "repeated_values": repeated_values,
        "resampled": resampled,
        "period_range_s": (float(periods.min()), float(periods.max())),
    }
    if cutoff_hz == 0:
        if qd is None:
            raise IdentificationError(
                f"{where}: exact differentiation (cutoff 0) needs recorded velocities"
            )
        qdd = np.diff(qd, axis=0) / dt_s
        out = JointSamples(where, sha, q[:-1], qd[:-1], qdd, tau[:-1], dt_s, truth)
    else:
        held = recording.armlab_metadata
        if held:  # tau[k] acts over [t_k, t_k+1]: at t_k, half of it and half of tau[k-1]
            tau = np.vstack([tau[:1], 0.5 * (tau[1:] + tau[:-1])])
        out = _filtered(where, sha, q, qd, tau, dt_s=dt_s, cutoff_hz=cutoff_hz, truth=truth)
        out = replace(out, effort_held=held)
    return replace(out, **counts)  # type: ignore[arg-type]


def _resample(t_s: F64, values: F64, grid: F64) -> F64:
    return np.column_stack([np.interp(grid, t_s, values[:, j]) for j in range(values.shape[1])])


def _filtered(
    where: str,
    sha: str,
    q: F64,
    qd: F64 | None,
    tau: F64,
    *,
    dt_s: float,
    cutoff_hz: float,
    truth: bool,
) -> JointSamples:
    nyquist_hz = 0.5 / dt_s
    if not 0 < cutoff_hz < nyquist_hz:
        raise IdentificationError(
            f"cutoff {cutoff_hz:g} Hz: must be in (0, {nyquist_hz:g}) Hz (half the "
            f"{1 / dt_s:g} Hz sample rate of {where}), or 0 for exact differentiation"
        )
    b, a = signal.butter(FILTER_ORDER, cutoff_hz / nyquist_hz)
    trim = math.ceil(1.0 / (cutoff_hz * dt_s))  # one cutoff period: the edge transients
    if q.shape[0] < 2 * trim + 16:
        raise IdentificationError(
            f"{where}: {q.shape[0]} samples, too short for a {cutoff_hz:g} Hz filter "
            f"(needs more than {2 * trim + 16})"
        )

    def low(x: F64) -> F64:
        return np.asarray(signal.filtfilt(b, a, x, axis=0), dtype=float)

    q_f = low(q)
    qd_f = low(qd) if qd is not None else np.gradient(q_f, dt_s, axis=0)
    qdd_f = np.gradient(qd_f, dt_s, axis=0)
    tau_f = low(tau)
    step = max(1, int(1.0 / (SAMPLES_PER_CUTOFF * cutoff_hz * dt_s)))
    keep = slice(trim, q.shape[0] - trim, step)
    return JointSamples(
        where, sha, q_f[keep], qd_f[keep], qdd_f[keep], tau_f[keep], dt_s * step, truth,
        raw_qd=qd if qd is not None else np.gradient(q, dt_s, axis=0),
        filter_ba=(np.asarray(b, dtype=float), np.asarray(a, dtype=float)),
        kept=(trim, q.shape[0] - trim, step),
    )  # fmt: skip
