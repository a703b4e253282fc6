"""Facts a robot's files lack: derived acceleration limits by a stated rule, and a warning at
``record`` naming each missing value and what stands in for it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pipeline.robots import load_spec
from pipeline.robots.facts import (
    ACCELERATION_EFFORT_FRACTION,
    ACCELERATION_RULE,
    VELOCITY_RISE_S,
    fact_warnings,
    missing_facts,
)
from pipeline.robots.urdf import build_pinocchio_model
from tests.robots.test_urdf_loader import THREE_JOINT
from tests.test_bad_input import run_cli

PARAMS = """\
sim: {{physics_dt_s: 0.001, control_period_steps: 1, integrator: RK4, joint_state_decimation: 1,
      tf_rate_hz: 50.0, ros_distro: jazzy}}
scenarios:
  three-short:
    robot: {robot}
    start: [0.0, 0.3, 0.0]
    goal: {{joints: [0.2, 0.4, 0.1]}}
    planner: {{time_limit_s: 2.0, simplify: true, seed: 0}}
    plant: {{}}
    preroll_s: 0.05
    hold_s: 0.05
controllers:
  ctc: {{type: ctc}}
episodes:
  three-ctc: {{scenario: three-short, controller: ctc, seed: 0}}
"""


def _three(tmp_path: Path, sidecar: str | None = None) -> Path:
    path = tmp_path / "three.urdf"
    # every axis +z: this test is about facts, not axes
    path.write_text(THREE_JOINT.replace('<axis xyz="0 0.6 0.8"/>', '<axis xyz="0 0 1"/>'))
    if sidecar is not None:
        (tmp_path / "three.armlab.yaml").write_text(sidecar)
    return path


def test_unstated_acceleration_limits_are_derived_from_effort_inertia_and_velocity(tmp_path):
    # a sidecar that states velocities but no acceleration: the rule still applies
    spec = load_spec(_three(tmp_path, "velocity: [50.0, 2.0, 50.0]\n"))
    assert dict(spec.settings_sources)["acceleration"] == ACCELERATION_RULE
    # independent: M_jj by finite differences of RNEA (unit accelerations), not CRBA
    model = build_pinocchio_model(spec)
    data = model.createData()
    poses = [np.zeros(3), np.zeros(3)]  # zero pose; mid-range (limits symmetric) is zero too
    m_max = np.zeros(3)
    for q in poses:
        bias = pin.rnea(model, data, q, np.zeros(3), np.zeros(3))
        for j in range(3):
            column = pin.rnea(model, data, q, np.zeros(3), np.eye(3)[j]) - bias
            m_max[j] = max(m_max[j], column[j])
    by_effort = ACCELERATION_EFFORT_FRACTION * np.array([50.0, 30.0, 10.0]) / m_max
    by_velocity = np.array([50.0, 2.0, 50.0]) / VELOCITY_RISE_S
    assert by_effort[0] < by_velocity[0] and by_effort[1] > by_velocity[1]  # both terms bind
    np.testing.assert_allclose(spec.acceleration_limits, np.minimum(by_effort, by_velocity))


def test_stated_acceleration_limits_are_kept_and_nothing_is_reported(tmp_path):
    spec = load_spec(_three(tmp_path, "acceleration: 4.0\narmature: 0.01\n"))
    assert spec.acceleration_limits.tolist() == [4.0] * 3
    assert missing_facts(spec) == ()
    assert missing_facts(load_spec("panda")) == () and missing_facts(load_spec("ur5")) == ()


def test_each_missing_value_is_named_with_its_joint_and_substitute(tmp_path):
    spec = load_spec(_three(tmp_path))
    facts = missing_facts(spec)
    assert {(f.joint, f.field) for f in facts} == {
        (j, field) for j in ("j1", "j2", "j3") for field in ("armature", "acceleration limit")
    }
    lines = fact_warnings(facts)
    assert len(lines) == 2
    accel = next(line for line in lines if "acceleration limit" in line)
    for j, a in zip(spec.joint_names, spec.acceleration_limits, strict=True):
        assert f"{j} {a:.3g} rad/s^2" in accel
    assert ACCELERATION_RULE in accel
    armature = "robot 'three' states no armature: using j1 0 kg m^2, j2 0 kg m^2, j3 0 kg m^2"
    assert any(line.startswith(armature) for line in lines)


@pytest.mark.slow
def test_record_warns_about_each_missing_fact_before_running(tmp_path, capsys):
    params = tmp_path / "params.yaml"
    params.write_text(PARAMS.format(robot=_three(tmp_path)))
    code, err = run_cli(["record", "--params", str(params), "--out", str(tmp_path / "rec")], capsys)
    assert code == 0, err
    warnings = [line for line in err.splitlines() if line.startswith("warning: robot 'three'")]
    assert len(warnings) == 2, err
    assert "no armature" in err and "no acceleration limit" in err
    code, err = run_cli(
        ["report", "--recordings", str(tmp_path / "rec"), "--out", str(tmp_path / "rep")], capsys
    )
    assert code == 0, err
    text = (tmp_path / "rep" / "report.md").read_text(encoding="utf-8")
    limits = load_spec(tmp_path / "three.urdf").acceleration_limits
    shown = ", ".join(f"{a:.3g}" for a in limits)
    assert f"- Acceleration limits [rad/s²]: [{shown}]; source: {ACCELERATION_RULE}." in text
