"""The batched collision checker against MuJoCo's per-configuration answers and brute force."""

from __future__ import annotations

from itertools import pairwise

import mujoco
import numpy as np
import pytest

from pipeline.model.scene import Box
from pipeline.planning import CollisionChecker, plan_path
from pipeline.planning.batch import BatchChecker, segment_box_distance_m, segment_distance_m
from tests.planning.scenarios import PAPER_GOAL, START, blocking_box


def _brute_segment_distance(p1, q1, p2, q2, n=801):
    s = np.linspace(0.0, 1.0, n)
    a = p1 + np.outer(s, q1 - p1)
    b = p2 + np.outer(s, q2 - p2)
    return np.min(np.linalg.norm(a[:, None] - b[None], axis=-1))


def test_segment_distance_matches_brute_force_including_points_and_parallels():
    rng = np.random.default_rng(0)
    cases = [rng.normal(size=(4, 3)) for _ in range(60)]
    p = rng.normal(size=3)
    d = rng.normal(size=3)
    cases.append(
        np.stack([p, p + d, p + np.array([0.0, 0.0, 0.3]), p + d + np.array([0.0, 0.0, 0.3])])
    )  # parallel
    cases.append(np.stack([p, p, p + d, p + 2 * d]))  # a point and a segment
    cases.append(np.stack([p, p + d, p + 0.5 * d, p + 0.5 * d]))  # a point on the segment
    cases.append(np.stack([p, p, p + d, p + d]))  # two points
    got = segment_distance_m(*(np.stack([c[i] for c in cases]) for i in range(4)))
    want = np.array([_brute_segment_distance(*c) for c in cases])
    # brute force samples 801 points per segment: it overestimates by a little
    assert np.all(got <= want + 1e-12)
    np.testing.assert_allclose(got, want, atol=5e-3)


def test_segment_box_distance_matches_brute_force():
    rng = np.random.default_rng(1)
    half = np.array([0.03, 0.05, 0.02])
    p = rng.uniform(-0.2, 0.2, size=(200, 3))
    q = rng.uniform(-0.2, 0.2, size=(200, 3))
    q[:10] = p[:10]  # points
    got = segment_box_distance_m(p, q, np.broadcast_to(half, p.shape))
    s = np.linspace(0.0, 1.0, 4001)
    pts = p[:, None] + s[None, :, None] * (q - p)[:, None]
    want = np.linalg.norm(np.maximum(np.abs(pts) - half, 0.0), axis=-1).min(axis=1)
    assert np.all(got <= want + 1e-12)
    np.testing.assert_allclose(got, want, atol=2e-4)
    assert np.any(got == 0.0)  # some cross the box


def test_batched_kinematics_puts_the_geoms_where_mujoco_does(any_robot):
    checker = CollisionChecker(any_robot)
    batch = BatchChecker(checker)
    rng = np.random.default_rng(2)
    qs = rng.uniform(any_robot.lower, any_robot.upper, size=(20, any_robot.dof))
    a, b = (np.moveaxis(x, 0, -1) for x in batch.segments(qs))
    robot_geoms = [g for g in range(checker.model.ngeom) if checker.model.geom_bodyid[g] > 1]
    for q, ak, bk in zip(qs, a, b, strict=True):
        checker.data.qpos[:] = q
        mujoco.mj_kinematics(checker.model, checker.data)
        np.testing.assert_allclose(
            0.5 * (ak + bk), checker.data.geom_xpos[robot_geoms], rtol=0, atol=1e-12
        )


def _near_contact_configurations(spec, checker, n_per_segment=300):
    """States along a detour that runs at the padding distance from the box."""
    plan = plan_path(spec, start=START, goal=PAPER_GOAL, obstacles=checker.obstacles, seed=0)
    s = np.linspace(0.0, 1.0, n_per_segment)
    wp = plan.waypoints
    return np.concatenate([qa + np.outer(s, qb - qa) for qa, qb in pairwise(wp)]), plan


