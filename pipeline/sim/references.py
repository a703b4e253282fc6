"""Simple joint-space references: test motions and benchmark inputs (the planner makes real ones).

A reference may offer ``sample_many(times_s)`` besides the ``Reference``
protocol's ``sample(t_s)``: the runner then samples the whole episode in one
vectorized call before the control loop instead of once per control step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from pipeline.trajectory import F64, Reference

PAPER_START_RAD = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
"""The paper's start pose (Table 2) [rad]."""
PAPER_GOAL_RAD = (-0.15, -0.5, 0.785, -1.15, -0.3925, 0.0)
"""The paper's goal pose (Table 2) [rad]."""


@runtime_checkable
class BatchReference(Reference, Protocol):
    """A reference that can also be sampled at many instants in one call."""

    def sample_many(self, times_s: F64) -> tuple[F64, F64, F64]:
        """(K, n) position [rad], velocity [rad/s], acceleration [rad/s^2] at ``times_s`` (K,)."""
        ...


@dataclass(frozen=True)
class QuinticReference:
    """Minimum-jerk (quintic) rest-to-rest motion in joint space.

    ``q(t) = start + (goal - start) s(t/T)``, ``s(u) = 10u^3 - 15u^4 + 6u^5``:
    zero velocity and acceleration at both ends; holds ``goal`` after ``T``.

    Attributes:
        start: start pose [rad].
        goal: goal pose [rad].
        duration_s: motion time T [s], > 0.
    """

    start: tuple[float, ...]
    goal: tuple[float, ...]
    duration_s: float

    @classmethod
    def between(
        cls, start: Sequence[float], goal: Sequence[float], *, duration_s: float
    ) -> QuinticReference:
        """Build from any sequences (checked: same length, finite, duration > 0)."""
        s = tuple(float(x) for x in start)
        g = tuple(float(x) for x in goal)
        if len(s) != len(g):
            raise ValueError(f"start has {len(s)} joints, goal {len(g)}")
        if not (np.isfinite(s).all() and np.isfinite(g).all()):
            raise ValueError("start and goal must be finite")
        if not duration_s > 0:
            raise ValueError(f"duration_s must be > 0, got {duration_s}")
        return cls(s, g, float(duration_s))

    def sample(self, t_s: float) -> tuple[F64, F64, F64]:
        q, qd, qdd = self.sample_many(np.array([t_s], dtype=float))
        return q[0], qd[0], qdd[0]

    def sample_many(self, times_s: F64) -> tuple[F64, F64, F64]:
        t = np.asarray(times_s, dtype=float)
        u = np.clip(t / self.duration_s, 0.0, 1.0)[:, None]
        start = np.asarray(self.start)
        delta = np.asarray(self.goal) - start
        s = u**3 * (10.0 + u * (-15.0 + 6.0 * u))
        ds = 30.0 * u**2 * (1.0 - u) ** 2 / self.duration_s
        dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / self.duration_s**2
        # u is clipped to [0, 1], where ds and dds vanish: before and after the motion
        # the reference holds still.
        return start + delta * s, delta * ds, delta * dds
