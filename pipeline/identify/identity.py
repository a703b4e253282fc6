"""Which robot a model or a recording is of: joint names, kinematics and the robot file's hash.

Joint names alone do not tell a UR5 from a UR10 (same names, other link lengths), so two
robots are the same here when their joint names agree and their flange poses agree at a
few fixed configurations (:data:`PROBES`, within :data:`FK_TOL_M`), up to a turn of the
base about the vertical (which leaves every joint torque unchanged: the ROS UR URDFs and
our DH UR5 differ by such a turn).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from pipeline.model.dh import forward_kinematics
from pipeline.robots.spec import RobotSpec

FK_TOL_M = 1e-4
"""Largest flange position difference [m] (and rotation-matrix entry difference) between
two robots taken as one (rounded URDF numbers pass; a UR5 and a UR10 differ by 0.1 m+)."""

PROBES = 4
"""Joint configurations compared: zero, then seeded draws within the limits (and ±pi)."""


def kinematics_mismatch(a: RobotSpec, b: RobotSpec) -> str | None:
    """Why ``a`` and ``b`` are not one robot's kinematics (a short phrase), or None."""
    if a.joint_names != b.joint_names:
        return f"joints {', '.join(a.joint_names)} vs {', '.join(b.joint_names)}"
    rng = np.random.default_rng(0)
    lower = np.maximum([j.limits.lower for j in a.joints], -np.pi)
    upper = np.minimum([j.limits.upper for j in a.joints], np.pi)
    for k in range(PROBES):
        q = np.zeros(a.dof) if k == 0 else rng.uniform(lower, upper)
        fa, fb = _yaw_free(forward_kinematics(a, q)), _yaw_free(forward_kinematics(b, q))
        gap = float(np.abs(fa - fb).max())
        if gap > FK_TOL_M:
            where = "the zero configuration" if k == 0 else f"q = {np.round(q, 3).tolist()}"
            return f"flange poses differ by {gap:.3g} at {where}"
    return None


def _yaw_free(pose: np.ndarray) -> np.ndarray:
    """What of a flange pose a turn of the base about gravity (z) leaves alone, and so
    what the joint torques see: the position's distance from the z axis and its height
    [m], and the rotation's bottom row (a URDF's base is often turned by pi)."""
    p = pose[:3, 3]
    return np.concatenate([[np.hypot(p[0], p[1]), p[2]], pose[2, :3]])


def robot_file_sha256(spec: RobotSpec) -> str:
    """SHA-256 of the file ``spec`` was loaded from ("" when it cannot be found): the
    loader's own hash, else the file at ``spec.source`` (a built-in's is in the package)."""
    if spec.source_sha256:
        return spec.source_sha256
    source = Path(spec.source)
    package = Path(__file__).parents[1]
    for path in [source] if source.is_absolute() else [package / source, source]:
        try:
            return hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError:
            continue
    return ""
