"""The page's server end to end over its websocket: a scripted client drags the target the
way the browser does and reads back the joints and arm pose the server sends."""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np
import pytest

from pipeline import transforms as tf
from pipeline.errors import TeachError
from pipeline.model.dh import forward_kinematics, link_frames
from pipeline.robots import load_spec
from pipeline.teach.server import (
    ERROR_MAP_NODE,
    TARGET_NODE,
    TeachServer,
    check_port_free,
    error_map_colours,
    link_node,
    readout_html,
)
from pipeline.teach.wire import PageClient
from tests.teach.conftest import start_server


def _connected(server: TeachServer) -> PageClient:
    client = PageClient(server.url)
    names = server.session.spec.joint_names
    assert client.pump_until(
        lambda c: (
            set(names) <= set(c.gui_label.values()) and link_node(len(names)) in c.orientations
        )
    ), "the page's initial scene and GUI never arrived"
    return client


def _joints(client: PageClient, names: tuple[str, ...]) -> np.ndarray:
    return np.array([client.value(n) for n in names], dtype=float)


def _drag_and_check(server: TeachServer, q_goal: list[float], tol: float) -> None:
    spec = server.session.spec
    target = forward_kinematics(spec, q_goal)
    with _connected(server) as client:
        before = _joints(client, spec.joint_names)
        client.move_target(target[:3, 3], tf.quat_wxyz(target[:3, :3]))

        def moved(c: PageClient) -> bool:
            q = _joints(c, spec.joint_names)
            return bool(np.abs(forward_kinematics(spec, q) - target).max() < tol)

        assert client.pump_until(moved), (
            f"joints sent back {_joints(client, spec.joint_names)} (before {before}) do not "
            f"reach the target; server says: {server.state.reason}"
        )
        q = _joints(client, spec.joint_names)
        # the arm drawn on the page: every link node sits at its DH frame for those joints
        client.pump(0.2)
        for i, base_T_i in enumerate(link_frames(spec, q), start=1):
            np.testing.assert_allclose(client.positions[link_node(i)], base_T_i[:3, 3], atol=1e-6)
            r = tf.quat_to_matrix(np.array(client.orientations[link_node(i)]))
            np.testing.assert_allclose(r, base_T_i[:3, :3], atol=1e-6)


@pytest.mark.parametrize("robot", ["ur5", "ur10", "mdh_example"])
def test_dragging_the_target_sends_joints_whose_fk_is_the_target(robot: str) -> None:
    server = start_server(robot)
    try:
        spec = server.session.spec
        q_goal = np.clip(server.state.q + np.array([0.3, -0.2, 0.25, 0.1, -0.2, 0.3]),
                         spec.lower, spec.upper)  # fmt: skip
        _drag_and_check(server, list(q_goal), tol=1e-5)
    finally:
        server.close()


def test_a_users_yaml_robot_works_by_path(user_robot: Path) -> None:
    server = start_server(str(user_robot))
    try:
        assert server.session.spec.name == "my_arm" and server.session.solver.name == "numeric"
        q_goal = list(np.clip(server.state.q + 0.2, server.session.spec.lower,
                              server.session.spec.upper))  # fmt: skip
        _drag_and_check(server, q_goal, tol=1e-5)
    finally:
        server.close()


def test_unreachable_target_turns_the_marker_red_and_keeps_the_arm(
    ur5_server: TeachServer,
) -> None:
    names = ur5_server.session.spec.joint_names
    with _connected(ur5_server) as client:
        before = _joints(client, names)
        n = len(client.received)
        client.move_target([3.0, 0.0, 0.2], [1.0, 0.0, 0.0, 0.0])
        assert client.pump_until(
            lambda c: any("Unreachable" in str(m) for _, m in c.received[n:])
        ), "the readout never said the target is unreachable"
        reds = [m for _, m in client.received[n:]
                if m.get("name") == "/target/marker" and "color" in str(m)]  # fmt: skip
        assert reds and "218" in str(reds[-1])  # BAD_RGB = (218, 54, 51)
        np.testing.assert_array_equal(_joints(client, names), before)
        assert not ur5_server.state.reachable and "cannot reach" in ur5_server.state.reason


def test_moving_a_joint_slider_moves_the_gizmo_to_the_flange(ur5_server: TeachServer) -> None:
    spec = ur5_server.session.spec
    with _connected(ur5_server) as client:
        q = _joints(client, spec.joint_names)
        q[1] -= 0.4
        client.set_gui(spec.joint_names[1], float(q[1]))
        flange = forward_kinematics(spec, q)[:3, 3]

        def followed(c: PageClient) -> bool:
            p = c.positions.get(TARGET_NODE)
            return p is not None and bool(np.abs(np.array(p) - flange).max() < 1e-6)

        assert client.pump_until(followed), "the gizmo did not follow the flange"
        assert ur5_server.state.source == "fk"


