"""Identification on the published plant (Gaz et al.'s Panda, ``plant.profile: gaz-panda``):
its friction is a sigmoid with a shifted centre per joint, not the identifier's class. The
torque a model identified on one excitation predicts for another (held out) of the same
plant, per joint, as a share of the RMS torque; then the model as a scenario's ``nominal:``
on that plant."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.identify.excitation import record_excitation
from pipeline.identify.stage import FIT_TRANSITION_SPEED_PER_JOINT, fit_command, validate_command
from tests.robots.test_urdf_loader import SHARE

PARAMS = Path(__file__).parents[2] / "examples" / "params-panda-gaz.yaml"
# the design's evaluations: the default 6000 costs ~35 s more; 2000 is measured below
EVALUATIONS = 2000


@pytest.mark.slow
@pytest.mark.skipif(SHARE is None, reason="example-robot-data share not found")
def test_a_model_identified_on_the_published_plant_predicts_a_held_out_excitation(
    tmp_path: Path,
) -> None:
    kw = {"scenario_name": "panda-gaz", "seed": 0, "periods": 2, "span_rad": 1.0}
    for name, variant in (("fit", 0), ("check", 1)):
        record_excitation(
            PARAMS, out=tmp_path / name, variant=variant, evaluations=EVALUATIONS, **kw
        )  # type: ignore[arg-type]
    errors = {}
    # the identifier's defaults (sign friction, 5 Hz), and the smooth transition per joint
    # at 2 Hz (four times the excitation's top harmonic: less of the sensor's noise)
    for friction, speed, cutoff_hz in (
        ("coulomb", 0.0, 5.0),
        ("sigmoid", FIT_TRANSITION_SPEED_PER_JOINT, 2.0),
    ):
        model = tmp_path / f"{friction}.yaml"
        fit_command(
            [tmp_path / "fit"], out=model, transition_speed_rad_s=speed, cutoff_hz=cutoff_hz
        )
        check = validate_command(model, [tmp_path / "check"], figure=tmp_path / "v.png")
        errors[friction] = check["rms_error_pct"]
    sigmoid, coulomb = errors["sigmoid"], errors["coulomb"]
    # measured (docs/identify.md): 4.87 0.22 1.17 0.13 4.98 0.70 3.02 %
    assert max(sigmoid) <= 5.0, sigmoid
    # the identifier's default class (sign) misses the sigmoid's transition: joint 7,
    # whose torque is almost all friction, is off by tens of %
    assert coulomb[6] > 3 * sigmoid[6], (coulomb, sigmoid)
    # the identified model as the controllers' nominal on that plant: an episode records
    data = yaml.safe_load(PARAMS.read_text())
    scenario = data["scenarios"]["panda-gaz"]
    scenario.update({"nominal": str(tmp_path / "sigmoid.yaml"), "preroll_s": 0.2,
                     "hold_s": 0.2, "hold_max_s": 0.2})  # fmt: skip
    data["episodes"] = {"x": {"scenario": "panda-gaz", "controller": "ctc", "seed": 0}}
    del data["extra_campaigns"]
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(params), "--out",
         str(tmp_path / "rec"), "--only", "x"],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert any((tmp_path / "rec" / "x").glob("*.mcap"))
