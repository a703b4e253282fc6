"""RRTConnect planning: collision-free paths, clear refusals, determinism per seed."""

from __future__ import annotations

import hashlib
import subprocess
import sys
import textwrap
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import PlanningError
from pipeline.model.dh import forward_kinematics
from pipeline.model.scene import Box
from pipeline.planning import CollisionChecker, plan_path, seed_ompl, time_parameterize
from tests.planning.scenarios import PAPER_GOAL, START, blocking_box


def _digest(waypoints: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(waypoints).tobytes()).hexdigest()


def _dense_invalid(checker: CollisionChecker, waypoints: np.ndarray, step_rad: float) -> int:
    """Count configurations in penetration along the polyline, checked every step_rad."""
    bad = 0
    for qa, qb in pairwise(waypoints):
        n = max(1, int(np.ceil(np.linalg.norm(qb - qa) / step_rad)))
        for k in range(n + 1):
            bad += not checker.is_valid(qa + (qb - qa) * k / n)
    return bad


def test_paper_scenario_is_the_direct_two_point_path(direct_plan):
    assert direct_plan.planner == "RRTConnect"
    assert direct_plan.direct
    np.testing.assert_array_equal(direct_plan.waypoints, np.stack([START, PAPER_GOAL]))
    assert direct_plan.path_length_rad == pytest.approx(np.linalg.norm(PAPER_GOAL))


def test_box_between_start_and_goal_forces_a_collision_free_detour(ur5, detour_plan):
    box = blocking_box(ur5)
    exact = CollisionChecker(ur5, obstacles=[box])
    # the box really blocks the straight segment, and RRTConnect went around it
    straight = np.stack([START, PAPER_GOAL])
    assert _dense_invalid(exact, straight, 0.01) > 0
    assert not detour_plan.direct
    assert len(detour_plan.waypoints) > 2
    assert detour_plan.path_length_rad > np.linalg.norm(PAPER_GOAL) + 1e-3
    np.testing.assert_array_equal(detour_plan.waypoints[0], START)
    np.testing.assert_array_equal(detour_plan.waypoints[-1], PAPER_GOAL)
    # re-checked 20x finer than the planner's resolution: no penetration anywhere
    assert _dense_invalid(exact, detour_plan.waypoints, detour_plan.check_step_rad / 20) == 0
    # and within the joint limits
    assert np.all(detour_plan.waypoints >= ur5.lower)
    assert np.all(detour_plan.waypoints <= ur5.upper)
    # simplification keeps the detour short (the straight line is 1.54 rad)
    assert detour_plan.path_length_rad < 2.0 * np.linalg.norm(PAPER_GOAL)
    assert detour_plan.n_states_before_simplify >= 2


def test_same_seed_gives_the_same_path_within_a_process(ur5, detour_plan):
    box = blocking_box(ur5)
    plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=11)
    again = plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=0)
    np.testing.assert_array_equal(again.waypoints, detour_plan.waypoints)


def test_different_seeds_explore_differently(ur5, detour_plan):
    box = blocking_box(ur5)
    digests = {_digest(detour_plan.waypoints)}
    for seed in (1, 2, 3):
        digests.add(
            _digest(
                plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=seed).waypoints
            )
        )
    assert len(digests) >= 2


_CHILD = textwrap.dedent(
    """
    import hashlib
    import numpy as np
    from pipeline.planning import plan_path, time_parameterize
    from pipeline.robots import load_spec
    from tests.planning.scenarios import PAPER_GOAL, START, blocking_box

    spec = load_spec("ur5")
    path = plan_path(spec, start=START, goal=PAPER_GOAL, obstacles=[blocking_box(spec)], seed=0)
    time_parameterize(spec, path)
    print(hashlib.sha256(np.ascontiguousarray(path.waypoints).tobytes()).hexdigest())
    """
)


