"""The IK interface: pose targets, options, results and the solver protocol.

A pose target is a 4x4 homogeneous matrix ``base_T_flange``: the flange frame
(``tool0``) in the robot's base frame, exactly what
:func:`pipeline.kinematics.fk.flange_pose` returns. :func:`target_pose`
builds one from a position and a rotation given as a matrix, a quaternion
(w, x, y, z) or roll/pitch/yaw (R = Rz(yaw) Ry(pitch) Rx(roll)).

What IK means depends on the joint count. An arm with at least
:data:`FULL_POSE_DOF` (6) joints is asked for the whole pose, position and
orientation. An arm with fewer joints cannot reach arbitrary 6-D poses, so its
IK is position-only: the target's rotation is ignored and only the flange
position must match (:func:`position_only`). Joints beyond what the task needs
(7 for a full pose, 4 or more for a position) are redundant; the numeric solver
spends them on a pull toward a rest posture (:class:`IKOptions`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline import transforms as tf
from pipeline.errors import KinematicsError
from pipeline.kinematics.fk import flange_pose
from pipeline.robots.spec import RobotSpec

Array = NDArray[np.float64]

DEFAULT_TOL_M = 1e-6
"""Default IK position tolerance [m]."""
DEFAULT_TOL_RAD = 1e-6
"""Default IK orientation tolerance [rad]."""
ROTATION_TOL = 1e-6
"""Largest |R^T R - I| entry accepted as a rotation matrix in a pose target."""
FULL_POSE_DOF = 6
"""Joints an arm needs for IK on the full pose; fewer get position-only IK."""


def position_only(spec: RobotSpec) -> bool:
    """True if ``spec``'s IK matches the flange position only (fewer than 6 joints)."""
    return spec.dof < FULL_POSE_DOF


def task_dim(spec: RobotSpec) -> int:
    """Task-space dimension of ``spec``'s IK: 3 (position only) or 6 (full pose)."""
    return 3 if position_only(spec) else 6


def meets_tolerance(
    spec: RobotSpec, pos_err_m: float, ang_err_rad: float, *, tol_m: float, tol_rad: float
) -> bool:
    """True if errors from :func:`verify_solution` are within tolerance; the orientation
    error is not judged for a position-only robot (:func:`position_only`)."""
    return pos_err_m <= tol_m and (position_only(spec) or ang_err_rad <= tol_rad)


def target_pose(
    position_m: ArrayLike,
    *,
    rotation: ArrayLike | None = None,
    quaternion_wxyz: ArrayLike | None = None,
    rpy_rad: ArrayLike | None = None,
) -> Array:
    """A pose target ``base_T_flange`` (4x4) from a position and exactly one rotation form.

    Args:
        position_m: flange origin in the DH base frame [m], 3 values.
        rotation: 3x3 rotation matrix (orthonormal, det +1).
        quaternion_wxyz: unit quaternion (w, x, y, z); normalised here, must not be zero.
        rpy_rad: roll, pitch, yaw [rad], R = Rz(yaw) Ry(pitch) Rx(roll).

    Raises:
        KinematicsError: wrong sizes, non-finite values, no or several rotation forms,
            a zero quaternion or a matrix that is not a rotation.
    """
    given = [n for n, v in (("rotation", rotation), ("quaternion", quaternion_wxyz),
                            ("rpy", rpy_rad)) if v is not None]  # fmt: skip
    if len(given) != 1:
        raise KinematicsError(
            "a pose target needs exactly one of rotation matrix, quaternion (w x y z) or "
            f"rpy (roll pitch yaw); got {', '.join(given) if given else 'none'}"
        )
    p = _vector(position_m, 3, "position [m]")
    if rotation is not None:
        r = np.asarray(rotation, dtype=float)
        if r.shape != (3, 3) or not np.all(np.isfinite(r)):
            raise KinematicsError(f"rotation must be a finite 3x3 matrix, got shape {r.shape}")
        ortho = float(np.abs(r.T @ r - np.eye(3)).max())
        if ortho > ROTATION_TOL or np.linalg.det(r) < 0:
            raise KinematicsError(
                f"rotation is not a rotation matrix (|R^T R - I| = {ortho:.2g}, "
                f"det = {np.linalg.det(r):.3g}); expected orthonormal with det +1"
            )
    elif quaternion_wxyz is not None:
        qv = _vector(quaternion_wxyz, 4, "quaternion (w x y z)")
        if not np.any(qv):
            raise KinematicsError("quaternion (w x y z) must not be zero")
        r = tf.quat_to_matrix(qv)
    else:
        assert rpy_rad is not None  # exactly one form was given
        roll, pitch, yaw = _vector(rpy_rad, 3, "rpy (roll pitch yaw) [rad]")
        r = tf.rpy_to_matrix(float(roll), float(pitch), float(yaw))
    out = np.eye(4)
    out[:3, :3] = r
    out[:3, 3] = p
    return out


