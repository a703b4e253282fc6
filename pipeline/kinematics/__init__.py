"""Inverse kinematics behind one interface; solvers chosen by name.

>>> from pipeline.kinematics import make_solver, target_pose
>>> from pipeline.robots import load_spec
>>> solver = make_solver("numeric", load_spec("ur5"))
>>> q = solver.solve(target_pose([0.4, 0.1, 0.3], rpy_rad=[3.14, 0, 0])).best()

Targets are ``base_T_flange`` 4x4 matrices (the flange frame ``tool0`` in the
base frame), as returned by :func:`flange_pose`. Any joint count: 6 or more
joints solve for the full pose (7 and more pull their spare joints toward a rest
posture), fewer solve for the flange position only (:func:`position_only`).
"""

from __future__ import annotations

from pipeline.kinematics.analytic import AnalyticURSolver, BatchSolutions, URGeometry, ur_geometry
from pipeline.kinematics.fk import flange_pose
from pipeline.kinematics.ik import (
    DEFAULT_TOL_M,
    DEFAULT_TOL_RAD,
    FULL_POSE_DOF,
    IKOptions,
    IKResult,
    IKSolver,
    as_pose,
    meets_tolerance,
    pose_error,
    pose_summary,
    position_only,
    target_pose,
    task_dim,
    verify_solution,
)
from pipeline.kinematics.jacobian import is_singular, jacobian, manipulability, min_singular_value
from pipeline.kinematics.limits import check_joint_limits, within_limits, wrap_to_limits
from pipeline.kinematics.numeric import NumericLMSolver
from pipeline.kinematics.solvers import SOLVERS, make_solver, solve_pose_nearest, solver_names

__all__ = [
    "DEFAULT_TOL_M",
    "DEFAULT_TOL_RAD",
    "FULL_POSE_DOF",
    "SOLVERS",
    "AnalyticURSolver",
    "BatchSolutions",
    "IKOptions",
    "IKResult",
    "IKSolver",
    "NumericLMSolver",
    "URGeometry",
    "as_pose",
    "check_joint_limits",
    "flange_pose",
    "is_singular",
    "jacobian",
    "make_solver",
    "manipulability",
    "meets_tolerance",
    "min_singular_value",
    "pose_error",
    "pose_summary",
    "position_only",
    "solve_pose_nearest",
    "solver_names",
    "target_pose",
    "task_dim",
    "ur_geometry",
    "verify_solution",
    "within_limits",
    "wrap_to_limits",
]