def test_fresh_process_reproduces_the_path_quietly(detour_plan):
    """Same seed in a fresh process (OMPL never used before) = same path as here, where
    OMPL has already planned many times; and OMPL prints no INFO lines or leak noise."""
    out = subprocess.run(
        [sys.executable, "-c", _CHILD],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
        cwd=Path(__file__).resolve().parents[2],  # the repo root, so `tests` imports
    )
    assert out.stdout.strip() == _digest(detour_plan.waypoints)
    assert "Info" not in out.stderr + out.stdout
    assert "leak" not in out.stderr.lower()


def test_goal_in_the_floor_is_refused_naming_the_contact(ur5):
    goal = np.array([0.0, np.pi / 2, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(PlanningError, match=r"^goal is in collision \(.*ground touches"):
        plan_path(ur5, start=START, goal=goal, seed=0)


def test_goal_inside_a_box_is_refused_naming_box_and_link(ur5):
    flange = forward_kinematics(ur5, PAPER_GOAL)[:3, 3]
    box = Box("crate", tuple(float(x) for x in flange), (0.05, 0.05, 0.05))
    swung_away = np.array([1.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # the zero pose's wrist is near
    with pytest.raises(PlanningError, match=r"^goal is in collision \(crate touches wrist_"):
        plan_path(ur5, start=swung_away, goal=PAPER_GOAL, obstacles=[box], seed=0)


def test_start_in_collision_is_refused(ur5):
    start = np.array([0.0, np.pi / 2, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(PlanningError, match=r"^start is in collision"):
        plan_path(ur5, start=start, goal=PAPER_GOAL, seed=0)


def test_goal_outside_the_joint_limits_is_refused(ur5):
    goal = PAPER_GOAL.copy()
    goal[1] = -7.0
    with pytest.raises(PlanningError, match=r"^goal: shoulder_lift_joint = -7 rad is outside"):
        plan_path(ur5, start=START, goal=goal, seed=0)


def test_no_path_within_the_time_limit_is_refused(ur5):
    with pytest.raises(PlanningError, match=r"^no collision-free path .* time_limit_s = 1e-06 s"):
        plan_path(
            ur5,
            start=START,
            goal=PAPER_GOAL,
            obstacles=[blocking_box(ur5)],
            time_limit_s=1e-6,
            seed=0,
        )


@pytest.mark.parametrize("seed", [-1, 2**32, 1.5, True])
def test_bad_seed_is_refused(seed):
    with pytest.raises(PlanningError, match=r"^seed: expected an integer"):
        seed_ompl(seed)


@pytest.mark.parametrize("limit", [0.0, -1.0, float("nan")])
def test_bad_time_limit_is_refused(ur5, limit):
    with pytest.raises(PlanningError, match=r"^time_limit_s: expected a positive"):
        plan_path(ur5, start=START, goal=PAPER_GOAL, time_limit_s=limit, seed=0)


def test_unsimplified_path_is_also_collision_free(ur5):
    box = blocking_box(ur5)
    raw = plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=5, simplify=False)
    assert not raw.simplified
    assert len(raw.waypoints) == raw.n_states_before_simplify
    exact = CollisionChecker(ur5, obstacles=[box])
    assert _dense_invalid(exact, raw.waypoints, raw.check_step_rad / 5) == 0


def test_every_robot_plans_and_times_a_random_goal(any_robot):
    checker = CollisionChecker(any_robot)
    rng = np.random.default_rng(7)
    start = np.zeros(any_robot.dof)
    assert checker.is_valid(start), checker.contacts(start)
    goal = next(
        q
        for q in (rng.uniform(-1.0, 1.0, any_robot.dof) for _ in range(1000))
        if checker.is_valid(q) and checker.planning_padding_m(start, q) > 2e-3
    )
    path = plan_path(any_robot, start=start, goal=goal, seed=3, time_limit_s=2.0)
    assert _dense_invalid(checker, path.waypoints, path.check_step_rad / 10) == 0
    traj = time_parameterize(any_robot, path)
    v_ratio, a_ratio = traj.limit_ratios()
    assert v_ratio <= 1 + 1e-6 and a_ratio <= 1 + 1e-6
    np.testing.assert_array_equal(traj.sample(traj.duration_s)[0], goal)
