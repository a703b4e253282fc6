"""Trajectories as the planner hands them on: the reference protocol and sampled points.

Shared vocabulary below planning, the simulator and the log writer (data flows one way:
planning produces these, the others consume them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


class Reference(Protocol):
    """A time-parameterized joint reference (the planner's output, or any other)."""

    @property
    def duration_s(self) -> float:
        """Time at which the motion ends; after it ``sample`` holds the goal."""
        ...

    def sample(self, t_s: float) -> tuple[F64, F64, F64]:
        """Reference position [rad], velocity [rad/s], acceleration [rad/s^2] at ``t_s``."""
        ...


@dataclass(frozen=True)
class TrajectorySamples:
    """A time-parameterized trajectory sampled at known instants (for logging).

    Attributes:
        times_s: (K,) time from the trajectory start [s].
        positions, velocities, accelerations: (K, n) [rad], [rad/s], [rad/s^2].
    """

    times_s: F64
    positions: F64
    velocities: F64
    accelerations: F64
