"""Forward kinematics: of any robot's joint model, and closed-form from DH rows.

:func:`forward_kinematics` / :func:`link_frames` compose the joint model (origins, axes) of
any robot; :func:`dh_link_frames` multiplies the textbook per-joint DH matrices directly,
the reference the joint model, MuJoCo and Pinocchio are checked against for DH robots.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import KinematicsError
from pipeline.robots.chain import chain_arrays, joint_motion
from pipeline.robots.spec import IDENTITY, DHRow, RobotSpec, pose_matrix


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


def dh_link_frames(spec: RobotSpec, q: ArrayLike) -> list[NDArray[np.float64]]:
    """Poses of DH frames 1..n in the DH base frame 0, straight from the DH rows.

    Raises:
        KinematicsError: the robot is not given as DH rows, or bad ``q``.
    """
    qs = _check(spec, q)
    rows = spec.dh_rows
    if rows is None:
        raise KinematicsError(f"{spec.source}: robot '{spec.name}' has no DH rows")
    step = standard_dh_matrix if spec.convention == "standard" else modified_dh_matrix
    t = np.eye(4)
    out = []
    for row, qi in zip(rows, qs, strict=True):
        t = t @ step(row, float(qi))
        out.append(t)
    return out


def link_frames(spec: RobotSpec, q: ArrayLike) -> list[NDArray[np.float64]]:
    """Poses of the link frames 1..n in the base frame (``base_T_i``) at ``q`` (a DH
    robot's link frames are its DH frames)."""
    qs = _check(spec, q)
    t = np.eye(4)
    out = []
    for joint, (pre, post, pre_is_id, post_is_id), qi in zip(
        spec.joints, chain_arrays(spec), qs, strict=True
    ):
        if not pre_is_id:
            t = t @ pre
        t = t @ joint_motion(joint, float(qi))
        if not post_is_id:
            t = t @ post
        out.append(t)
    return out


def forward_kinematics(spec: RobotSpec, q: ArrayLike) -> NDArray[np.float64]:
    """Flange pose ``base_T_flange`` (the ``tool0`` frame in the base frame) as a 4x4 [m]."""
    last = link_frames(spec, q)[-1]
    return last if spec.flange == IDENTITY else last @ pose_matrix(spec.flange)
