"""Issue 27, item 5 end to end: a Panda URDF copied out without its SRDF records (it used to
fail every episode on its base and first link), and a scenario starts at a named state."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.robots import load_spec
from tests.robots.panda_files import copy_panda_urdf, needs_erd
from tests.test_bad_input import run_cli

pytestmark = needs_erd

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
  named:
    robot: panda
    start: default
    goal: {joints: [0.3, -0.6, 0.1, -2.1, 0.05, 1.6, 0.8]}
    plant: {}
    preroll_s: 0.1
    hold_s: 0.1
controllers:
  ctc: {type: ctc, gains: {kp: 1600.0, kd: 80.0}}
episodes:
  copied-ctc: {scenario: copied, controller: ctc, seed: 0}
  named-ctc: {scenario: named, controller: ctc, seed: 0}
"""


@pytest.mark.slow
def test_a_urdf_without_srdf_records_and_a_named_start_is_used(tmp_path: Path, capsys) -> None:
    from pipeline.log.reader import read_recording

    urdf = copy_panda_urdf(tmp_path / "arm")
    params = tmp_path / "params.yaml"
    params.write_text(PARAMS.replace("ROBOT", str(urdf)))
    code, err = run_cli(
        ["record", "--params", str(params), "--out", str(tmp_path / "rec"), "-j", "1"], capsys
    )
    assert code == 0, err
    copied = read_recording(tmp_path / "rec" / "copied-ctc")
    assert copied.settings is not None
    assert "no SRDF" in dict(copied.settings.robot.settings_sources)["collision_pairs"]
    named = read_recording(tmp_path / "rec" / "named-ctc")
    start = load_spec("panda").named_state("default")
    first = named.samples.sort("time_s").head(named.samples["joint"].n_unique())
    by_joint = dict(zip(first["joint"].to_list(), first["position_rad"].to_list(), strict=True))
    np.testing.assert_allclose([by_joint[n] for n in named.joint_names], start, atol=1e-3)
