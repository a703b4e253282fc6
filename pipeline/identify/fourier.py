"""Finite Fourier series joint trajectories (Swevers et al., IEEE T-RA 1997).

Per joint j, with base frequency ``w_f = 2 pi f_base``::

    q_j(t) = q0_j + sum_l  a_jl / (l w_f) sin(l w_f t) - b_jl / (l w_f) cos(l w_f t)

periodic with period ``1 / f_base``. The free coefficients exclude the first harmonic,
which is set so the motion starts at rest (``qd(0) = 0``: ``sum_l a_jl = 0``;
``qdd(0) = 0``: ``sum_l l b_jl = 0``): the episode's pre-roll holds ``q(0)``, and the
excitation starts without a jump in the reference's velocity or acceleration. After
``periods`` periods it ends at rest at ``q(0)`` again.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def full_coefficients(free: F64, dof: int, harmonics: int) -> tuple[F64, F64]:
    """(dof, harmonics) ``a`` and ``b`` from the free ones (harmonics 2.. of each)."""
    free = np.asarray(free, dtype=float).reshape(2, dof, harmonics - 1)
    a = np.empty((dof, harmonics))
    b = np.empty((dof, harmonics))
    orders = np.arange(2, harmonics + 1)
    a[:, 1:] = free[0]
    b[:, 1:] = free[1]
    a[:, 0] = -free[0].sum(axis=1)
    b[:, 0] = -(free[1] * orders).sum(axis=1)
    return a, b


@dataclass(frozen=True)
class FourierReference:
    """A finite Fourier series reference (satisfies ``pipeline.trajectory.Reference``).

    Attributes:
        q0: (dof,) the series' offset (mid posture) [rad].
        a, b: (dof, harmonics) coefficients [rad/s].
        base_frequency_hz: ``f_base`` [Hz].
        periods: whole periods run; the motion lasts ``periods / f_base``.
    """

    q0: tuple[float, ...]
    a: tuple[tuple[float, ...], ...]
    b: tuple[tuple[float, ...], ...]
    base_frequency_hz: float
    periods: int

    @classmethod
    def from_free(
        cls, q0: F64, free: F64, *, harmonics: int, base_frequency_hz: float, periods: int
    ) -> FourierReference:
        dof = len(q0)
        a, b = full_coefficients(free, dof, harmonics)
        return cls(
            q0=tuple(float(x) for x in q0),
            a=tuple(tuple(float(x) for x in row) for row in a),
            b=tuple(tuple(float(x) for x in row) for row in b),
            base_frequency_hz=float(base_frequency_hz),
            periods=int(periods),
        )

    @property
    def duration_s(self) -> float:
        return self.periods / self.base_frequency_hz

    def sample(self, t_s: float) -> tuple[F64, F64, F64]:
        q, qd, qdd = self.sample_many(np.array([t_s], dtype=float))
        return q[0], qd[0], qdd[0]

    def sample_many(self, times_s: F64) -> tuple[F64, F64, F64]:
        """(K, dof) position, velocity, acceleration; held at ``q(0)`` outside the motion."""
        t = np.clip(np.asarray(times_s, dtype=float), 0.0, self.duration_s)
        moving = (np.asarray(times_s) > 0) & (np.asarray(times_s) < self.duration_s)
        a = np.asarray(self.a)
        b = np.asarray(self.b)
        w = 2 * math.pi * self.base_frequency_hz * np.arange(1, a.shape[1] + 1)  # (L,)
        phase = t[:, None] * w[None, :]  # (K, L)
        sin, cos = np.sin(phase), np.cos(phase)
        q = np.asarray(self.q0) + sin @ (a / w).T - cos @ (b / w).T
        qd = cos @ a.T + sin @ b.T
        qdd = -(sin * w) @ a.T + (cos * w) @ b.T
        qd[~moving] = 0.0
        qdd[~moving] = 0.0
        return q, qd, qdd


def write_csv(path: Path, reference: FourierReference, joint_names: Sequence[str], *,
              rate_hz: float) -> int:  # fmt: skip
    """The reference sampled at ``rate_hz`` as CSV (``time_s``, then per joint ``q_<name>``
    [rad], ``qd_<name>`` [rad/s], ``qdd_<name>`` [rad/s^2]): a trajectory a real robot's
    controller can stream. Returns the rows written."""
    t = np.arange(0.0, reference.duration_s + 0.5 / rate_hz, 1.0 / rate_hz)
    q, qd, qdd = reference.sample_many(t)
    header = ["time_s"] + [f"{k}_{n}" for k in ("q", "qd", "qdd") for n in joint_names]
    table = np.column_stack([t, q, qd, qdd])
    lines = [",".join(header)] + [",".join(repr(float(x)) for x in row) for row in table]
    from pipeline.fsutil import atomic_write_bytes

    atomic_write_bytes(Path(path), ("\n".join(lines) + "\n").encode("utf-8"))
    return int(t.size)
