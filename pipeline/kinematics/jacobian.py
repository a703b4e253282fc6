"""Flange Jacobian (Pinocchio), Yoshikawa manipulability and a singularity flag."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from pipeline.kinematics.fk import flange_model
from pipeline.kinematics.limits import joint_vector
from pipeline.robots.spec import RobotSpec

Array = NDArray[np.float64]

SINGULAR_SIGMA = 1e-3
"""Default singularity threshold: smallest singular value of the 6 x n Jacobian."""


def jacobian(spec: RobotSpec, q: ArrayLike) -> Array:
    """Geometric Jacobian of the flange, 6 x dof, rows [v; omega] in base-frame axes.

    v is the flange origin's linear velocity [m/s per rad/s], omega the angular
    velocity [rad/s per rad/s] (Pinocchio ``LOCAL_WORLD_ALIGNED``).
    """
    model, data, fid = flange_model(spec)
    qs = joint_vector(spec, q)
    out: Array = np.array(
        pin.computeFrameJacobian(model, data, qs, fid, pin.LOCAL_WORLD_ALIGNED), dtype=float
    )
    return out


def manipulability(spec: RobotSpec, q: ArrayLike) -> float:
    """Yoshikawa's manipulability sqrt(det(J J^T)) of the flange Jacobian (0 at a singularity)."""
    j = jacobian(spec, q)
    return math.sqrt(max(0.0, float(np.linalg.det(j @ j.T))))


def min_singular_value(spec: RobotSpec, q: ArrayLike) -> float:
    """Smallest singular value of the flange Jacobian (distance to a singularity)."""
    return float(np.linalg.svd(jacobian(spec, q), compute_uv=False)[-1])


def is_singular(spec: RobotSpec, q: ArrayLike, *, threshold: float = SINGULAR_SIGMA) -> bool:
    """True if the flange Jacobian's smallest singular value is below ``threshold``.

    The singular value mixes units (m per rad in the position rows, 1 in the
    rotation rows). On the UR5 it is about 0.45 |sin theta5| near the wrist
    singularity and 0.16 |sin theta3| near the elbow one, so the default 1e-3
    flags configurations within a few milliradians of them.
    """
    return min_singular_value(spec, q) < threshold
