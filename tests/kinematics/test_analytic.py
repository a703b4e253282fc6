"""Closed-form UR IK, checked against DH forward kinematics (an independent implementation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.errors import KinematicsError
from pipeline.kinematics import AnalyticURSolver, make_solver, pose_error
from pipeline.model.dh import forward_kinematics
from pipeline.robots import load_spec

from .helpers import with_dh, with_limits, wrapped_distance

N = 60
TOL = 1e-9  # closed form: only rounding error


def _random_q(spec, n, seed):
    return np.random.default_rng(seed).uniform(spec.lower, spec.upper, (n, spec.dof))


def test_every_solution_reproduces_the_target_and_the_generator_is_among_them(ur_robot):
    solver = make_solver("analytic", ur_robot)
    for q in _random_q(ur_robot, N, 1):
        target = forward_kinematics(ur_robot, q)
        result = solver.solve(target)
        assert result.ok
        for sol in result.solutions:
            pos, ang = pose_error(forward_kinematics(ur_robot, sol), target)
            assert pos < TOL and ang < TOL
        assert wrapped_distance(result.solutions, q).min() < 1e-7


def test_a_generic_pose_has_eight_distinct_solutions(ur_robot):
    q = np.array([0.3, -1.2, 1.4, -0.8, 1.1, 0.5])
    sols = make_solver("analytic", ur_robot).solve(forward_kinematics(ur_robot, q)).solutions
    assert sols.shape == (8, 6)
    for i in range(8):
        others = np.delete(sols, i, axis=0)
        assert wrapped_distance(others, sols[i]).min() > 1e-3


def test_solutions_are_the_in_range_representatives_nearest_the_seed(ur5):
    solver = AnalyticURSolver(ur5)
    seed = np.array([1.0, -2.0, 0.5, 3.0, -1.0, 2.5])
    for q in _random_q(ur5, 20, 2):
        sols = solver.solve(forward_kinematics(ur5, q), seed_q=seed).solutions
        assert np.all(sols >= ur5.lower) and np.all(sols <= ur5.upper)
        assert np.abs(sols - seed).max() <= math.pi + 1e-9
        dist = np.linalg.norm(sols - seed, axis=1)
        assert np.all(np.diff(dist) >= 0)  # nearest first


@pytest.mark.parametrize(
    "seed",
    [[5.5, -5.5, 4.0, 0.0, -3.5, 6.2], [-6.2, 6.2, -4.5, 3.3, 5.0, -5.0], [0.1] * 6],
)
def test_each_angle_is_the_in_range_representative_nearest_the_seed(ur5, seed):
    solver = AnalyticURSolver(ur5)
    seed = np.array(seed)
    for q in _random_q(ur5, 20, 6):
        sols = solver.solve(forward_kinematics(ur5, q), seed_q=seed).solutions
        assert sols.shape[0] > 0
        assert np.all(sols >= ur5.lower) and np.all(sols <= ur5.upper)
        for shift in (-2 * math.pi, 2 * math.pi):
            other = sols + shift
            in_range = (other >= ur5.lower) & (other <= ur5.upper)
            closer = np.abs(other - seed) < np.abs(sols - seed) - 1e-9
            assert not np.any(in_range & closer)


def test_narrow_joint_limits_drop_exactly_the_solutions_outside_them(ur5):
    full = AnalyticURSolver(ur5)
    lower = np.array([-1.0, -math.pi, -2.5, -math.pi, -2.0, -math.pi])
    upper = np.array([2.0, 0.5, 2.5, math.pi, 2.0, math.pi])
    narrow = AnalyticURSolver(with_limits(ur5, lower, upper))
    kept_some = dropped_some = False
    for q in _random_q(ur5, 40, 3):
        target = forward_kinematics(ur5, q)
        wide_sols = full.solve(target).solutions
        # which of the wide solutions have a 2 pi representative inside the narrow box
        k = np.round((0.5 * (lower + upper) - wide_sols) / (2 * math.pi))
        shifted = wide_sols + 2 * math.pi * k
        inside = np.all((shifted >= lower - 1e-9) & (shifted <= upper + 1e-9), axis=1)
        result = narrow.solve(target)
        assert result.solutions.shape[0] == int(inside.sum())
        assert np.all(result.solutions >= lower) and np.all(result.solutions <= upper)
        if result.ok:
            assert (
                wrapped_distance(result.solutions[:, None, :], shifted[inside]).min(1).max() < 1e-9
            )
        kept_some |= bool(inside.any())
        dropped_some |= bool((~inside).any())
    assert kept_some and dropped_some


@pytest.mark.parametrize("q5", [0.0, math.pi])
def test_wrist_singularity_fixes_theta6_to_the_seed(ur_robot, q5):
    q = np.array([0.4, -1.0, 1.2, -0.5, q5, -2.0])
    target = forward_kinematics(ur_robot, q)
    seed = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.7])
    solver = AnalyticURSolver(ur_robot)
    sols = solver.solve(target, seed_q=seed).solutions
    for sol in sols:
        pos, ang = pose_error(forward_kinematics(ur_robot, sol), target)
        assert pos < TOL and ang < TOL
    # the generating shoulder branch is singular: its two wrist branches coincide, so it
    # gives one solution per elbow, with theta5 exactly q5 and theta6 the seed's
    singular = wrapped_distance(sols[:, 4:5], np.array([q5])) < 1e-12
    assert int(singular.sum()) == 2
    assert np.all(sols[singular, 5] == 0.7)
    assert sols.shape[0] == 6  # the other shoulder branch is regular: 4 more
    batch = solver.solve_batch(target[None], seed_q=seed)
    assert int(batch.valid.sum()) == 6
    assert np.all(
        batch.q[0][batch.valid[0] & (np.abs(np.sin(batch.q[0][:, 4])) < 1e-12)][:, 5] == 0.7
    )


def test_unreachable_target_returns_nothing_and_says_why(ur5):
    target = np.eye(4)
    target[:3, 3] = (2.0, 0.0, 0.3)  # the UR5 reaches about 0.95 m
    result = AnalyticURSolver(ur5).solve(target)
    assert not result.ok
    with pytest.raises(KinematicsError, match=r"robot 'ur5' cannot reach .*elbow cannot reach"):
        result.best()
    batch = AnalyticURSolver(ur5).solve_batch(target[None])
    assert not batch.valid.any() and np.isnan(batch.q).all()


def test_target_inside_the_shoulder_offset_cylinder_is_unreachable(ur5):
    target = np.eye(4)
    target[:3, 3] = (0.0, 0.0, 0.5)
    target[:3, :3] = np.diag([1.0, -1.0, -1.0])  # tool down: wrist centre on the base axis
    result = AnalyticURSolver(ur5).solve(target)
    assert not result.ok and "shoulder offset" in result.reason


def test_modified_dh_robot_is_refused_naming_the_robot_and_the_mismatch():
    with pytest.raises(KinematicsError, match=r"robot 'mdh_example'.*convention is 'modified'"):
        make_solver("analytic", load_spec("mdh_example"))


def test_papers_printed_alpha5_sign_slip_is_refused(ur5):
    slipped = with_dh(ur5, 4, alpha=math.pi / 2)  # seeds/000 Table 1 prints +pi/2
    with pytest.raises(KinematicsError, match=r"alpha5 = 1\.5708 rad \(needs -1\.5708\)"):
        AnalyticURSolver(slipped)


def test_non_ur_link_lengths_are_refused(ur5):
    with pytest.raises(KinematicsError, match=r"a4 = 0\.05 m \(needs 0\)"):
        AnalyticURSolver(with_dh(ur5, 3, a=0.05))


def test_theta_offsets_and_split_shoulder_offsets_are_handled(ur5):
    spec = with_dh(ur5, 1, d=0.05, theta_offset=0.3)
    spec = with_dh(spec, 2, d=-0.02, theta_offset=-1.1)
    spec = with_dh(spec, 5, theta_offset=0.7)
    solver = AnalyticURSolver(spec)
    for q in _random_q(spec, 30, 4):
        target = forward_kinematics(spec, q)
        sols = solver.solve(target).solutions
        for sol in sols:
            pos, ang = pose_error(forward_kinematics(spec, sol), target)
            assert pos < TOL and ang < TOL
        assert wrapped_distance(sols, q).min() < 1e-7


def test_batched_call_matches_the_single_call(ur_robot):
    solver = AnalyticURSolver(ur_robot)
    qs = _random_q(ur_robot, 50, 5)
    targets = np.array([forward_kinematics(ur_robot, q) for q in qs])
    batch = solver.solve_batch(targets, seed_q=qs, chunk=16)  # several chunks
    assert batch.q.shape == (50, 8, 6) and batch.valid.shape == (50, 8)
    for i, (q, target) in enumerate(zip(qs, targets, strict=True)):
        single = solver.solve(target, seed_q=q).solutions
        mine = batch.q[i][batch.valid[i]]
        assert mine.shape == single.shape
        # same set (2 pi ties may round either way)
        assert wrapped_distance(mine[:, None, :], single[None]).min(axis=1).max() < 1e-9
        assert np.all(np.isnan(batch.q[i][~batch.valid[i]]))


def test_batch_rejects_bad_shapes(ur5):
    solver = AnalyticURSolver(ur5)
    with pytest.raises(KinematicsError, match=r"shape \(N, 4, 4\)"):
        solver.solve_batch(np.eye(4))
    with pytest.raises(KinematicsError, match="seeds"):
        solver.solve_batch(np.eye(4)[None], seed_q=np.zeros(5))
