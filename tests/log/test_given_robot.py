"""Issue 27 item 8: a bag without ``/robot_description`` (written by ``rosbags``: a
controller state and ``/joint_states`` only) gets its robot from ``report --robot`` and
its flange from ``--tip``; TCP metrics are then computed and the report says which
description and which frame. The TCP is checked against an independent URDF forward
kinematics (yourdfpy) of example-robot-data's UR5."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from pipeline.analysis.task_space import TaskSpace
from pipeline.errors import RecordingError, SpecError
from pipeline.log.reader import ReadOptions, read_recording
from pipeline.log.robot_facts import robot_facts
from pipeline.robots.packages import example_robot_data_share
from tests.log.rosbags_msgs import RosMsgs

_SHARE = example_robot_data_share()
assert _SHARE is not None, "example-robot-data is not installed"
UR5_URDF = _SHARE / "example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"
JOINTS = (
    "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
    "wrist_1_joint", "wrist_2_joint", "wrist_3_joint",
)  # fmt: skip
RATE_HZ = 500
N = 500  # 1 s
T0_NS = 1_700_000_000_000_000_000


def write_bag(path: Path) -> None:
    """A Jazzy MCAP bag of a 6-joint arm: JTC state + /joint_states, no description."""
    ros = RosMsgs("jazzy")
    s = np.arange(N)[:, None] / RATE_HZ
    k = np.arange(6)[None, :]
    ref = 0.6 * np.sin(1.5 * s + k) + np.array([0.0, -1.2, 1.2, -1.0, 0.5, 0.0])
    err = 1e-3 * (1 + k) * np.sin(7.0 * s)
    effort = 3.0 * np.cos(s + k)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        cs_type = "control_msgs/msg/JointTrajectoryControllerState"
        c_cs = w.add_connection("/arm_controller/controller_state", cs_type, typestore=ros.store)
        c_js = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ros.store)
        for i in range(N):
            ns = T0_NS + i * (10**9 // RATE_HZ)
            state = ros.controller_state(
                ns=ns, joints=list(JOINTS), reference=ros.point(ref[i]),
                feedback=ros.point(ref[i] - err[i]), error=ros.point(err[i]),
                output=ros.point(eff=effort[i]),
            )  # fmt: skip
            w.write(c_cs, ns, ros.cdr(state))
            js = ros.joint_state(ns=ns, names=list(JOINTS), position=ref[i] - err[i],
                                 velocity=0 * ref[i], effort=effort[i])  # fmt: skip
            w.write(c_js, ns, ros.cdr(js))


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("given") / "bags" / "ur5_run"
    write_bag(path)
    return path


def _independent_fk(frame: str, q: np.ndarray) -> list[np.ndarray]:
    import yourdfpy

    robot = yourdfpy.URDF.load(str(UR5_URDF), load_meshes=False, build_scene_graph=True)
    out = []
    for qk in q:
        robot.update_cfg(dict(zip(JOINTS, qk, strict=True)))
        out.append(robot.get_transform(frame, "base_link"))
    return out


@pytest.mark.parametrize(("tip", "frame"), [(None, "tool0"), ("ee_link", "ee_link"),
                                            ("wrist_3_link", "wrist_3_link")])  # fmt: skip
def test_robot_and_tip_options_give_the_tcp_of_an_independent_fk(
    bag: Path, tip: str | None, frame: str
) -> None:
    rec = read_recording(bag, ReadOptions(controller="jtc", robot=str(UR5_URDF), tip=tip))
    assert rec.robot_description is None
    facts = robot_facts(rec)
    assert facts.source == "given" and facts.spec is not None
    assert facts.spec.joint_names == JOINTS == rec.joint_names
    assert f"robot from --robot {UR5_URDF} (urdf 'ur5'" in facts.note
    assert f"TCP at frame '{frame}'" in facts.note
    assert facts.effort_limits_nm["shoulder_pan_joint"] == 150.0  # the URDF's
    rows = rec.samples.pivot(on="joint", index="stamp_ns", values="position_rad").sort("stamp_ns")
    q = rows.select(JOINTS).to_numpy()[::50]
    tcp = TaskSpace(facts.spec).tcp_poses(q)
    for got, expected in zip(tcp, _independent_fk(frame, q), strict=True):
        np.testing.assert_allclose(got[:3, 3], expected[:3, 3], atol=1e-6, rtol=0)
        np.testing.assert_allclose(got[:3, :3], expected[:3, :3], atol=1e-9, rtol=0)


def test_a_robot_of_other_joints_or_a_frame_off_the_tip_is_refused(bag: Path) -> None:
    rec = read_recording(bag, ReadOptions(controller="jtc", robot="panda"))
    with pytest.raises(RecordingError, match=r"--robot panda: its joints \(panda_joint1"):
        robot_facts(rec)
    rec = read_recording(bag, ReadOptions(controller="jtc", robot=str(UR5_URDF), tip="base"))
    with pytest.raises(SpecError, match="--tip base: not the last joint's link nor a frame"):
        robot_facts(rec)


def _report(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pipeline", "report", *args],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip


@pytest.mark.slow
def test_report_with_robot_has_tcp_metrics_and_says_which_robot_and_frame(
    bag: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    base = ["--recordings", str(bag.parent), "--baseline", "jtc", "--controller", "jtc"]
    proc = _report(*base, "--out", str(out), "--robot", str(UR5_URDF), "--tip", "ee_link")
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    (episode,) = metrics["episodes"].values()
    assert episode["joints"]["tcp"]["tcp_max_position_error"] > 0
    text = (out / "report.md").read_text(encoding="utf-8")
    assert f"robot from --robot {UR5_URDF} (urdf 'ur5'" in text
    assert "TCP at frame 'ee_link'" in text
    bad = tmp_path / "bad"
    proc = _report(*base, "--out", str(bad), "--robot", "panda")
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "--robot panda: its joints (panda_joint1" in lines[0]
    assert not bad.exists()
