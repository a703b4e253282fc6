"""When a held pose is settled: the one criterion the pre-roll and the hold share.

An episode holds its start pose before the motion (the pre-roll) so that metrics start
from a settled state. The pre-roll ends at the first window of :data:`SETTLING` in
which the arm is settled; at the cap (the scenario's ``preroll_s``) it ends anyway,
and the episode says so (``EpisodeResult.preroll_settled``, the report's
findings).

Settled over a window of ``window_s`` (every row of it, every joint):

- the tracking error ``q_ref - q`` has stopped moving: it stays within
  ``error_change_rad`` of its value at the window's first row;
- the joint speed ``|qd|`` is below ``velocity_rad_s``;
- the integral term has stopped moving: over the window, it changes by less than
  ``integral_rad`` on every joint, measured as the position error it stands for (its
  torque, or for computed torque its acceleration, over ``kp``: the units of the error
  band, and a scale in which the encoder noise it integrates stays below the
  threshold). A controller with an integrator exposes it as :data:`INTEGRAL_ATTRIBUTE`;
  one without has nothing to wait for.

The state read is the plant's (true) state, not the noisy measurement: the question is
whether the arm is settled, not whether a sensor says so.

Settled means steady, not small: a law without integral action on a mismatched plant
comes to rest with an offset, and that offset is its steady-state error (the error at
the target measures it; the report shows the start's as *at start*). An absolute band
would call every such hold "not settled" and take the error at the target out of every
verdict where it matters most.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.trajectory import F64


@dataclass(frozen=True)
class SettlingCriterion:
    """The thresholds of :func:`settled` (declared once, in :data:`SETTLING`).

    Attributes:
        error_change_rad: every joint's tracking error stays this close to its value
            at the window's start [rad].
        velocity_rad_s: every joint's |velocity| stays below this [rad/s].
        integral_rad: the integral term's change over the window, as a position error
            (``INTEGRAL_ATTRIBUTE``) [rad].
        window_s: how long all of it must hold [s].
    """

    error_change_rad: float = 1e-5
    velocity_rad_s: float = 1e-3
    integral_rad: float = 1e-5
    window_s: float = 0.1


SETTLING = SettlingCriterion()
"""The settling criterion of every pre-roll and every hold."""

INTEGRAL_ATTRIBUTE = "integral_rad"
"""Where a controller exposes its integral term, as the position error it stands for."""


def integral_state(controller: object) -> F64 | None:
    """A copy of the controller's integral term [rad], or None when it has none."""
    value = getattr(controller, INTEGRAL_ATTRIBUTE, None)
    return None if value is None else np.array(value, dtype=float, copy=True)


def settled(
    error_rad: F64,
    velocity_rad_s: F64,
    *,
    integral_before: F64 | None = None,
    integral_after: F64 | None = None,
    criterion: SettlingCriterion = SETTLING,
) -> bool:
    """Whether a window of rows is settled under ``criterion``.

    Args:
        error_rad: (rows, n) tracking error ``q_ref - q`` over the window [rad].
        velocity_rad_s: (rows, n) joint velocity over the window [rad/s].
        integral_before, integral_after: the controller's integral term [rad] at the
            window's start and end (None: the controller has no integral).
        criterion: the thresholds.
    """
    if error_rad.size == 0:
        return False
    if not (np.abs(error_rad - error_rad[0]) < criterion.error_change_rad).all():
        return False
    if not (np.abs(velocity_rad_s) < criterion.velocity_rad_s).all():
        return False
    if integral_before is None or integral_after is None:
        return True
    return bool((np.abs(integral_after - integral_before) < criterion.integral_rad).all())
