"""A URDF robot with a gripper end to end: record + report on the Panda (fingers locked)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from pipeline.robots import load_spec
from pipeline.robots.packages import package_search_path
from tests.test_bad_input import run_cli, run_cli_out

pytestmark = pytest.mark.skipif(
    not any((p / "example-robot-data").is_dir() for p in package_search_path()),
    reason="example-robot-data is not installed",
)

PARAMS = """\
sim: {physics_dt_s: 0.0005, control_period_steps: 2, integrator: RK4, joint_state_decimation: 1,
      tf_rate_hz: 50.0, ros_distro: jazzy}
scenarios:
  panda-short:
    robot: panda
    start: [0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]
    goal: {joints: [0.3, -0.6, 0.1, -2.1, 0.05, 1.6, 0.8]}
    planner: {time_limit_s: 5.0, simplify: true, seed: 0}
    plant: {}
    preroll_s: 0.1
    hold_s: 0.1
controllers:
  ctc: {type: ctc, gains: {kp: 1600.0, kd: 80.0}}
episodes:
  panda-ctc: {scenario: panda-short, controller: ctc, seed: 0}
"""


@pytest.mark.slow
def test_panda_records_and_reports_with_its_own_urdf(tmp_path: Path, capsys) -> None:
    from pipeline.log.reader import read_recording

    params = tmp_path / "params.yaml"
    params.write_text(PARAMS)
    code, err = run_cli(["record", "--params", str(params), "--out", str(tmp_path / "rec")], capsys)
    assert code == 0, err
    panda = load_spec("panda")
    rec = read_recording(tmp_path / "rec" / "panda-ctc")
    assert rec.joint_names == panda.joint_names
    assert rec.robot_description == Path(panda.source).read_text(encoding="utf-8")
    assert rec.settings is not None
    robot = rec.settings.robot
    assert robot.source == panda.source and robot.format == "urdf"
    assert robot.source_sha256 == hashlib.sha256(Path(panda.source).read_bytes()).hexdigest()
    sources = dict(robot.settings_sources)
    assert "Menagerie" in sources["armature"]
    # plant: {} gives no friction: the sidecar's damping, the URDF's <dynamics friction>
    assert sources["frictionloss"] == "URDF <dynamics>"
    assert rec.settings.plant.damping == (1.0,) * 7
    from pipeline.analysis.episodes import robot_spec

    assert robot_spec(rec) == panda  # the recording carries its robot by value
    code, _, err = run_cli_out(
        ["report", "--recordings", str(tmp_path / "rec"), "--out", str(tmp_path / "rep")], capsys
    )
    assert code == 0, err
    text = (tmp_path / "rep" / "report.md").read_text(encoding="utf-8")
    assert "7 joints" in text and "from urdf" in text and "DH convention" not in text
    assert "Where the plant's joint friction comes from: damping: " in text
    assert "frictionloss: URDF <dynamics>" in text
    # the sidecar's armature source, not "not stated in the robot file"
    assert "0.1 (all joints); source: MuJoCo Menagerie" in text


def test_a_bad_urdf_is_one_error_line_and_writes_nothing(tmp_path: Path, capsys) -> None:
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(
        '<robot name="arm"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
        '<parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint></robot>'
    )
    before = sorted(tmp_path.iterdir())
    code, err = run_cli(["fk", str(urdf), "0"], capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 1 and len(lines) == 1 and str(urdf) in lines[0], err
    assert "Traceback" not in err and sorted(tmp_path.iterdir()) == before
