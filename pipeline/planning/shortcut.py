"""Rope shortcutting that checks only the motions that can shorten the path (issue 21).

RRT-Rope (Petit and Lussier Desbiens, SMC 2021; OMPL's ``ropeShortcutPath``):
put states at most ``delta`` apart along the path, then for each state ``i``, from
the path's end backwards, connect ``i`` to the farthest state ``j`` it reaches in a
straight motion, unless the path from ``i`` to ``j`` is already within
``tolerance * delta`` of that straight line; after a shortcut, densify it and
start again from the first state.

Most of the collision checks OMPL's version makes go to motions that cannot change
anything: a valid motion whose shortcut gains less than the tolerance is checked
in full (every state, often right along an obstacle) and then dropped. The gain
``along(i, j) - |q_j - q_i|`` never grows as ``j`` comes closer to ``i`` (triangle
inequality), so once it is below the tolerance no nearer ``j`` can gain either:
``rope_shortcut`` stops there without checking, and checks only motions that would
be taken if valid. Same shortcuts as checking them all (~3 valid motions per plan
around the test box instead of ~20).

Two things differ from OMPL 2.0.1's code, on purpose: a shortcut is densified by
its own length (OMPL measures from ``i`` to the state that follows the shortcut
once the skipped states are erased, and reads past the path's end when there is
none), and the arithmetic is numpy's. So plans are not OMPL's bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

MotionCheck = Callable[[F64, F64], bool]
"""``(qa, qb) -> bool``: is the straight motion clear (``qa`` assumed valid)?"""


def _distance(a: F64, b: F64) -> float:
    """Euclidean distance, summed in joint order (OMPL's ``RealVectorStateSpace``)."""
    total = 0.0
    for x, y in zip(a.tolist(), b.tolist(), strict=True):
        total += (x - y) * (x - y)
    return math.sqrt(total)


def _between(a: F64, b: F64, length: float, delta: float) -> list[F64]:
    """``floor(length / delta)`` states evenly spaced strictly between ``a`` and ``b``
    (none when ``length <= delta``)."""
    if length <= delta:
        return []
    m = math.floor(length / delta)
    t = 1.0 / (m + 1)
    return [a + (b - a) * (t * (k + 1)) for k in range(m)]


def _cumulative(states: Sequence[F64], start: float) -> list[float]:
    """Path length [rad] at each of ``states``, from ``start`` at the first."""
    out = [start]
    for a, b in pairwise(states):
        out.append(out[-1] + _distance(a, b))
    return out


def densify(waypoints: F64, delta: float) -> list[F64]:
    """The path's states with states added so that none are more than ``delta`` apart."""
    states: list[F64] = [np.asarray(waypoints[0], dtype=np.float64)]
    for a, b in pairwise(waypoints):
        states.extend(_between(a, b, _distance(a, b), delta))
        states.append(np.asarray(b, dtype=np.float64))
    return states


def rope_shortcut(
    waypoints: F64, *, delta: float, tolerance: float, motion_clear: MotionCheck
) -> F64:
    """Shorten a valid piecewise-linear path (K, n) by rope shortcutting.

    Args:
        waypoints: the path [rad]; each segment already valid.
        delta: spacing of the states shortcuts may start and end at [rad].
        tolerance: a shortcut must gain at least ``tolerance * delta`` [rad].
        motion_clear: the motion check (called only for shortcuts that gain).

    Returns:
        The shortened path (first and last states unchanged). Every segment is either
        part of a segment of ``waypoints`` or a motion ``motion_clear`` accepted.
    """
    if len(waypoints) < 3:
        return np.array(waypoints, dtype=np.float64)
    states = densify(waypoints, delta)
    costs = _cumulative(states, 0.0)
    enough = tolerance * delta
    i = 0
    while i < len(states) - 2:
        restart = False
        for j in range(len(states) - 1, i + 1, -1):
            short = _distance(states[i], states[j])
            if costs[j] - costs[i] - short < enough:
                break  # no j closer to i gains either
            if motion_clear(states[i], states[j]):
                a, b = states[i], states[j]
                states[i + 1 : j] = _between(a, b, short, delta)
                costs = [*costs[:i], *_cumulative(states[i:], costs[i])]
                restart = True
                break
        i = 0 if restart else i + 1
    return np.array(states)
