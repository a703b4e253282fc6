"""Issue 27 item 8: a bag we did not write (``rosbags``) that carries ``/robot_description``
gets its robot, and so TCP metrics, from that URDF; the report says which description and
which frame. The TCP is checked against an independent URDF forward kinematics (yourdfpy)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin

from pipeline.analysis.task_space import TaskSpace
from pipeline.log.reader import ReadOptions, read_recording
from pipeline.log.robot_facts import described_robot, robot_facts
from pipeline.stages.report import run_report
from tests.log.test_external_bags import JOINTS, write_external_bag

# joints about +x, -y (arbitrary origins, a turned joint frame) and an arbitrary unit axis,
# a fixed flange (tool0) and a mesh nobody has: FK needs none of the meshes
URDF = """<robot name="my_arm">
  <link name="base"><visual><geometry><mesh filename="package://gone/base.stl"/></geometry>
    </visual></link>
  <link name="l1"><inertial><mass value="2"/><origin xyz="0 0 0.1"/>
    <inertia ixx="0.02" iyy="0.02" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l2"><inertial><mass value="1.5"/><origin xyz="0.1 0 0"/>
    <inertia ixx="0.01" iyy="0.015" izz="0.015" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l3"><inertial><mass value="0.5"/><origin xyz="0 0 0.05"/>
    <inertia ixx="0.002" iyy="0.002" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><mesh filename="file:///nowhere/l3.stl"/></geometry></collision></link>
  <link name="tool0"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.2"/><axis xyz="1 0 0"/>
    <limit lower="-3" upper="3" effort="40" velocity="3"/></joint>
  <joint name="elbow" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.05 0.02 0.3" rpy="0.3 -0.2 0.5"/><axis xyz="0 -1 0"/>
    <limit lower="-3" upper="3" effort="50" velocity="3"/></joint>
  <joint name="wrist" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.25 0 0.01"/><axis xyz="0.6 0 0.8"/>
    <limit lower="-3" upper="3" effort="60" velocity="3"/></joint>
  <joint name="flange" type="fixed"><parent link="l3"/><child link="tool0"/>
    <origin xyz="0.01 0.02 0.1" rpy="0 1.2 0"/></joint>
</robot>
"""


def test_a_foreign_bags_description_gives_its_robot_and_the_tcp_of_an_independent_fk(
    tmp_path: Path,
) -> None:
    import yourdfpy

    path = tmp_path / "my_robot_run"
    write_external_bag(path, distro="jazzy", storage=StoragePlugin.MCAP, urdf=URDF)
    rec = read_recording(path, ReadOptions(controller="jtc", scenario="pick"))
    facts = robot_facts(rec)
    assert facts.source == "urdf" and facts.spec is not None
    assert facts.spec.joint_names == JOINTS == rec.joint_names
    assert "/robot_description" in facts.note and "frame 'tool0'" in facts.note
    assert dict(facts.effort_limits_nm) == {"shoulder": 40.0, "elbow": 50.0, "wrist": 60.0}

    urdf_path = tmp_path / "independent.urdf"
    urdf_path.write_text(URDF.replace('<mesh filename="package://gone/base.stl"/>',
                                      '<box size="0.1 0.1 0.1"/>')
                         .replace('<mesh filename="file:///nowhere/l3.stl"/>',
                                  '<box size="0.1 0.1 0.1"/>'))  # fmt: skip
    robot = yourdfpy.URDF.load(str(urdf_path), load_meshes=False, build_scene_graph=True)
    rows = rec.samples.pivot(on="joint", index="stamp_ns", values="position_rad").sort("stamp_ns")
    q = rows.select(JOINTS).to_numpy()[::50]
    tcp = TaskSpace(facts.spec).tcp_poses(q)
    for k, qk in enumerate(q):
        robot.update_cfg(dict(zip(JOINTS, qk, strict=True)))
        expected = robot.get_transform("tool0", "base")
        np.testing.assert_allclose(tcp[k][:3, 3], expected[:3, 3], atol=1e-6, rtol=0)
        np.testing.assert_allclose(tcp[k][:3, :3], expected[:3, :3], atol=1e-9, rtol=0)


@pytest.mark.slow
def test_a_foreign_bags_report_has_tcp_metrics_and_names_the_description(
    tmp_path: Path,
) -> None:
    bags = tmp_path / "bags"
    write_external_bag(bags / "run1", distro="humble", storage=StoragePlugin.MCAP, urdf=URDF)
    run_report(
        recordings_dir=bags,
        out_dir=tmp_path / "out",
        baseline="jtc",
        options=ReadOptions(controller="jtc", scenario="pick"),
    )
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    (episode,) = metrics["episodes"].values()
    tcp = episode["joints"]["tcp"]
    assert tcp["tcp_max_position_error"] > 0
    text = (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    assert "robot from the bag's /robot_description (URDF 'my_arm'" in text
    assert "TCP at frame 'tool0'" in text


def test_a_description_without_a_chain_gives_no_robot_and_says_why() -> None:
    spec, note = described_robot('<robot name="x"><joint name="j" type="revolute"/></robot>')
    assert spec is None and note.startswith("no robot from the bag's /robot_description (")
    assert "\n" not in note and "armlab-description" not in note
    assert described_robot("") == (None, "")


def test_a_description_of_other_joints_says_task_space_is_na(tmp_path: Path) -> None:
    path = tmp_path / "run"
    write_external_bag(path, distro="jazzy", storage=StoragePlugin.MCAP,
                       urdf=URDF.replace('"wrist"', '"wrist_roll"'))  # fmt: skip
    facts = robot_facts(read_recording(path, ReadOptions(controller="jtc")))
    assert facts.spec is not None and facts.note.endswith("task space n/a")
    assert "(shoulder, elbow, wrist_roll) are not the bag's (shoulder, elbow, wrist)" in facts.note


def test_without_tool0_the_tcp_is_the_leaf_link() -> None:
    text = URDF.replace('<link name="tool0"/>', "").split('<joint name="flange"')[0] + "</robot>"
    spec, note = described_robot(text)
    assert spec is not None and "TCP at frame 'l3'" in note
