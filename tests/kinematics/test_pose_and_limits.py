"""Pose targets, pose errors, joint-limit helpers and the solver registry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline import transforms as tf
from pipeline.errors import KinematicsError
from pipeline.kinematics import (
    AnalyticURSolver,
    NumericLMSolver,
    check_joint_limits,
    make_solver,
    pose_error,
    solve_pose_nearest,
    target_pose,
    within_limits,
    wrap_to_limits,
)
from pipeline.model.dh import forward_kinematics
from pipeline.robots import load_spec


def test_rotation_forms_give_the_same_target():
    r = tf.rpy_to_matrix(0.3, -0.7, 2.0)
    a = target_pose([0.1, -0.2, 0.3], rotation=r)
    b = target_pose([0.1, -0.2, 0.3], quaternion_wxyz=2.5 * tf.quat_wxyz(r))  # not unit
    c = target_pose([0.1, -0.2, 0.3], rpy_rad=[0.3, -0.7, 2.0])
    assert np.abs(a - b).max() < 1e-12 and np.abs(a - c).max() < 1e-12
    assert a[:3, 3].tolist() == [0.1, -0.2, 0.3]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({}, "exactly one of"),
        ({"rpy_rad": [0, 0, 0], "quaternion_wxyz": [1, 0, 0, 0]}, "got quaternion, rpy"),
        ({"quaternion_wxyz": [0, 0, 0, 0]}, "must not be zero"),
        ({"rpy_rad": [0, 0]}, r"rpy .* needs 3 finite values"),
        ({"rotation": np.diag([1.0, 1.0, -1.0])}, "not a rotation matrix"),
        ({"rotation": np.diag([1.0, 2.0, 1.0])}, "not a rotation matrix"),
    ],
)
def test_bad_pose_targets_are_refused_in_one_line(kwargs, match):
    with pytest.raises(KinematicsError, match=match) as err:
        target_pose([0.1, 0.2, 0.3], **kwargs)
    assert "\n" not in str(err.value)


def test_solvers_refuse_a_matrix_that_is_not_a_pose(ur5):
    bad = np.eye(4)
    bad[:3, :3] *= 1.1
    for name in ("analytic", "numeric"):
        with pytest.raises(KinematicsError, match="not a rotation"):
            make_solver(name, ur5).solve(bad)


def test_pose_error_is_accurate_for_tiny_angles():
    a = np.eye(4)
    b = np.eye(4)
    b[:3, :3] = tf.rpy_to_matrix(0.0, 0.0, 1e-12)
    b[:3, 3] = (3e-9, 4e-9, 0.0)
    pos, ang = pose_error(a, b)
    assert pos == pytest.approx(5e-9, rel=1e-9)
    assert ang == pytest.approx(1e-12, rel=1e-6)  # acos of the trace would give 0 or 2e-8


def test_joint_limit_check_names_the_joint():
    spec = load_spec("mdh_example")
    q = np.zeros(6)
    assert within_limits(spec, q)
    q[2] = math.radians(175.0)
    assert not within_limits(spec, q)
    with pytest.raises(KinematicsError, match=r"joint_3 = 3\.05433 rad is outside"):
        check_joint_limits(spec, q)


def test_wrap_to_limits_picks_the_in_range_representative_nearest_the_seed():
    lower, upper = np.array([-2 * math.pi, -1.0]), np.array([2 * math.pi, 1.0])
    angles = np.array([[3.0, 0.5], [-3.0, 2 * math.pi + 0.5], [0.1, 2.0]])
    out, ok = wrap_to_limits(angles, lower, upper, np.array([5.0, 0.0]))
    assert ok.tolist() == [True, True, False]
    assert out[0].tolist() == pytest.approx([3.0, 0.5])
    assert out[1].tolist() == pytest.approx([-3.0 + 2 * math.pi, 0.5])


def test_unknown_solver_name_lists_the_valid_ones(ur5):
    with pytest.raises(
        KinematicsError,
        match=r"unknown IK solver 'analytc' \(did you mean 'analytic'\?\); "
        r"valid: analytic, numeric",
    ):
        make_solver("analytc", ur5)


def test_registry_builds_the_named_solver(ur5):
    assert isinstance(make_solver("analytic", ur5), AnalyticURSolver)
    assert isinstance(make_solver("numeric", ur5), NumericLMSolver)
    assert make_solver("numeric", ur5).name == "numeric"


@pytest.mark.parametrize("solver", ["analytic", "numeric"])
def test_solve_pose_nearest_returns_the_solution_nearest_near(ur5, solver):
    q = np.array([0.3, -1.2, 1.4, -0.8, 1.1, 0.5])
    t = forward_kinematics(ur5, q)
    got = solve_pose_nearest(
        ur5,
        position=t[:3, 3],
        quaternion_wxyz=tf.quat_wxyz(t[:3, :3]),
        solver=solver,
        near=q + 0.02,
    )
    assert np.abs(got - q).max() < 1e-5


def test_solve_pose_nearest_raises_for_unreachable(ur5):
    with pytest.raises(KinematicsError, match="cannot reach"):
        solve_pose_nearest(ur5, position=[3.0, 0, 0], rpy=[0, 0, 0], solver="analytic")
