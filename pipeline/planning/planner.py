"""Joint-space motion planning with OMPL's RRTConnect, MuJoCo collision checking.

Seeding (OMPL 2.0.1, found by experiment and from its ``RandomNumbers.cpp``): OMPL
has one process-wide seed generator; every OMPL RNG (state samplers, the
nearest-neighbour structure, the path simplifier) takes its seed from it when it
is constructed. ``RNG.setSeed`` re-seeds that generator even after it has been
used (it then logs "Random number generation already started", meaning only
that RNGs which already exist keep their streams). ``plan_path`` therefore
re-seeds right before it builds fresh OMPL objects, so a plan is a function of
its inputs and seed alone, whatever was planned before in the process (tested
in-process and against a fresh subprocess). The re-seeding message is
suppressed; other OMPL warnings and errors still print.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from pipeline.constants import MAX_SEED
from pipeline.errors import PlanningError
from pipeline.model.scene import Box
from pipeline.planning.batch import BatchChecker
from pipeline.planning.collision import CollisionChecker, motion_check_step_rad
from pipeline.planning.shortcut import rope_shortcut
from pipeline.robots.spec import RobotSpec

F64 = NDArray[np.float64]

PLANNER_NAME = "RRTConnect"
_RRT_RANGE_RAD = 0.5
"""RRTConnect's longest extension [rad]. OMPL's default, a fifth of the space's extent
(6.2 rad for six joints of +-2 pi), makes long motions that mostly fail along the box;
0.5 rad checks fewer configurations per plan and gives shorter detours (issue 21)."""
_ROPE_DELTAS = (0.2, 0.1)  # rope shortcutting passes (see _shorten)
_ROPE_TOLERANCE = 0.1  # OMPL's default equivalence tolerance
RECIPES = ("rope", "ompl_rope", "legacy")
"""``plan_path(recipe=...)``: the default first, then two kept for benchmarks."""


def quiet_ompl() -> None:
    """Lower OMPL's log level to warnings (no INFO lines per solve/simplify)."""
    ou.setLogLevel(ou.LogLevel.LOG_WARN)


def seed_ompl(seed: int) -> None:
    """Seed OMPL's process-wide seed generator (``plan_path`` calls this itself).

    Args:
        seed: 0 <= seed <= 2**32 - 2; OMPL gets ``seed + 1`` (it rejects 0).

    Raises:
        PlanningError: seed out of range.
    """
    if (
        isinstance(seed, bool)
        or not isinstance(seed, int | np.integer)
        or not (0 <= int(seed) <= MAX_SEED)
    ):
        raise PlanningError(f"seed: expected an integer in [0, {MAX_SEED}], got {seed!r}")
    # Re-seeding after first use logs an OMPL error that does not apply to us (we
    # build every OMPL object after seeding): silence just that call.
    ou.setLogLevel(ou.LogLevel.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed) + 1)
    finally:
        quiet_ompl()


@dataclass(frozen=True, eq=False)
class PlannedPath:
    """A collision-free piecewise-linear joint path from start to goal.

    Attributes:
        joint_names: joint order of ``waypoints``.
        waypoints: (K, n) joint positions [rad], K >= 2, first = start, last = goal.
        planner: "RRTConnect".
        seed: the seed the plan was made with.
        planning_time_s: wall-clock time of solve + simplification [s] (not
            reproducible: keep it out of byte-compared outputs).
        time_limit_s: the solve time limit [s].
        path_length_rad: Euclidean joint-space length of ``waypoints`` [rad].
        n_states_before_simplify: states in RRTConnect's raw path (2 when direct).
        direct: the straight segment start -> goal was valid, so it is the path
            (what RRTConnect's first connection returns; no sampling needed).
        simplified: the path went through OMPL's simplifier.
        padding_m: clearance every checked state keeps [m] (see
            ``CollisionChecker.planning_padding_m``).
        check_step_rad: joint-space step between collision checks [rad]; with the
            padding it makes the continuous path collision-free.
        obstacles: the boxes planned around.
    """

    joint_names: tuple[str, ...]
    waypoints: F64
    planner: str
    seed: int
    planning_time_s: float
    time_limit_s: float
    path_length_rad: float
    n_states_before_simplify: int
    direct: bool
    simplified: bool
    padding_m: float
    check_step_rad: float
    obstacles: tuple[Box, ...] = field(default=())

    @property
    def start(self) -> F64:
        start: F64 = self.waypoints[0]
        return start

    @property
    def goal(self) -> F64:
        goal: F64 = self.waypoints[-1]
        return goal


def path_length_rad(waypoints: F64) -> float:
    """Euclidean joint-space length of a piecewise-linear path [rad]."""
    return float(np.sum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1)))


