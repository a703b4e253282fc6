"""Closed-form DH forward kinematics, standard and modified (Craig) conventions.

This is the reference implementation the MuJoCo and Pinocchio models are
checked against: it multiplies the textbook per-joint matrices directly.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import KinematicsError
from pipeline.robots.spec import DHRow, RobotSpec


def standard_dh_matrix(row: DHRow, q: float) -> NDArray[np.float64]:
    """A_i = Rz(theta) Tz(d) Tx(a) Rx(alpha), theta = q + offset."""
    th = q + row.theta_offset
    ct, st = math.cos(th), math.sin(th)
    ca, sa = math.cos(row.alpha), math.sin(row.alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, row.a * ct],
            [st, ct * ca, -ct * sa, row.a * st],
            [0.0, sa, ca, row.d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def modified_dh_matrix(row: DHRow, q: float) -> NDArray[np.float64]:
    """A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta) Tz(d), theta = q + offset."""
    th = q + row.theta_offset
    ct, st = math.cos(th), math.sin(th)
    ca, sa = math.cos(row.alpha), math.sin(row.alpha)
    return np.array(
        [
            [ct, -st, 0.0, row.a],
            [st * ca, ct * ca, -sa, -sa * row.d],
            [st * sa, ct * sa, ca, ca * row.d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _check(spec: RobotSpec, q: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(q, dtype=float).reshape(-1)
    if arr.shape[0] != spec.dof:
        raise KinematicsError(
            f"robot '{spec.name}' has {spec.dof} joints, got {arr.shape[0]} joint values"
        )
    if not np.all(np.isfinite(arr)):
        raise KinematicsError(f"joint values must be finite [rad], got {arr.tolist()}")
    return arr


def link_frames(spec: RobotSpec, q: ArrayLike) -> list[NDArray[np.float64]]:
    """Poses of DH frames 1..n in the DH base frame 0 (``base_T_i``)."""
    qs = _check(spec, q)
    step = standard_dh_matrix if spec.convention == "standard" else modified_dh_matrix
    t = np.eye(4)
    out = []
    for row, qi in zip((j.dh for j in spec.joints), qs, strict=True):
        t = t @ step(row, float(qi))
        out.append(t)
    return out


def forward_kinematics(spec: RobotSpec, q: ArrayLike) -> NDArray[np.float64]:
    """Flange pose ``base_T_flange`` (DH frame n in frame 0) as a 4x4 matrix [m]."""
    return link_frames(spec, q)[-1]
