"""IK solvers by name: a dict from name to factory, nothing more.

Adding a solver is one new module plus one line in :data:`SOLVERS`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import KinematicsError, unknown_name_message
from pipeline.kinematics.analytic import AnalyticURSolver
from pipeline.kinematics.base import IKOptions, IKSolver, target_pose, verify_solution
from pipeline.kinematics.numeric import NumericLMSolver
from pipeline.robots.spec import RobotSpec

SolverFactory = Callable[[RobotSpec, IKOptions], IKSolver]

SOLVERS: dict[str, SolverFactory] = {
    "analytic": AnalyticURSolver,
    "numeric": NumericLMSolver,
}
"""Registered IK solvers: ``analytic`` (closed form, UR-type arms), ``numeric`` (LM, any arm)."""


def solver_names() -> list[str]:
    """Names accepted by :func:`make_solver`."""
    return sorted(SOLVERS)


def make_solver(name: str, spec: RobotSpec, *, options: IKOptions | None = None) -> IKSolver:
    """Build the solver ``name`` for ``spec``.

    Raises:
        KinematicsError: unknown name (lists the valid ones), or a robot the solver
            cannot handle (e.g. analytic on a non-UR geometry).
    """
    factory = SOLVERS.get(name)
    if factory is None:
        raise KinematicsError(unknown_name_message("IK solver", name, solver_names()))
    return factory(spec, options or IKOptions())


def solve_pose_nearest(
    spec: RobotSpec,
    *,
    position: ArrayLike,
    quaternion_wxyz: ArrayLike | None = None,
    rpy: ArrayLike | None = None,
    solver: str = "numeric",
    near: ArrayLike | None = None,
    options: IKOptions | None = None,
) -> NDArray[np.float64]:
    """One joint vector [rad] for a flange pose, the solution nearest ``near``.

    Args:
        spec: the robot.
        position: flange position in the DH base frame [m].
        quaternion_wxyz: orientation as (w, x, y, z); give this or ``rpy``.
        rpy: orientation as roll, pitch, yaw [rad], R = Rz(yaw) Ry(pitch) Rx(roll).
        solver: registry name (``analytic`` returns the nearest of all solutions,
            ``numeric`` starts from ``near``).
        near: preferred joints [rad]; default: middle of the joint range.
        options: solver options (tolerances, iterations, seed).

    Raises:
        KinematicsError: unreachable pose, bad pose values, unknown solver or a robot
            the solver does not fit. The answer is verified by FK before it is returned.
    """
    opts = options or IKOptions()
    target = target_pose(position, quaternion_wxyz=quaternion_wxyz, rpy_rad=rpy)
    q = make_solver(solver, spec, options=opts).solve(target, seed_q=near).best()
    pos_err, ang_err = verify_solution(spec, q, target)
    if pos_err > opts.tol_m or ang_err > opts.tol_rad:
        raise KinematicsError(
            f"robot '{spec.name}': {solver} IK answer misses the target by {pos_err:.3g} m, "
            f"{ang_err:.3g} rad (tolerance {opts.tol_m:g} m, {opts.tol_rad:g} rad)"
        )
    return q
