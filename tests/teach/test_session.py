"""TeachSession: the page's IK/FK logic without a browser, checked against DH FK."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.errors import KinematicsError
from pipeline.kinematics import make_solver
from pipeline.model.dh import forward_kinematics
from pipeline.robots import RobotSpec, load_spec
from pipeline.teach.session import (
    NEAR_SINGULAR_SIGMA,
    TeachSession,
    choose_solver,
    home_pose,
)


def _session(spec: RobotSpec, solver: str | None = None) -> TeachSession:
    ik, _ = choose_solver(spec, solver)
    return TeachSession(spec, ik)


def _fk_error(spec: RobotSpec, q: np.ndarray, target: np.ndarray) -> float:
    return float(np.abs(forward_kinematics(spec, q) - target).max())


def test_analytic_target_lists_every_solution_nearest_the_previous_pose_first(
    ur5: RobotSpec,
) -> None:
    session = _session(ur5, "analytic")
    before = session.state.q.copy()
    target = forward_kinematics(ur5, [0.4, -1.1, 1.3, -0.6, 0.9, -0.3])
    state = session.set_target(target)
    assert state.reachable and state.reason == ""
    # the same closed form asked directly finds the same number of solutions
    assert state.solutions.shape[0] == make_solver("analytic", ur5).solve(target).solutions.shape[0]
    assert state.solutions.shape[0] >= 2
    for q in state.solutions:
        assert _fk_error(ur5, q, target) < 1e-9
    dist = np.linalg.norm(state.solutions - before, axis=1)
    assert np.all(np.diff(dist) >= 0)  # nearest first
    np.testing.assert_array_equal(state.q, state.solutions[0])
    assert state.checks == {"position_error": True, "orientation_error": True, "solve_time": True}
    assert state.position_error_m < 1e-9 and state.orientation_error_rad < 1e-9


def test_selecting_another_solution_moves_the_arm_and_keeps_the_flange(ur5: RobotSpec) -> None:
    session = _session(ur5)
    target = forward_kinematics(ur5, [0.4, -1.1, 1.3, -0.6, 0.9, -0.3])
    first = session.set_target(target).q.copy()
    state = session.select_solution(2)
    assert state.selected == 2 and not np.allclose(state.q, first)
    assert _fk_error(ur5, state.q, target) < 1e-9
    with pytest.raises(KinematicsError, match="does not exist"):
        session.select_solution(99)


def test_numeric_is_seeded_from_the_current_pose_during_a_drag(ur5: RobotSpec) -> None:
    session = _session(ur5, "numeric")
    q_prev = session.state.q.copy()
    # a small drag: 5 mm along x from the current flange pose
    target = forward_kinematics(ur5, q_prev)
    target[0, 3] += 0.005
    state = session.set_target(target)
    assert state.reachable
    assert _fk_error(ur5, state.q, target) < 1e-5
    # seeded from the current pose, the answer stays on the same branch, close by
    assert float(np.abs(state.q - q_prev).max()) < 0.1


def test_unreachable_target_keeps_the_last_valid_pose_and_says_why(ur5: RobotSpec) -> None:
    session = _session(ur5)
    valid = session.set_target(forward_kinematics(ur5, [0.2, -1.0, 1.0, 0.0, 1.0, 0.0])).q.copy()
    far = np.eye(4)
    far[:3, 3] = [2.5, 0.0, 0.3]
    state = session.set_target(far)
    assert not state.reachable
    np.testing.assert_array_equal(state.q, valid)
    assert "cannot reach" in state.reason and "ur5" in state.reason
    assert math.isnan(state.position_error_m) and state.checks == {}
    np.testing.assert_array_equal(state.target, far)


def test_numeric_unreachable_target_also_keeps_the_pose(any_robot: RobotSpec) -> None:
    session = _session(any_robot, "numeric")
    q0 = session.state.q.copy()
    far = np.eye(4)
    far[:3, 3] = [5.0, 5.0, 5.0]
    state = session.set_target(far)
    assert not state.reachable and "cannot reach" in state.reason
    np.testing.assert_array_equal(state.q, q0)


def test_joint_sliders_move_the_target_to_the_flange(any_robot: RobotSpec) -> None:
    session = _session(any_robot)
    q = 0.5 * (any_robot.lower + any_robot.upper) + 0.3
    state = session.set_joints(q)
    np.testing.assert_allclose(state.target, forward_kinematics(any_robot, q), atol=1e-15)
    assert state.source == "fk" and "solve_time" not in state.checks
    with pytest.raises(KinematicsError, match="outside its limits"):
        session.set_joints(any_robot.upper + 0.1)


def test_robot_without_closed_form_uses_numeric_and_says_why() -> None:
    spec = load_spec("mdh_example")
    solver, note = choose_solver(spec, None)
    assert solver.name == "numeric"
    assert "modified" in note and "numeric" in note
    solver, note = choose_solver(load_spec("ur5"), None)
    assert solver.name == "analytic" and note == ""
    with pytest.raises(KinematicsError, match="valid: analytic, numeric"):
        choose_solver(spec, "anlytic")


def test_every_robot_solves_a_target_from_its_own_fk(any_robot: RobotSpec) -> None:
    session = _session(any_robot)
    rng = np.random.default_rng(3)
    q = np.clip(home_pose(any_robot) + rng.uniform(-0.3, 0.3, any_robot.dof),
                any_robot.lower, any_robot.upper)  # fmt: skip
    target = forward_kinematics(any_robot, q)
    state = session.set_target(target)
    assert state.reachable, state.reason
    assert _fk_error(any_robot, state.q, target) < 1e-5
    assert all(state.checks.values())


def _fd_jacobian(spec: RobotSpec, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Geometric Jacobian by central differences of DH FK (independent of Pinocchio)."""
    cols = []
    for i in range(spec.dof):
        dq = np.zeros(spec.dof)
        dq[i] = h
        a, b = forward_kinematics(spec, q + dq), forward_kinematics(spec, q - dq)
        v = (a[:3, 3] - b[:3, 3]) / (2 * h)
        w_hat = (a[:3, :3] - b[:3, :3]) / (2 * h) @ forward_kinematics(spec, q)[:3, :3].T
        cols.append(np.concatenate([v, [w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]]]))
    return np.column_stack(cols)