def _vector(values: ArrayLike, n: int, what: str) -> Array:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape[0] != n or not np.all(np.isfinite(arr)):
        raise KinematicsError(f"{what} needs {n} finite values, got {arr.tolist()}")
    return arr


def as_pose(base_T_flange: ArrayLike) -> Array:
    """Validate a 4x4 pose target: finite, rotation block orthonormal with det +1
    (to 1e-6), last row 0 0 0 1. Returns it as a float array."""
    return pose_rows(base_T_flange)[0]


def pose_rows(base_T_flange: ArrayLike) -> tuple[Array, list[list[float]]]:
    """:func:`as_pose`, plus the top 3 rows as Python floats (cheap for one pose)."""
    t = np.asarray(base_T_flange, dtype=float)
    if t.shape != (4, 4):
        raise KinematicsError(f"a pose target is a finite 4x4 matrix, got shape {t.shape}")
    rows: list[list[float]] = t.tolist()
    (nx, ox, ax, px), (ny, oy, ay, py), (nz, oz, az, pz), last = rows
    tol = ROTATION_TOL
    # the common case in plain floats; the numpy path below says what is wrong
    if not (
        math.isfinite(nx + ox + ax + px + ny + oy + ay + py + nz + oz + az + pz)
        and last == [0.0, 0.0, 0.0, 1.0]
        and abs(nx * nx + ny * ny + nz * nz - 1.0) <= tol
        and abs(ox * ox + oy * oy + oz * oz - 1.0) <= tol
        and abs(ax * ax + ay * ay + az * az - 1.0) <= tol
        and abs(nx * ox + ny * oy + nz * oz) <= tol
        and abs(nx * ax + ny * ay + nz * az) <= tol
        and abs(ox * ax + oy * ay + oz * az) <= tol
        and (ny * oz - nz * oy) * ax + (nz * ox - nx * oz) * ay + (nx * oy - ny * ox) * az > 0.0
    ):
        _raise_pose_problem(t)
    return t, rows[:3]


def _raise_pose_problem(t: Array) -> None:
    if not np.all(np.isfinite(t)):
        raise KinematicsError(f"a pose target must be finite, got {t.tolist()}")
    if np.abs(t[3] - (0.0, 0.0, 0.0, 1.0)).max() > 1e-12:
        raise KinematicsError(f"a pose target's last row must be [0 0 0 1], got {t[3].tolist()}")
    r = t[:3, :3]
    ortho = float(np.abs(r.T @ r - np.eye(3)).max())
    if ortho > ROTATION_TOL or np.linalg.det(r) < 0:
        raise KinematicsError(
            f"a pose target's 3x3 block is not a rotation (|R^T R - I| = {ortho:.2g}, "
            f"det = {np.linalg.det(r):.3g}); expected orthonormal with det +1"
        )


def pose_summary(base_T_flange: Array) -> dict[str, list[float]]:
    """JSON-ready pose: ``position`` [m], ``quaternion_wxyz``, ``rpy`` [rad] (Rz Ry Rx)."""
    return {
        "position": [float(x) for x in base_T_flange[:3, 3]],
        "quaternion_wxyz": [float(x) for x in tf.quat_wxyz(base_T_flange[:3, :3])],
        "rpy": [float(x) for x in tf.rpy(base_T_flange[:3, :3])],
    }


def pose_error(base_T_a: Array, base_T_b: Array) -> tuple[float, float]:
    """Position error [m] and geodesic orientation error [rad] between two poses.

    The angle is atan2(|axis part|, cos part) of R_a^T R_b, accurate near 0
    (acos of the trace would bottom out at about 2e-8 rad).
    """
    dp = float(np.linalg.norm(base_T_a[:3, 3] - base_T_b[:3, 3]))
    r = base_T_a[:3, :3].T @ base_T_b[:3, :3]
    axis = (r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1])
    angle = math.atan2(0.5 * math.hypot(*axis), 0.5 * (r[0, 0] + r[1, 1] + r[2, 2] - 1.0))
    return dp, angle


def verify_solution(spec: RobotSpec, q: ArrayLike, base_T_flange: Array) -> tuple[float, float]:
    """FK of ``q`` against the target: (position error [m], orientation error [rad]).

    The orientation error is reported for every robot; judge it with
    :func:`meets_tolerance` (a position-only robot is not held to it).
    """
    return pose_error(flange_pose(spec, q), base_T_flange)


def seed_or_middle(spec: RobotSpec, seed_q: ArrayLike | None) -> Array:
    """The seed as a joint vector [rad]; the middle of the joint range when None."""
    if seed_q is None:
        out: Array = 0.5 * (spec.lower + spec.upper)
        return out
    arr = np.asarray(seed_q, dtype=float)
    if arr.ndim != 1:
        arr = arr.reshape(-1)
    if arr.shape[0] == len(spec.joints) and not np.all(np.isfinite(arr)):
        raise KinematicsError(f"the IK seed must be finite joint values [rad], got {arr.tolist()}")
    if arr.shape[0] != len(spec.joints):
        raise KinematicsError(
            f"robot '{spec.name}' has {spec.dof} joints; the IK seed has {arr.shape[0]} "
            f"values {arr.tolist()}"
        )
    return arr


