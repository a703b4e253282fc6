"""Levenberg-Marquardt IK: round trips on every robot, agreement with the closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.errors import KinematicsError
from pipeline.kinematics import (
    IKOptions,
    make_solver,
    meets_tolerance,
    min_singular_value,
    pose_error,
    within_limits,
)
from pipeline.model.dh import forward_kinematics

from .helpers import wrapped_distance

N = 25


def test_every_answer_reproduces_the_target_within_tolerance(every_dof_robot):
    spec = every_dof_robot
    opts = IKOptions(tol_m=1e-6, tol_rad=1e-6)
    solver = make_solver("numeric", spec, options=opts)
    qs = np.random.default_rng(11).uniform(spec.lower, spec.upper, (N, spec.dof))
    solved = 0
    for q in qs:
        target = forward_kinematics(spec, q)
        result = solver.solve(target)
        if not result.ok:
            continue
        solved += 1
        (sol,) = result.solutions
        pos, ang = pose_error(forward_kinematics(spec, sol), target)
        # below 6 joints IK is position-only: the orientation is not asked for
        assert meets_tolerance(spec, pos, ang, tol_m=opts.tol_m, tol_rad=opts.tol_rad)
        assert pos <= opts.tol_m and (spec.dof < 6 or ang <= opts.tol_rad)
        assert within_limits(spec, sol)
    assert solved == N


def test_answer_seeded_near_a_solution_is_among_the_analytic_ones(ur_robot):
    # tight pose tolerance, so the joint-space comparison is not limited by conditioning
    numeric = make_solver("numeric", ur_robot, options=IKOptions(tol_m=1e-11, tol_rad=1e-11))
    analytic = make_solver("analytic", ur_robot)
    rng = np.random.default_rng(12)
    checked = 0
    for q in rng.uniform(-math.pi, math.pi, (N, 6)):
        target = forward_kinematics(ur_robot, q)
        seed = q + rng.normal(0.0, 0.05, 6)
        num = numeric.solve(target, seed_q=seed).best()
        closed = analytic.solve(target, seed_q=seed).solutions
        assert wrapped_distance(closed, num).min() < 1e-7
        if min_singular_value(ur_robot, q) > 0.02:
            # well conditioned: LM stays in the basin it started in
            assert wrapped_distance(num, q) < 1e-7
            checked += 1
    assert checked > N // 2


def test_solution_near_the_wrist_singularity(ur5):
    q = np.array([0.4, -1.0, 1.2, -0.5, 1e-7, -2.0])
    target = forward_kinematics(ur5, q)
    sol = make_solver("numeric", ur5).solve(target).best()
    pos, ang = pose_error(forward_kinematics(ur5, sol), target)
    assert pos <= 1e-6 and ang <= 1e-6


def test_same_seed_same_answer_and_restarts_are_used(ur5):
    solver = make_solver("numeric", ur5, options=IKOptions(seed=3))
    again = make_solver("numeric", ur5, options=IKOptions(seed=3))
    qs = np.random.default_rng(13).uniform(ur5.lower, ur5.upper, (40, 6))
    restarted = 0
    for q in qs:
        target = forward_kinematics(ur5, q)
        a, b = solver.solve(target), again.solve(target)
        assert np.array_equal(a.solutions, b.solutions)
        assert a.iterations == b.iterations
        assert np.array_equal(solver.solve(target).solutions, a.solutions)  # no hidden state
        restarted += a.restarts > 0
    assert restarted > 0  # the seeded restarts were exercised


def test_joint_limits_are_respected_on_a_limited_arm():
    from pipeline.robots import load_spec

    spec = load_spec("mdh_example")  # +-170 deg
    solver = make_solver("numeric", spec)
    for q in np.random.default_rng(14).uniform(spec.lower, spec.upper, (N, 6)):
        result = solver.solve(forward_kinematics(spec, q))
        assert result.ok
        assert np.all(result.solutions >= spec.lower) and np.all(result.solutions <= spec.upper)


def test_unreachable_target_reports_the_closest_approach(ur5):
    # inside the links' end-to-end bound (1.19 m), outside what the arm reaches
    target = np.eye(4)
    target[:3, 3] = (1.1, 0.0, 0.3)
    solver = make_solver("numeric", ur5, options=IKOptions(max_restarts=2, max_iterations=20))
    result = solver.solve(target)
    assert not result.ok and result.restarts == 2
    with pytest.raises(KinematicsError, match=r"robot 'ur5' cannot reach .* after 3 attempts"):
        result.best()
    closest = float(result.reason.split("closest: ")[1].split(" m")[0])
    assert closest > 1.1 - 0.95  # the UR5 reaches about 0.95 m from the shoulder


def test_a_target_beyond_every_link_end_to_end_is_refused_without_descending(ur5):
    target = np.eye(4)
    target[:3, 3] = (2.0, 0.0, 0.3)
    result = make_solver("numeric", ur5).solve(target)
    assert not result.ok and result.iterations == 0
    assert "beyond the arm's reach of 1.193 m" in result.reason


def test_bad_seed_is_refused(ur5):
    with pytest.raises(KinematicsError, match="6 joints; the IK seed has 5 values"):
        make_solver("numeric", ur5).solve(np.eye(4), seed_q=np.zeros(5))
