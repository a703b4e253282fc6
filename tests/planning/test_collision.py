"""The MuJoCo collision checker against independent geometry (DH forward kinematics)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from pipeline.errors import PlanningError
from pipeline.model.dh import forward_kinematics, link_frames
from pipeline.model.mjcf import FLOOR_Z_M, build_mjcf
from pipeline.model.scene import Box
from pipeline.planning import (
    CollisionChecker,
    default_padding_m,
    motion_check_step_rad,
    reach_bound_m,
)
from pipeline.robots.chain import chain
from tests.planning.scenarios import PAPER_GOAL, blocking_box


def test_zero_pose_of_the_ur_arms_is_collision_free(ur5):
    checker = CollisionChecker(ur5)
    assert checker.is_valid(np.zeros(6))
    assert checker.contacts(np.zeros(6)) == []


def test_arm_folded_below_the_floor_collides_with_the_ground(ur5):
    q = np.array([0.0, np.pi / 2, 0.0, 0.0, 0.0, 0.0])  # upper arm straight down
    assert forward_kinematics(ur5, q)[2, 3] < FLOOR_Z_M - 0.2  # DH FK: flange under the floor
    checker = CollisionChecker(ur5)
    assert not checker.is_valid(q)
    pairs = checker.contacts(q)
    assert ("ground", "wrist_3_link") in pairs
    with pytest.raises(PlanningError, match=r"^goal is in collision \(.*ground touches wrist"):
        checker.check_state(q, "goal")


def test_box_around_the_flange_is_reported_by_name(ur5):
    flange = forward_kinematics(ur5, np.zeros(6))[:3, 3]
    box = Box("crate", tuple(float(x) for x in flange), (0.05, 0.05, 0.05))
    checker = CollisionChecker(ur5, obstacles=[box])
    assert ("crate", "wrist_3_link") in checker.contacts(np.zeros(6))
    assert CollisionChecker(ur5).is_valid(np.zeros(6))  # the box alone makes the difference


def test_out_of_limit_state_names_the_joint_and_the_limits(ur5):
    q = np.zeros(6)
    q[2] = 7.0
    with pytest.raises(PlanningError, match=r"^start: elbow_joint = 7 rad is outside .*6\.28"):
        CollisionChecker(ur5).check_state(q, "start")
    with pytest.raises(PlanningError, match=r"^goal: expected 6 joint positions"):
        CollisionChecker(ur5).check_state(np.zeros(5), "goal")


def _box_below_wrist_3(spec, gap_m):
    """A small box whose top is ``gap_m`` under the wrist_3 capsule at q = 0 (DH FK)."""
    frames = link_frames(spec, np.zeros(6))
    a, b = frames[4][:3, 3], frames[5][:3, 3]  # wrist_3 capsule axis: frame 5 -> flange
    assert abs(a[2] - b[2]) < 1e-12  # horizontal at q = 0
    radius = spec.joints[5].collision_radius
    half = 0.01
    centre = (0.75 * b + 0.25 * a) - np.array([0.0, 0.0, radius + gap_m + half])
    return Box("shelf", tuple(float(x) for x in centre), (half, half, half))


def test_padding_detects_near_misses_at_the_geometric_distance(ur5):
    gap = 0.010
    checker = CollisionChecker(ur5, obstacles=[_box_below_wrist_3(ur5, gap)])
    q = np.zeros(6)
    assert checker.is_valid(q)
    checker.padding_m = 0.03
    dist, pair = checker.clearance_m(q)
    assert pair == ("shelf", "wrist_3_link")
    assert dist == pytest.approx(gap, abs=1e-9)
    # the padding is a pair distance (MuJoCo 4 sums the two geoms' margins)
    checker.padding_m = gap * 1.05
    assert not checker.is_clear(q)
    assert checker.is_valid(q)  # padding never turns a near miss into a collision
    checker.padding_m = gap * 0.95
    assert checker.is_clear(q)


def test_planning_padding_shrinks_to_half_the_clearance_of_start_and_goal(ur5):
    gap = 0.010
    checker = CollisionChecker(ur5, obstacles=[_box_below_wrist_3(ur5, gap)])
    far = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    padding = checker.planning_padding_m(far, np.zeros(6))
    assert padding == pytest.approx(gap / 2, abs=1e-9)
    assert padding < default_padding_m(ur5)
    touching = CollisionChecker(ur5, obstacles=[_box_below_wrist_3(ur5, 0.001)])
    with pytest.raises(PlanningError, match=r"^goal: shelf is 1\.00 mm from wrist_3_link"):
        touching.planning_padding_m(far, np.zeros(6))


def test_reach_bound_covers_every_point_displacement(any_robot):
    """Displacements of DH frame origins and MuJoCo geom centres never exceed the bound."""
    model = CollisionChecker(any_robot).model
    data = mujoco.MjData(model)
    bound = reach_bound_m(any_robot)
    rng = np.random.default_rng(3)

    def points(q):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        origins = [t[:3, 3] for t in link_frames(any_robot, q)]
        return np.concatenate([np.array(origins), data.geom_xpos.copy()])

    worst = 0.0
    for _ in range(200):
        q = rng.uniform(any_robot.lower, any_robot.upper)
        dq = rng.normal(size=any_robot.dof)
        dq *= rng.uniform(1e-3, 0.5) / np.linalg.norm(dq)
        moved = np.linalg.norm(points(q + dq) - points(q), axis=1).max()
        worst = max(worst, moved / np.linalg.norm(dq))
    assert worst <= bound
    assert worst > 0.3 * bound  # and the bound is not absurdly loose


def test_motion_check_step_moves_points_by_at_most_the_padding(ur5):
    padding = default_padding_m(ur5)
    step = motion_check_step_rad(ur5, padding)
    assert step * reach_bound_m(ur5) == pytest.approx(padding)
    assert 1e-3 < step < 0.05  # sane for a UR5: fine but not absurd


def _shelf_under_the_elbow(spec, gap_m):
    """A wide shelf whose top is ``gap_m`` under the elbow capsule at q = 0 (DH FK): the
    capsule lies along the shelf's face, where MuJoCo's capsule–box collider misses
    pairs within the margin (google-deepmind/mujoco#1473)."""
    frame = link_frames(spec, np.zeros(6))[2]
    (seg,) = chain(spec)[2].segments
    a, b = ((frame @ np.append(p, 1.0))[:3] for p in (seg.start, seg.end))
    assert a[2] == pytest.approx(b[2])  # horizontal at q = 0
    top = a[2] - seg.radius - gap_m
    return Box("shelf", (-0.6, 0.0, top - 0.05), (0.12, 0.1, 0.05))


def test_padding_sees_a_box_along_a_capsule_that_mujocos_box_collider_misses(ur5):
    q = np.zeros(6)
    checker = CollisionChecker(ur5, obstacles=[_shelf_under_the_elbow(ur5, 0.005)], padding_m=0.01)
    # MuJoCo's own box pair reports nothing within the 10 mm margin here ...
    plain = mujoco.MjModel.from_xml_string(
        build_mjcf(ur5, obstacles=[_shelf_under_the_elbow(ur5, 0.005)])
    )
    plain.geom_margin[:] = 0.005
    data = mujoco.MjData(plain)
    mujoco.mj_forward(plain, data)
    shelf = plain.geom("shelf").id
    assert not any(shelf in (c.geom1, c.geom2) for c in data.contact[: data.ncon])
    # ... the checker does, at the geometric gap
    assert not checker.is_clear(q)
    dist, pair = checker.clearance_m(q)
    assert pair == ("elbow_link", "shelf")
    assert dist == pytest.approx(0.005, abs=1e-9)
    assert checker.is_valid(q) and checker.contacts(q) == []  # near, not touching
    # and a planned motion must keep the padding there too
    lifted = q.copy()
    lifted[1] = -0.3  # shoulder lift raises the elbow well clear of the shelf
    assert checker.is_clear(lifted)
    assert not checker.motion_clear(lifted, q, step_rad=0.01)
    assert checker.first_invalid(np.stack([lifted, q]), step_rad=0.01) is not None
    checker.padding_m = 0.004
    assert checker.is_clear(q)
    assert checker.motion_clear(lifted, q, step_rad=0.01 * 0.4)


def test_motion_check_probes_then_checks_every_state_like_the_state_check(ur5):
    from pipeline.planning.collision import _coarse_prefix, coarse_to_fine

    for n in (2, 3, 7, 64, 301, 1000):
        for count in (1, 6, 40):
            prefix = _coarse_prefix(n, count)
            assert list(prefix) == coarse_to_fine(n).tolist()[: min(count, n)]
    box = blocking_box(ur5)
    checker = CollisionChecker(ur5, obstacles=[box], padding_m=0.0056)
    rng = np.random.default_rng(12)
    outcomes = set()
    for _ in range(40):
        qa = PAPER_GOAL * rng.uniform(0.0, 1.0) + rng.normal(scale=0.1, size=6)
        qb = PAPER_GOAL * rng.uniform(0.0, 1.0) + rng.normal(scale=0.1, size=6)
        step = 0.003
        n = int(np.ceil(np.sqrt(float(np.dot(qb - qa, qb - qa))) / step))
        want = all(checker.is_clear(qa + (k / n) * (qb - qa)) for k in range(1, n + 1))
        assert checker.motion_clear(qa, qb, step_rad=step) == want
        outcomes.add(want)
    assert outcomes == {True, False}