def _states_to_array(path: og.PathGeometric, dof: int) -> F64:
    return np.array(
        [
            [st[i] for i in range(dof)]
            for st in (path.getState(k) for k in range(path.getStateCount()))
        ],
        dtype=np.float64,
    )


def _shorten_rounds(ss: og.SimpleSetup, si: ob.SpaceInformation) -> og.PathGeometric:
    """The recipe before issue 21, kept for benchmarks (``recipe="legacy"``): OMPL's
    ``simplifySolution``, then three subdivide + partial shortcut + reduceVertices
    rounds (fixed counts), since ``simplifySolution`` leaves detours of radians."""
    ss.simplifySolution()
    path = og.PathGeometric(ss.getSolutionPath())
    simplifier = og.PathSimplifier(si)
    for _ in range(3):
        path.subdivide()
        simplifier.partialShortcutPath(path, 100, 20)
        simplifier.reduceVertices(path, 100, 20)
    return path


def _shorten_ompl_rope(path: og.PathGeometric, simplifier: og.PathSimplifier) -> None:
    """The recipe of issue 21's first round, kept for benchmarks (``recipe="ompl_rope"``):
    ``reduceVertices``, then OMPL's ``ropeShortcutPath`` with each of ``_ROPE_DELTAS``."""
    simplifier.reduceVertices(path)
    for delta in _ROPE_DELTAS:
        simplifier.ropeShortcutPath(path, delta, _ROPE_TOLERANCE)


def _shorten(waypoints: F64, validator: _MotionValidator) -> F64:
    """Shorten RRTConnect's path with few collision checks, deterministically.

    Two passes of rope shortcutting (``rope_shortcut``: it walks the path in steps of
    ``delta`` and pulls it taut), a coarse one and a fine one. Unlike OMPL's
    ``ropeShortcutPath`` it checks only the motions that would shorten the path, and
    OMPL's ``reduceVertices`` before it is left out (rope removes needless vertices
    anyway): about half the configurations of the recipe before (``"ompl_rope"``),
    for paths as short (docs/BENCHMARKS.md, "Planning").
    """
    for delta in _ROPE_DELTAS:
        waypoints = rope_shortcut(
            waypoints, delta=delta, tolerance=_ROPE_TOLERANCE, motion_clear=validator.clear
        )
    return waypoints


class _MotionValidator(ob.MotionValidator):  # type: ignore[misc]
    """OMPL's ``DiscreteMotionValidator`` semantics (states at most ``step_rad`` apart,
    checked coarse to fine) with one Python call per motion instead of one per state
    (``CollisionChecker.motion_clear``). Only the two-state form is used by
    RRTConnect and the path simplifier."""

    def __init__(
        self,
        si: ob.SpaceInformation,
        checker: CollisionChecker | BatchChecker,
        coords: Callable[[ob.State], F64],
        step_rad: float,
    ) -> None:
        super().__init__(si)
        self._checker = checker
        self._coords = coords
        self._step_rad = step_rad
        # the simplifier re-checks many motions (about a quarter of the states): a
        # motion's answer is a function of its two ends
        self._known: dict[bytes, bool] = {}

    def checkMotion(self, s1: ob.State, s2: ob.State, *last_valid: object) -> bool:
        if last_valid:
            raise PlanningError("checkMotion with a last valid state is not supported")
        return self.clear(self._coords(s1), self._coords(s2))

    def clear(self, qa: F64, qb: F64) -> bool:
        """Is the motion ``qa -> qb`` [rad] clear (``qa`` assumed valid)? Remembered."""
        key = qa.tobytes() + qb.tobytes()
        known = self._known.get(key)
        if known is None:
            known = self._known[key] = self._checker.motion_clear(qa, qb, step_rad=self._step_rad)
        return known


