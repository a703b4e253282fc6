"""What the teach page computes, without a browser: IK on a target, FK on joints, goals.

:class:`TeachSession` holds the arm's current joints and answers two events,
a new flange target (the gizmo moved) and new joint values (a slider moved),
with a :class:`TeachState`: the pose shown, the IK solutions, the FK check of
the shown one against the kinematics notes' targets, manipulability and
warnings. An unreachable target leaves the joints where they were and says why.
The page (:mod:`pipeline.teach.server`) only draws these states.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import KinematicsError
from pipeline.kinematics.check import (
    ORIENTATION_TARGET_RAD,
    POSITION_TARGET_M,
    TIME_TARGET_MS,
)
from pipeline.kinematics.ik import IKSolver, as_pose, pose_error, position_only
from pipeline.kinematics.jacobian import manipulability, min_singular_value
from pipeline.kinematics.limits import check_joint_limits
from pipeline.kinematics.seeds import seed_table
from pipeline.kinematics.solvers import make_solver, solver_names
from pipeline.model.dh import forward_kinematics
from pipeline.robots.spec import RobotSpec

Array = NDArray[np.float64]

NEAR_SINGULAR_SIGMA = 0.02
"""Smallest Jacobian singular value below which the page warns of a singularity.

Looser than :data:`pipeline.kinematics.jacobian.SINGULAR_SIGMA` (1e-3, "singular"):
on the UR5 it is about 0.45 |sin theta5| near the wrist singularity, so 0.02
warns within about 2.5 degrees of it, while dragging, before joints race.
"""
NEAR_LIMIT_FRACTION = 0.05
"""A joint within this fraction of its range from a limit is flagged."""


@dataclass(frozen=True, eq=False)
class TeachState:
    """What the page shows after one event.

    Attributes:
        q: joints the arm is drawn at [rad] (the last valid pose if unreachable).
        target: the requested flange pose ``base_T_flange`` (4x4) [m].
        reachable: False if IK found no solution for ``target``.
        reason: why the target is unreachable, in words ("" when reachable).
        solutions: (k, dof) IK solutions [rad], nearest the previous pose first.
        selected: index of the shown solution in ``solutions`` (-1 when none).
        position_error_m: FK of ``q`` against ``target`` [m].
        orientation_error_rad: geodesic angle between FK of ``q`` and ``target`` [rad].
        solve_time_ms: IK solve time [ms] (0 for a joint-slider event).
        manipulability: Yoshikawa's sqrt(det(J J^T)) at ``q``.
        min_singular_value: smallest singular value of the flange Jacobian at ``q``.
        source: "ik" (target moved) or "fk" (joints moved).
        checks: each error against the notes' target (name -> passed); no
            ``orientation_error`` where IK is position-only.
        position_only: the robot's IK matches the flange position only (fewer than 6
            joints): the orientation error is shown, not judged.
    """

    q: Array
    target: Array
    reachable: bool
    reason: str
    solutions: Array
    selected: int
    position_error_m: float
    orientation_error_rad: float
    solve_time_ms: float
    manipulability: float
    min_singular_value: float
    source: str
    checks: dict[str, bool] = field(default_factory=dict)
    position_only: bool = False

    @property
    def near_singular(self) -> bool:
        return self.min_singular_value < NEAR_SINGULAR_SIGMA

    def joint_fraction(self, spec: RobotSpec) -> Array:
        """Each joint's place in its range, 0 at the lower limit and 1 at the upper."""
        out: Array = (self.q - spec.lower) / (spec.upper - spec.lower)
        return out

    def near_limit(self, spec: RobotSpec) -> list[bool]:
        """Per joint: within :data:`NEAR_LIMIT_FRACTION` of its range from a limit."""
        f = self.joint_fraction(spec)
        return [bool(x < NEAR_LIMIT_FRACTION or x > 1.0 - NEAR_LIMIT_FRACTION) for x in f]


def _checks(
    pos_m: float, ang_rad: float, time_ms: float, *, timed: bool, judge_orientation: bool
) -> dict[str, bool]:
    out = {"position_error": pos_m < POSITION_TARGET_M}
    if judge_orientation:
        out["orientation_error"] = ang_rad < ORIENTATION_TARGET_RAD
    if timed:
        out["solve_time"] = time_ms < TIME_TARGET_MS
    return out


def choose_solver(spec: RobotSpec, requested: str | None) -> tuple[IKSolver, str]:
    """The IK solver for the page, and a note when it is not the one asked for.

    ``analytic`` is preferred (every solution, exact); a robot whose geometry the
    closed form does not fit gets ``numeric`` and the note says why.

    Raises:
        KinematicsError: an unknown solver name (lists the valid ones).
    """
    name = requested or "analytic"
    if name not in solver_names():
        make_solver(name, spec)  # raises with the list of names
    try:
        solver, note = make_solver(name, spec), ""
    except KinematicsError as err:
        if name != "analytic":
            raise
        note = f"no closed form for this robot ({err}); using numeric (Levenberg-Marquardt)"
        solver = make_solver("numeric", spec)
    if name != "analytic" or note:
        seed_table(spec)  # built now (0.15-0.4 s), not on the first drag that needs a restart
    return solver, note


