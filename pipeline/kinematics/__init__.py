"""Inverse kinematics behind one interface; solvers chosen by name.

>>> from pipeline.kinematics import make_solver, target_pose
>>> from pipeline.robots import load_spec
>>> solver = make_solver("numeric", load_spec("ur5"))
>>> q = solver.solve(target_pose([0.4, 0.1, 0.3], rpy_rad=[3.14, 0, 0])).best()

Targets are ``base_T_flange`` 4x4 matrices (flange = DH frame n, in DH frame 0),
as returned by :func:`pipeline.model.dh.forward_kinematics`.
"""

from __future__ import annotations

from pipeline.kinematics.analytic import AnalyticURSolver, BatchSolutions, URGeometry, ur_geometry
from pipeline.kinematics.base import (
    DEFAULT_TOL_M,
    DEFAULT_TOL_RAD,
    IKOptions,
    IKResult,
    IKSolver,
    as_pose,
    pose_error,
    pose_summary,
    target_pose,
    verify_solution,
)
from pipeline.kinematics.jacobian import is_singular, jacobian, manipulability, min_singular_value
from pipeline.kinematics.limits import check_joint_limits, within_limits, wrap_to_limits
from pipeline.kinematics.numeric import NumericLMSolver
from pipeline.kinematics.registry import SOLVERS, make_solver, solve_pose_nearest, solver_names

__all__ = [
    "DEFAULT_TOL_M",
    "DEFAULT_TOL_RAD",
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
    "is_singular",
    "jacobian",
    "make_solver",
    "manipulability",
    "min_singular_value",
    "pose_error",
    "pose_summary",
    "solve_pose_nearest",
    "solver_names",
    "target_pose",
    "ur_geometry",
    "verify_solution",
    "within_limits",
    "wrap_to_limits",
]