def plan_path(
    spec: RobotSpec,
    *,
    start: ArrayLike,
    goal: ArrayLike,
    obstacles: Sequence[Box] = (),
    time_limit_s: float = 5.0,
    seed: int,
    simplify: bool = True,
    batched: bool = False,
    recipe: str = "rope",
) -> PlannedPath:
    """Plan a collision-free joint path with RRTConnect within the joint limits.

    Args:
        spec: the robot.
        start, goal: joint positions [rad].
        obstacles: boxes in the base frame.
        time_limit_s: solve time limit [s].
        seed: OMPL seed (see ``seed_ompl``); same inputs + seed => same path.
        simplify: shorten the path (``reduceVertices`` and rope shortcutting, see
            ``_shorten``).
        batched: check each motion with ``BatchChecker`` (whole batches of states in
            numpy) rather than state by state in MuJoCo; same answers, so the same path.
        recipe: how to plan and shorten, one of ``RECIPES``: ``"rope"`` (the default,
            ``_shorten``); kept for comparison benchmarks, ``"ompl_rope"`` (OMPL's own
            rope shortcutting, ``_shorten_ompl_rope``: ~7x more configurations
            checked) and ``"legacy"`` (before issue 21: OMPL's default range and
            ``_shorten_rounds``, ~50x more).

    Raises:
        PlanningError: start/goal out of limits or in collision (names the joint or
            the contact pair), or no path found within the time limit.
    """
    if not (isinstance(time_limit_s, int | float) and math.isfinite(time_limit_s)) or (
        time_limit_s <= 0
    ):
        raise PlanningError(
            f"time_limit_s: expected a positive number of seconds, got {time_limit_s!r}"
        )
    if recipe not in RECIPES:
        raise PlanningError(f"recipe: expected one of {', '.join(RECIPES)}, got {recipe!r}")
    seed_ompl(seed)
    checker = CollisionChecker(spec, obstacles=obstacles)
    q_start = checker.check_state(start, "start")
    q_goal = checker.check_state(goal, "goal")
    checker.padding_m = checker.planning_padding_m(q_start, q_goal)
    step = motion_check_step_rad(spec, checker.padding_m)
    n = spec.dof
    t0 = time.perf_counter()

    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for i in range(n):
        bounds.setLow(i, float(spec.lower[i]))
        bounds.setHigh(i, float(spec.upper[i]))
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)

    def coords(state: ob.State) -> F64:
        # (the state space keeps samples and interpolations inside the joint limits)
        return np.array([state[i] for i in range(n)])

    def state_valid(state: ob.State) -> bool:
        return checker.is_clear(coords(state))

    ss.setStateValidityChecker(state_valid)
    si = ss.getSpaceInformation()
    si.setStateValidityCheckingResolution(step / space.getMaximumExtent())
    try:
        batch: BatchChecker | None = BatchChecker(checker)
    except PlanningError:
        batch = None  # a robot it does not cover (meshes): MuJoCo alone
    motions = batch if batched and batch is not None else checker
    validator = _MotionValidator(si, motions, coords, step)
    si.setMotionValidator(validator)
    rrt = og.RRTConnect(si)
    if recipe != "legacy":
        rrt.setRange(_RRT_RANGE_RAD)
    ss.setPlanner(rrt)
    # SpaceInformation.allocState hands ownership to Python (freed with the
    # wrapper); StateSpace.allocState would leak, and freeState would double-free.
    s_state, g_state = si.allocState(), si.allocState()
    for i in range(n):
        s_state[i] = float(q_start[i])
        g_state[i] = float(q_goal[i])
    ss.setStartAndGoalStates(s_state, g_state)
    ss.setup()

    if si.checkMotion(s_state, g_state):
        waypoints = np.stack([q_start, q_goal])
        n_raw, direct, simplified = 2, True, False
    else:
        status = ss.solve(float(time_limit_s))
        if status.getStatus() != ob.PlannerStatus.PlannerStatusType.EXACT_SOLUTION:
            raise PlanningError(
                f"no collision-free path from start to goal within time_limit_s = "
                f"{time_limit_s:g} s ({PLANNER_NAME}, seed {seed}, OMPL status "
                f"'{status.asString()}'); expected an exact solution: raise the time "
                "limit or move the goal/obstacles"
            )
        n_raw = ss.getSolutionPath().getStateCount()
        direct, simplified = False, simplify
        path = og.PathGeometric(ss.getSolutionPath())
        if not simplify:
            waypoints = _states_to_array(path, n)
        elif recipe == "rope":
            waypoints = _shorten(_states_to_array(path, n), validator)
        elif recipe == "ompl_rope":
            _shorten_ompl_rope(path, og.PathSimplifier(si))
            waypoints = _states_to_array(path, n)
        else:
            waypoints = _states_to_array(_shorten_rounds(ss, si), n)
    elapsed = time.perf_counter() - t0

    # Endpoints exactly as given (OMPL copies them, but keep the bits identical),
    # then re-check the whole path independently of the motion validator (in numpy
    # where BatchChecker covers the robot: one batch, and a second implementation).
    waypoints[0], waypoints[-1] = q_start, q_goal
    recheck = batch if batch is not None else checker
    bad = recheck.first_invalid(waypoints, step_rad=step)
    if bad is not None:
        raise PlanningError(
            f"planned path fails the re-check at q = {np.round(bad, 4).tolist()} "
            f"(clearance {checker.clearance_m(bad)}); this is a bug, please report it"
        )
    return PlannedPath(
        joint_names=spec.joint_names,
        waypoints=waypoints,
        planner=PLANNER_NAME,
        seed=int(seed),
        planning_time_s=elapsed,
        time_limit_s=float(time_limit_s),
        path_length_rad=path_length_rad(waypoints),
        n_states_before_simplify=n_raw,
        direct=direct,
        simplified=simplified,
        padding_m=checker.padding_m,
        check_step_rad=step,
        obstacles=tuple(obstacles),
    )
