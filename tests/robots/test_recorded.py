"""The robot by value (issue 29): every robot format round-trips exactly through a bag's
``settings.robot`` JSON, and a URDF robot's bag is reported after its files are deleted."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.errors import SpecError
from pipeline.robots import RobotSpec, load_spec
from pipeline.robots.recorded import RECORDED_SOURCE, robot_from_dict, robot_to_dict
from pipeline.settings import EpisodeSettings, SettingsError
from tests.robots.panda_files import ERD, copy_panda_urdf, needs_erd

TWO_HINGES = """\
<mujoco model="arm">
  <worldbody>
    <body name="base">
      <body name="l1" pos="0 0 0.1">
        <joint name="j1" axis="0 0 1" range="-2 2" actuatorfrcrange="-10 10" damping="0.4"/>
        <geom type="box" size="0.02 0.02 0.1" mass="1"/>
        <body name="l2" pos="0 0 0.2">
          <joint name="j2" axis="0 1 0" range="-2 2" actuatorfrcrange="-10 10"/>
          <geom type="sphere" size="0.05" mass="0.5"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def _through_json(spec: RobotSpec) -> RobotSpec:
    """``spec`` written as a bag writes it and read back as a bag reader reads it."""
    text = json.dumps(robot_to_dict(spec), sort_keys=True, separators=(",", ":"))
    return robot_from_dict(json.loads(text))


def test_a_dh_robot_round_trips_exactly_in_its_unchanged_yaml_form() -> None:
    ur5 = load_spec("ur5")
    data = robot_to_dict(ur5)
    # the form every UR5 bag has carried (kept: the demo bags stay byte-identical)
    assert set(data) == {"name", "convention", "angle_unit", "joints", "armature_source"}
    assert set(data["joints"][0]) == {"name", "dh", "limits", "inertial", "collision", "armature"}
    assert _through_json(ur5) == replace(ur5, source=RECORDED_SOURCE)


@needs_erd
@pytest.mark.parametrize("robot", ["panda", "ur_description/urdf/ur5_robot.urdf"])
def test_a_urdf_robot_round_trips_exactly_by_value(robot: str) -> None:
    assert ERD is not None
    spec = load_spec(robot if robot == "panda" else ERD / "robots" / robot)
    assert spec.format == "urdf" and spec.dh_rows is None
    back = _through_json(spec)
    assert back == spec
    assert back.description == spec.description and back.frames == spec.frames
    assert back.joints[1].axis == spec.joints[1].axis  # ur5_robot.urdf: about y
    assert robot_to_dict(back) == robot_to_dict(spec)


def test_an_mjcf_robot_round_trips_exactly_by_value(tmp_path: Path) -> None:
    path = tmp_path / "arm.xml"
    path.write_text(TWO_HINGES)
    spec = load_spec(path)
    assert spec.format == "mjcf" and spec.damping == (0.4, 0.0)
    assert _through_json(spec) == spec


@needs_erd
def test_the_recorded_value_names_no_file_it_needs() -> None:
    """Every fact the loaders read from files is in the value; meshes by reference only."""
    data = robot_to_dict(load_spec("panda"))
    joint = data["joints"][0]
    for key in ("kind", "axis", "origin", "limits", "inertial", "armature", "damping_nm_s_rad",
                "frictionloss_nm", "shapes", "link"):  # fmt: skip
        assert key in joint, key
    assert data["base_link"] and data["frames"] and data["named_states"] and data["description"]
    assert any(f["name"] == "panda_hand_tcp" for f in data["frames"])


def test_a_bad_robot_value_is_one_line_naming_the_field() -> None:
    data = robot_to_dict(load_spec("ur5"))
    data["joints"][0]["limits"]["lower"] = "low"
    with pytest.raises(SpecError, match=r"^settings\.robot: joints\[0\]\.limits\.lower"):
        robot_from_dict(data)
    by_value: dict[str, Any] = {"source_sha256": "", "name": "x", "joints": "none"}
    with pytest.raises(SpecError, match=r"^settings\.robot: ") as err:
        robot_from_dict(by_value)
    assert "\n" not in str(err.value)


