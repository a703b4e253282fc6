"""Small rigid-transform helpers (4x4 homogeneous matrices, numpy)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

Mat = NDArray[np.float64]


def rot_x(angle: float) -> Mat:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_z(angle: float) -> Mat:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def rot_axis(axis: Mat, angle: float) -> Mat:
    """Rotation by ``angle`` [rad] about the unit ``axis`` (Rodrigues), as a 4x4."""
    x, y, z = (float(v) for v in axis)
    c, s = math.cos(angle), math.sin(angle)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    out = np.eye(4)
    out[:3, :3] = np.eye(3) + s * k + (1.0 - c) * (k @ k)
    return out


def motion(kind: str, axis: tuple[float, float, float], q: float) -> Mat:
    """The motion of a joint of ``kind`` (revolute, continuous, prismatic) about / along the
    unit ``axis`` (joint frame) at ``q`` [rad or m], as a 4x4. Every frame computation composes
    joints through it, or through its batched forms in :mod:`pipeline.robots.chain`."""
    if kind == "prismatic":
        return trans(*(q * np.array(axis, dtype=float)))
    if tuple(axis) == (0.0, 0.0, 1.0):
        return rot_z(q)
    return rot_axis(np.array(axis, dtype=float), q)


def trans(x: float, y: float, z: float) -> Mat:
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


def inverse(t: Mat) -> Mat:
    out = np.eye(4)
    r = t[:3, :3]
    out[:3, :3] = r.T
    out[:3, 3] = -r.T @ t[:3, 3]
    return out


def quat_wxyz(r: Mat) -> Mat:
    """Unit quaternion (w, x, y, z), w >= 0, of a rotation matrix."""
    m = np.asarray(r, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    out = np.array(q)
    out /= np.linalg.norm(out)
    return out if out[0] >= 0 else -out


def quat_to_matrix(q_wxyz: Mat) -> Mat:
    q = np.asarray(q_wxyz, dtype=float)
    q = q / np.abs(q).max()  # first: the norm of (1e308, 1e308, 0, 0) overflows
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rpy(r: Mat) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] with R = Rz(yaw) Ry(pitch) Rx(roll)."""
    m = np.asarray(r, dtype=float)
    pitch = math.atan2(-m[2, 0], math.hypot(m[0, 0], m[1, 0]))
    if abs(math.cos(pitch)) < 1e-12:  # gimbal lock: put all yaw into roll
        roll = math.atan2(-m[1, 2], m[1, 1])
        return roll, pitch, 0.0
    roll = math.atan2(m[2, 1], m[2, 2])
    yaw = math.atan2(m[1, 0], m[0, 0])
    return roll, pitch, yaw


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> Mat:
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    out: Mat = rz @ ry @ rx
    return out


def rotation_angle_between(r_a: Mat, r_b: Mat) -> float:
    """Geodesic angle [rad] between two rotation matrices."""
    c = (np.trace(np.asarray(r_a).T @ np.asarray(r_b)) - 1.0) / 2.0
    return math.acos(max(-1.0, min(1.0, float(c))))