def test_manipulability_matches_a_finite_difference_jacobian_of_dh_fk(ur5: RobotSpec) -> None:
    session = _session(ur5)
    q = np.array([0.3, -1.2, 1.1, -0.4, 0.7, 0.2])
    state = session.set_joints(q)
    j = _fd_jacobian(ur5, q)
    assert state.manipulability == pytest.approx(math.sqrt(np.linalg.det(j @ j.T)), rel=1e-6)
    sigma = np.linalg.svd(j, compute_uv=False)
    assert state.min_singular_value == pytest.approx(sigma[-1], rel=1e-6)


def test_straight_wrist_is_flagged_near_singular_and_home_is_not(ur5: RobotSpec) -> None:
    session = _session(ur5)
    straight = session.set_joints([0.3, -1.2, 1.1, -0.4, 0.0, 0.2])  # theta5 = 0
    assert straight.near_singular and straight.min_singular_value < NEAR_SINGULAR_SIGMA
    home = session.set_joints(home_pose(ur5))
    assert not home.near_singular


def test_joint_near_its_limit_is_flagged(ur5: RobotSpec) -> None:
    session = _session(ur5)
    q = home_pose(ur5)
    q[2] = ur5.upper[2] - 0.01
    state = session.set_joints(q)
    assert state.near_limit(ur5)[2] and not state.near_limit(ur5)[0]
    assert state.joint_fraction(ur5)[2] == pytest.approx(1 - 0.01 / (ur5.upper[2] - ur5.lower[2]))


def test_a_three_joint_robot_is_judged_on_position_only() -> None:
    """arm3's IK is position-only: a target whose orientation it cannot reach is solved,
    its orientation error shown but not judged (no FAIL); a 6-joint robot still is."""
    from pipeline import transforms as tf
    from pipeline.teach.server import readout_html

    spec = load_spec("arm3_example")
    session = _session(spec)
    target = forward_kinematics(spec, [0.3, 0.4, -0.6])
    target = target @ tf.rot_x(0.5)  # the flange turned about x: three joints cannot follow
    state = session.set_target(target)
    assert state.reachable and state.position_only
    assert state.orientation_error_rad > 0.1  # the error is real ...
    assert state.checks == {"position_error": True, "solve_time": state.checks["solve_time"]}
    rows = readout_html(state, solver=session.solver.name).split("<tr>")
    (orientation,) = [r for r in rows if "orientation error" in r]
    assert "not judged: position-only IK (3 joints)" in orientation
    assert "FAIL" not in orientation and "pass" not in orientation
    six = _session(load_spec("ur5")).set_joints([0.1, -1.0, 1.0, 0.2, 0.8, 0.0])
    assert not six.position_only and "orientation_error" in six.checks


def test_the_error_map_of_a_position_only_robot_ignores_orientation() -> None:
    from pipeline.teach.server import error_map_colours

    pos, ang = np.array([1e-9]), np.array([1.0])  # 1 rad: far past the orientation target
    assert tuple(error_map_colours(pos, ang, position_only=True)[0]) != tuple(
        error_map_colours(pos, ang)[0]
    )
    assert tuple(error_map_colours(pos, ang)[0]) == (218, 54, 51)  # judged: red