def test_error_map_is_drawn_as_a_point_cloud_on_request(ur5_server: TeachServer) -> None:
    with _connected(ur5_server) as client:
        failed = ur5_server.show_error_map(40)
        assert failed == 0  # the closed form solves every reachable sample
        assert client.pump_until(
            lambda c: any(m.get("name") == ERROR_MAP_NODE for _, m in c.received)
        )


def test_error_map_colours_run_green_to_red_with_failures_red() -> None:
    pos = np.array([1e-16, 1e-7, 1e-4, np.nan])
    ang = np.array([1e-16, 1e-16, 1e-16, np.nan])
    c = error_map_colours(pos, ang).astype(int)
    assert c[0, 1] > c[0, 0]  # green
    assert tuple(c[2]) == tuple(c[3]) == (218, 54, 51)  # at the target, and unsolved: red


def test_readout_marks_each_check_against_the_notes_targets(ur5_server: TeachServer) -> None:
    spec = load_spec("ur5")
    state = ur5_server.session.set_target(forward_kinematics(spec, [0.1, -1.0, 1.0, 0.2, 0.8, 0]))
    text = readout_html(state, solver="analytic")
    assert "Solved" in text and text.count("pass") == 3 and "FAIL" not in text
    assert "&lt; 0.1 mm" in text and "&lt; 0.01 rad" in text and "&lt; 5 ms" in text


def test_port_in_use_is_one_error_suggesting_port() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(TeachError, match=f"port {port} .* already in use; .*--port"):
            check_port_free("127.0.0.1", port)
        other = start_server("ur5")  # any free port
        try:
            with pytest.raises(TeachError, match="--port"):
                TeachServer(other.session, robot_arg="ur5", port=port)
        finally:
            other.close()


def test_choosing_another_solution_on_the_page_moves_the_arm_not_the_flange(
    ur5_server: TeachServer,
) -> None:
    spec = ur5_server.session.spec
    target = forward_kinematics(spec, [0.4, -1.1, 1.3, -0.6, 0.9, -0.3])
    with _connected(ur5_server) as client:
        client.move_target(target[:3, 3], tf.quat_wxyz(target[:3, :3]))
        assert client.pump_until(lambda c: str(c.value("IK solution")).startswith("1 of 8"))
        first = _joints(client, spec.joint_names)
        client.set_gui("IK solution", "3 of 8")

        def switched(c: PageClient) -> bool:
            return not np.allclose(_joints(c, spec.joint_names), first)

        assert client.pump_until(switched), "the arm did not change solution"
        q = _joints(client, spec.joint_names)
        np.testing.assert_allclose(forward_kinematics(spec, q), target, atol=1e-9)
        np.testing.assert_allclose(q, ur5_server.state.solutions[2], atol=0)


def test_use_as_goal_button_writes_a_valid_params_file(tmp_path: Path) -> None:
    import shutil

    from pipeline.params import load_params

    params = tmp_path / "params.yaml"
    shutil.copy(Path(__file__).resolve().parents[2] / "params.yaml", params)
    server = start_server("ur5", params=str(params))  # teach writes only this file
    spec = server.session.spec
    target = forward_kinematics(spec, [0.4, -1.1, 1.3, -0.6, 0.9, -0.3])
    with _connected(server) as client:
        client.move_target(target[:3, 3], tf.quat_wxyz(target[:3, :3]))
        assert client.pump_until(lambda c: str(c.value("IK solution")).startswith("1 of 8"))
        client.set_gui("scenario", "from-page")
        client.set_gui("goal as", "joints")
        client.set_gui("Write goal", True)  # handled after the inputs above, in order
        assert client.pump_until(
            lambda c: any("wrote scenarios.from-page.goal" in str(m) for _, m in c.received)
        ), "the page never confirmed the write"
    server.close()
    joints = load_params(params).scenarios["from-page"].goal.joints
    assert joints is not None
    np.testing.assert_allclose(forward_kinematics(spec, joints), target, atol=1e-9)


def test_hiding_the_error_map_before_showing_it_is_harmless(ur5_server: TeachServer) -> None:
    ur5_server.hide_error_map()
    assert ur5_server.show_error_map(10) == 0
    ur5_server.hide_error_map()