HOME_CANDIDATES = 64


def home_pose(spec: RobotSpec) -> Array:
    """Where the page starts: all zeros (clipped into the limits) unless that is near a
    singularity (it is for UR arms: the wrist is straight); then the most manipulable
    of :data:`HOME_CANDIDATES` seeded draws within 1 rad of it."""
    zero: Array = np.clip(np.zeros(spec.dof), spec.lower, spec.upper)
    if min_singular_value(spec, zero) >= NEAR_SINGULAR_SIGMA:
        return zero
    rng = np.random.default_rng(0)
    draws = np.clip(
        zero + rng.uniform(-1.0, 1.0, (HOME_CANDIDATES, spec.dof)), spec.lower, spec.upper
    )
    scores = [manipulability(spec, q) for q in draws]
    best: Array = draws[int(np.argmax(scores))]
    return best


class TeachSession:
    """The arm's state and the IK/FK answers to page events (no browser needed).

    Args:
        spec: the robot.
        solver: IK solver (see :func:`choose_solver`).
        q0: starting joints [rad]; default: :func:`home_pose`.
    """

    def __init__(self, spec: RobotSpec, solver: IKSolver, *, q0: ArrayLike | None = None) -> None:
        self.spec = spec
        self.solver = solver
        self._state = self.set_joints(home_pose(spec) if q0 is None else q0)

    @property
    def state(self) -> TeachState:
        return self._state

    def set_target(self, base_T_flange: ArrayLike) -> TeachState:
        """Solve IK for a new flange target, seeded by (and ordered nearest to) the current pose.

        Unreachable: the arm keeps its joints and the state says why.
        """
        target = as_pose(base_T_flange)
        prev = self._state.q
        t0 = time.perf_counter_ns()
        result = self.solver.solve(target, seed_q=prev)
        solve_ms = (time.perf_counter_ns() - t0) * 1e-6
        if not result.ok:
            self._state = self._make(
                prev, target, reachable=False, reason=result.reason,
                solutions=np.empty((0, self.spec.dof)), selected=-1, solve_ms=solve_ms,
                source="ik",
            )  # fmt: skip
            return self._state
        self._state = self._make(
            result.solutions[0], target, reachable=True, reason="",
            solutions=result.solutions, selected=0, solve_ms=solve_ms, source="ik",
        )  # fmt: skip
        return self._state

    def select_solution(self, index: int) -> TeachState:
        """Show another of the current target's IK solutions."""
        s = self._state
        if not 0 <= index < s.solutions.shape[0]:
            raise KinematicsError(
                f"solution {index + 1} does not exist: the target has {s.solutions.shape[0]}"
            )
        self._state = self._make(
            s.solutions[index], s.target, reachable=True, reason="", solutions=s.solutions,
            selected=index, solve_ms=s.solve_time_ms, source=s.source,
        )  # fmt: skip
        return self._state

    def set_joints(self, q: ArrayLike) -> TeachState:
        """Forward kinematics: the arm moves to ``q`` [rad] and the target follows the flange.

        Raises:
            KinematicsError: wrong number of joints or a joint outside its limits.
        """
        arr = np.asarray(q, dtype=float).reshape(-1)
        check_joint_limits(self.spec, arr)
        target = forward_kinematics(self.spec, arr)
        self._state = self._make(
            arr, target, reachable=True, reason="", solutions=arr[None, :], selected=0,
            solve_ms=0.0, source="fk",
        )  # fmt: skip
        return self._state

    def _make(
        self,
        q: Array,
        target: Array,
        *,
        reachable: bool,
        reason: str,
        solutions: Array,
        selected: int,
        solve_ms: float,
        source: str,
    ) -> TeachState:
        pos_m, ang_rad = pose_error(forward_kinematics(self.spec, q), target)
        if not reachable:
            pos_m = ang_rad = math.nan  # the arm is not at this target: no FK check
        return TeachState(
            q=np.array(q, dtype=float),
            target=target,
            reachable=reachable,
            reason=reason,
            solutions=solutions,
            selected=selected,
            position_error_m=pos_m,
            orientation_error_rad=ang_rad,
            solve_time_ms=solve_ms,
            manipulability=manipulability(self.spec, q),
            min_singular_value=min_singular_value(self.spec, q),
            source=source,
            checks=_checks(
                pos_m, ang_rad, solve_ms, timed=source == "ik",
                judge_orientation=not position_only(self.spec),
            ) if reachable else {},
            position_only=position_only(self.spec),
        )  # fmt: skip


__all__ = [
    "NEAR_LIMIT_FRACTION",
    "NEAR_SINGULAR_SIGMA",
    "TeachSession",
    "TeachState",
    "choose_solver",
    "home_pose",
]