@dataclass(frozen=True)
class IKOptions:
    """Solver settings (the closed form ignores them: it is exact up to rounding).

    Attributes:
        tol_m: position tolerance [m].
        tol_rad: orientation tolerance [rad].
        max_iterations: iterations per attempt (numeric).
        max_restarts: attempts after the seeded one (numeric).
        seed: seed of the restart draws; same seed, same answer (numeric).
        rest_q: rest posture [rad], one value per joint within the limits, that a
            redundant arm's spare joints are pulled toward once the target is
            reached (numeric); None: the middle of each joint's range.
        null_space_iterations: iterations that pull may spend, its landing steps
            included (numeric; 0 turns it off). Ignored for arms without spare joints
            (6 joints for a pose, 3 for a position).
    """

    tol_m: float = DEFAULT_TOL_M
    tol_rad: float = DEFAULT_TOL_RAD
    max_iterations: int = 60
    max_restarts: int = 40
    seed: int = 0
    rest_q: tuple[float, ...] | None = None
    null_space_iterations: int = 30

    def __post_init__(self) -> None:
        if not (self.tol_m > 0 and self.tol_rad > 0):
            raise KinematicsError(
                f"IK tolerances must be > 0, got tol_m={self.tol_m}, tol_rad={self.tol_rad}"
            )
        if self.max_iterations < 1 or self.max_restarts < 0:
            raise KinematicsError(
                f"IK needs max_iterations >= 1 and max_restarts >= 0, got "
                f"{self.max_iterations} and {self.max_restarts}"
            )
        if self.null_space_iterations < 0:
            raise KinematicsError(
                f"IK needs null_space_iterations >= 0, got {self.null_space_iterations}"
            )
        if self.rest_q is not None and not all(math.isfinite(v) for v in self.rest_q):
            raise KinematicsError(
                f"the IK rest posture must be finite joint values [rad], got {list(self.rest_q)}"
            )


@dataclass(frozen=True, eq=False)
class IKResult:
    """What a solver found for one target.

    Attributes:
        solutions: (k, dof) joint vectors [rad], within limits, nearest to the seed
            first; k = 0 when the target was not reached.
        reason: why there is no solution ("" when solved).
        iterations: iterations spent (numeric; 0 for closed form).
        restarts: attempts after the seeded one (numeric).
    """

    solutions: Array
    reason: str = ""
    iterations: int = 0
    restarts: int = 0

    @property
    def ok(self) -> bool:
        return bool(self.solutions.shape[0] > 0)

    def best(self) -> Array:
        """The first (nearest-to-seed) solution; raises KinematicsError with the reason."""
        if not self.ok:
            raise KinematicsError(self.reason or "IK found no solution")
        out: Array = self.solutions[0]
        return out


class IKSolver(Protocol):
    """One IK solver for one robot. Build it with :func:`pipeline.kinematics.make_solver`."""

    @property
    def name(self) -> str: ...

    @property
    def spec(self) -> RobotSpec: ...

    def solve(self, base_T_flange: ArrayLike, *, seed_q: ArrayLike | None = None) -> IKResult:
        """Joint vectors reaching ``base_T_flange`` (4x4, flange in the base frame [m]).

        ``seed_q`` [rad] picks the solution (numeric: the start; analytic: the 2 pi
        representative and the ordering); default: middle of the joint range.
        Never raises for an unreachable target: the result is empty with a reason.
        """
        ...


def format_reason(spec: RobotSpec, base_T_flange: Array, what: str) -> str:
    """One-line 'unreachable' message naming the robot and the target."""
    p = base_T_flange[:3, 3]
    roll, pitch, yaw = tf.rpy(base_T_flange[:3, :3])
    fmt = ".4f" if float(np.abs(p).max()) < 1e6 else ".4g"  # 1e308 m is not 309 digits
    if position_only(spec):
        return (
            f"robot '{spec.name}' cannot reach position "
            f"[{p[0]:{fmt}}, {p[1]:{fmt}}, {p[2]:{fmt}}] m (position-only IK, "
            f"{spec.dof} joint{'s' * (spec.dof != 1)}): {what}"
        )
    return (
        f"robot '{spec.name}' cannot reach position "
        f"[{p[0]:{fmt}}, {p[1]:{fmt}}, {p[2]:{fmt}}] m, "
        f"rpy [{roll:.4f}, {pitch:.4f}, {yaw:.4f}] rad: {what}"
    )


__all__ = [
    "DEFAULT_TOL_M",
    "DEFAULT_TOL_RAD",
    "FULL_POSE_DOF",
    "IKOptions",
    "IKResult",
    "IKSolver",
    "as_pose",
    "format_reason",
    "meets_tolerance",
    "pose_error",
    "pose_rows",
    "pose_summary",
    "position_only",
    "seed_or_middle",
    "target_pose",
    "task_dim",
    "verify_solution",
]
