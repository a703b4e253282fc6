"""IK solvers by name: a dict from name to factory, then plug-ins.

Adding a solver is one new module plus one line in :data:`SOLVERS`. A name that is
not built in resolves to an installed entry point in the group ``armlab.ik_solvers``,
else to ``package.module:Object`` (see :mod:`pipeline.plugins`); either points at a
factory ``factory(spec, options) -> IKSolver`` (e.g. the solver class).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import KinematicsError
from pipeline.kinematics.analytic import AnalyticURSolver
from pipeline.kinematics.ik import (
    IKOptions,
    IKSolver,
    meets_tolerance,
    position_only,
    target_pose,
    verify_solution,
)
from pipeline.kinematics.numeric import NumericLMSolver
from pipeline.plugins import installed_names, resolve
from pipeline.robots.spec import RobotSpec

SolverFactory = Callable[[RobotSpec, IKOptions], IKSolver]

SOLVERS: dict[str, SolverFactory] = {
    "analytic": AnalyticURSolver,
    "numeric": NumericLMSolver,
}
"""Registered IK solvers: ``analytic`` (closed form, UR-type arms), ``numeric`` (LM, any
arm and joint count; position-only below 6 joints, a rest-posture pull above)."""


GROUP = "armlab.ik_solvers"
"""Entry-point group of installed IK solvers."""


def solver_names() -> list[str]:
    """Built-in solver names (plug-ins: :func:`installed_solvers`, or ``module:Object``)."""
    return sorted(SOLVERS)


def installed_solvers() -> tuple[str, ...]:
    """Names of the IK solvers installed as entry points (group ``armlab.ik_solvers``)."""
    return installed_names(GROUP)


def solver_factory(name: str) -> SolverFactory:
    """The factory of solver ``name``: built-in, entry point or ``module:Object``.

    Raises:
        KinematicsError: unknown name (lists built-in and installed names), a plug-in
            that fails to import or is not callable.
    """
    found = resolve(name, SOLVERS, group=GROUP, what="IK solver", error=KinematicsError)
    if not callable(found.obj):
        raise KinematicsError(
            f"IK solver '{name}' is not a solver factory: got {type(found.obj).__name__}"
        )
    factory: SolverFactory = found.obj
    return factory


def make_solver(name: str, spec: RobotSpec, *, options: IKOptions | None = None) -> IKSolver:
    """Build the solver ``name`` for ``spec``.

    Raises:
        KinematicsError: unknown name (lists the valid ones), or a robot the solver
            cannot handle (e.g. analytic on a non-UR geometry).
    """
    return solver_factory(name)(spec, options or IKOptions())


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
        position: flange position in the base frame [m].
        quaternion_wxyz: orientation as (w, x, y, z); give this or ``rpy``. A robot
            with fewer than 6 joints gets position-only IK: the orientation may be
            left out, and is ignored if given.
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
    if position_only(spec) and quaternion_wxyz is None and rpy is None:
        rpy = (0.0, 0.0, 0.0)  # not matched: any rotation makes the 4x4 target
    target = target_pose(position, quaternion_wxyz=quaternion_wxyz, rpy_rad=rpy)
    q = make_solver(solver, spec, options=opts).solve(target, seed_q=near).best()
    pos_err, ang_err = verify_solution(spec, q, target)
    if not meets_tolerance(spec, pos_err, ang_err, tol_m=opts.tol_m, tol_rad=opts.tol_rad):
        raise KinematicsError(
            f"robot '{spec.name}': {solver} IK answer misses the target by {pos_err:.3g} m, "
            f"{ang_err:.3g} rad (tolerance {opts.tol_m:g} m, {opts.tol_rad:g} rad)"
        )
    return q