def test_batched_checks_agree_with_mujoco_on_random_and_near_contact_states(ur5):
    checker = CollisionChecker(ur5, obstacles=[blocking_box(ur5)])
    batch = BatchChecker(checker)
    rng = np.random.default_rng(3)
    far = rng.uniform(ur5.lower, ur5.upper, size=(400, 6)) * 0.5
    near, plan = _near_contact_configurations(ur5, checker)
    checker.padding_m = 0.03
    clearance = np.array([checker.clearance_m(q)[0] for q in near[::7]])
    for padding in (plan.padding_m, 1.01 * plan.padding_m, 0.01, 0.002, 0.0):
        checker.padding_m = padding
        for qs in (far, near):
            want = np.array([checker.is_clear(q) for q in qs])
            np.testing.assert_array_equal(batch.clear(qs), want)
        if padding == plan.padding_m:
            assert want.all()  # the detour is clear by the padding, ...
    assert clearance.min() < 2 * plan.padding_m  # ... within a few mm of the box
    # exactly at a pair's distance: MuJoCo decides, so the answers still agree
    checker.padding_m = float(clearance.min())
    q = near[::7][np.argmin(clearance)]
    assert batch.clear(q[None])[0] == checker.is_clear(q)


def test_batched_checks_agree_where_mujocos_box_collider_would_miss(ur5):
    """A shelf along the elbow capsule (google-deepmind/mujoco#1473): same answers."""
    from tests.planning.test_collision import _shelf_under_the_elbow

    checker = CollisionChecker(ur5, obstacles=[_shelf_under_the_elbow(ur5, 0.005)])
    batch = BatchChecker(checker)
    lifted = np.zeros(6)
    lifted[1] = -0.3
    qs = np.outer(np.linspace(0.0, 1.0, 200), -lifted) + lifted
    for padding in (0.004, 0.005 - 1e-9, 0.005 + 1e-9, 0.01):
        checker.padding_m = padding
        np.testing.assert_array_equal(batch.clear(qs), [checker.is_clear(q) for q in qs])


def test_batched_motion_check_agrees_on_random_segments(ur5):
    box = blocking_box(ur5)
    post = Box("post", (0.3, 0.3, 0.2), (0.05, 0.05, 0.3))
    checker = CollisionChecker(ur5, obstacles=[box, post])
    batch = BatchChecker(checker)
    near, plan = _near_contact_configurations(ur5, CollisionChecker(ur5, obstacles=[box]))
    rng = np.random.default_rng(4)
    outcomes = set()
    for padding in (plan.padding_m, 0.01):
        checker.padding_m = padding
        step = plan.check_step_rad * padding / plan.padding_m
        for _ in range(60):
            qa = near[rng.integers(len(near))] + rng.normal(size=6) * 0.03
            qb = near[rng.integers(len(near))] + rng.normal(size=6) * 0.03
            want = checker.motion_clear(qa, qb, step_rad=step)
            assert batch.motion_clear(qa, qb, step_rad=step) == want
            outcomes.add(want)
    assert outcomes == {True, False}


def test_batched_and_per_state_planning_give_the_same_path(ur5):
    box = blocking_box(ur5)
    for seed in (0, 1):
        per_state = plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=seed)
        batched = plan_path(
            ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=seed, batched=True
        )
        np.testing.assert_array_equal(per_state.waypoints, batched.waypoints)


@pytest.mark.parametrize("seed", [2, 3, 4, 5])
def test_batched_plans_never_collide_when_densely_rechecked(ur5, seed):
    box = blocking_box(ur5)
    plan = plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=seed)
    exact = CollisionChecker(ur5, obstacles=[box])
    step = plan.check_step_rad / 10
    for qa, qb in zip(plan.waypoints[:-1], plan.waypoints[1:], strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(qb - qa) / step)))
        for k in range(n + 1):
            assert exact.is_valid(qa + (qb - qa) * k / n)
