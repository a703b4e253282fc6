"""Joint limits: check a configuration, and bring angles into the range near a seed."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import KinematicsError
from pipeline.robots.spec import RobotSpec

Array = NDArray[np.float64]
TWO_PI = 2.0 * math.pi
LIMIT_TOL_RAD = 1e-9
"""Slack on joint limits [rad]: a closed-form angle a hair outside is clipped, not dropped."""


def within_limits(spec: RobotSpec, q: ArrayLike, *, tol_rad: float = LIMIT_TOL_RAD) -> bool:
    """True if every joint of ``q`` [rad] is inside [lower - tol, upper + tol]."""
    arr = joint_vector(spec, q)
    return bool(np.all(arr >= spec.lower - tol_rad) and np.all(arr <= spec.upper + tol_rad))


def check_joint_limits(spec: RobotSpec, q: ArrayLike, *, tol_rad: float = LIMIT_TOL_RAD) -> None:
    """Raise KinematicsError naming the first joint outside its limits."""
    arr = joint_vector(spec, q)
    for joint, value in zip(spec.joints, arr, strict=True):
        lim = joint.limits
        if not lim.lower - tol_rad <= value <= lim.upper + tol_rad:
            raise KinematicsError(
                f"robot '{spec.name}': {joint.name} = {value:.6g} rad is outside its limits "
                f"[{lim.lower:.6g}, {lim.upper:.6g}] rad"
            )


def wrap_to_limits(
    angles: Array,
    lower: Array,
    upper: Array,
    seed: Array,
    *,
    joint_axis: int = -1,
    tol_rad: float = LIMIT_TOL_RAD,
) -> tuple[Array, NDArray[np.bool_]]:
    """Bring each angle to its 2 pi representative nearest the seed that lies in the limits.

    ``lower``, ``upper`` and ``seed`` broadcast against ``angles``; ``joint_axis``
    is the axis that runs over joints (the mask reduces over it). For a range at
    least 2 pi wide an in-range representative always exists; for a narrower
    one there may be none, and that entry is masked out.

    Returns:
        (wrapped angles [rad], clipped into the limits; mask that is True where
        every joint was within [lower - tol, upper + tol]).
    """
    out = angles - TWO_PI * np.rint((angles - seed) / TWO_PI)
    out = np.where(out > upper + tol_rad, out - TWO_PI, out)
    out = np.where(out < lower - tol_rad, out + TWO_PI, out)
    ok = np.all((out >= lower - tol_rad) & (out <= upper + tol_rad), axis=joint_axis)
    return np.clip(out, lower, upper), ok


def nearest_representative(q: Array, seed: Array, lower: Array, upper: Array) -> Array:
    """Each joint of ``q`` [rad] moved by a multiple of 2 pi to the value nearest the seed
    that is within the limits; a joint with no such other value keeps its own."""
    out = []
    for a, s, lo, hi in zip(q.tolist(), seed.tolist(), lower.tolist(), upper.tolist(), strict=True):
        r = a - TWO_PI * round((a - s) / TWO_PI)
        if r > hi:
            r -= TWO_PI
        elif r < lo:
            r += TWO_PI
        out.append(r if lo <= r <= hi else a)
    return np.array(out)


def joint_vector(spec: RobotSpec, q: ArrayLike) -> Array:
    """``q`` as a flat float array of one value per joint [rad].

    Raises:
        KinematicsError: ``q`` does not hold exactly one value per joint of ``spec``.
    """
    arr = np.asarray(q, dtype=float).reshape(-1)
    if arr.shape[0] != spec.dof:
        raise KinematicsError(
            f"robot '{spec.name}' has {spec.dof} joints, got {arr.shape[0]} joint values"
        )
    return arr