@needs_erd
def test_an_old_bag_robot_recorded_by_path_reads_while_its_file_is_unchanged(
    tmp_path: Path,
) -> None:
    assert ERD is not None
    urdf = tmp_path / "ur5.urdf"
    shutil.copy(ERD / "robots/ur_description/urdf/ur5_robot.urdf", urdf)
    spec = load_spec(urdf)
    old = {"name": spec.name, "format": "urdf", "source": str(urdf),
           "sha256": spec.source_sha256, "robot": str(urdf), "joints": []}  # fmt: skip
    assert robot_from_dict(old) == spec
    urdf.write_text(urdf.read_text() + "\n")
    with pytest.raises(SpecError, match=r"recorded by path .* changed since"):
        robot_from_dict(old)
    urdf.unlink()
    with pytest.raises(SpecError, match=r"recorded by path .* not readable here"):
        robot_from_dict(old)


def test_settings_refuse_a_robot_that_is_not_one_in_one_line() -> None:
    from tests.analysis.bagfactory import default_settings, paper_like

    data = default_settings(paper_like("ctc.s0", "ctc"))
    data["robot"] = {"name": "ur5"}
    with pytest.raises(SettingsError) as err:
        EpisodeSettings.from_dict(data)
    assert str(err.value).startswith("settings.robot: ") and "\n" not in str(err.value)


PARAMS = """\
sim: {physics_dt_s: 0.0005, control_period_steps: 2, integrator: RK4, joint_state_decimation: 1,
      tf_rate_hz: 50.0, ros_distro: jazzy}
scenarios:
  copied:
    robot: ROBOT
    start: [0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]
    goal: {joints: [0.3, -0.6, 0.1, -2.1, 0.05, 1.6, 0.8]}
    plant: {}
    preroll_s: 0.1
    hold_s: 0.1
controllers:
  ctc: {type: ctc, gains: {kp: 1600.0, kd: 80.0}}
episodes:
  copied-ctc: {scenario: copied, controller: ctc, seed: 0}
"""


@needs_erd
@pytest.mark.slow
def test_a_urdf_robots_bag_is_reported_after_its_files_are_deleted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from pipeline.log.reader import read_recording
    from tests.test_bad_input import run_cli, run_cli_out

    arm = tmp_path / "arm"
    # the copy's meshes, not the installed package's: package:// -> the copied folder
    urdf = copy_panda_urdf(arm, meshes=True)
    recorded = load_spec(urdf)
    assert any(Path(s.mesh).is_relative_to(arm) for j in recorded.joints for s in j.shapes)
    params = tmp_path / "params.yaml"
    params.write_text(PARAMS.replace("ROBOT", str(urdf)))
    code, err = run_cli(["record", "--params", str(params), "--out", str(tmp_path / "rec")], capsys)
    assert code == 0, err

    shutil.rmtree(arm)  # the robot's files are gone: the bag carries the robot

    rec = read_recording(tmp_path / "rec" / "copied-ctc")
    assert rec.settings is not None and rec.settings.robot.source == str(urdf)
    assert rec.settings.robot.joints == recorded.joints
    from pipeline.report.rrd_meshes import link_meshes

    arm = link_meshes(rec.settings.robot, np.zeros((1, 7)))
    assert arm is not None and arm.geometry == ()  # capsules, and the reason beside them
    assert "link meshes not drawn (capsules instead)" in arm.note
    code, _, err = run_cli_out(
        ["report", "--recordings", str(tmp_path / "rec"), "--out", str(tmp_path / "rep")], capsys
    )
    assert code == 0, err
    metrics = json.loads((tmp_path / "rep" / "metrics.json").read_text(encoding="utf-8"))
    (episode,) = metrics["episodes"].values()
    tcp = episode["joints"]["tcp"]
    assert tcp["tcp_max_position_error"] is not None and tcp["tcp_max_position_error"] >= 0
    assert (tmp_path / "rep" / "recording.rrd").stat().st_size > 0
    assert "from urdf" in (tmp_path / "rep" / "report.md").read_text(encoding="utf-8")
