"""Identification of robots given as URDF and MJCF: excite -> fit -> validate on a
noise-free ideal plant recovers the base parameters, and the model file is a scenario's
``nominal:`` whatever the robot's format."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.errors import IdentificationError
from pipeline.identify.excitation import record_excitation
from pipeline.identify.model_file import load_model, nominal_spec
from pipeline.identify.regressor import base_parameters, standard_parameters
from pipeline.identify.stage import fit_command, model_parameters, validate_command
from pipeline.robots.loaders import load_spec
from tests.robots.test_urdf_loader import SHARE

pytestmark = pytest.mark.skipif(SHARE is None, reason="example-robot-data share not found")

READY = [0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]


def ideal_params(folder: Path, robot: str, *, nominal: str | None = None) -> Path:
    """A params file: the robot on an ideal plant (no friction, no noise) stepped by the
    semi-implicit Euler step at the control rate (the exact fit's model), CTC."""
    scenario = {
        "robot": robot,
        "start": READY,
        "goal": {"joints": [0.3, -0.5, 0.0, -2.0, 0.0, 1.5, 0.785398]},
        "planner": {"time_limit_s": 5.0, "simplify": True, "seed": 0},
        "plant": {"damping": 0.0, "frictionloss": 0.0},
        "preroll_s": 0.2,
        "hold_s": 0.2,
        **({"nominal": nominal} if nominal else {}),
    }
    params = {
        "sim": {"physics_dt_s": 0.001, "control_period_steps": 1, "integrator": "Euler"},
        "scenarios": {"ideal": scenario},
        "controllers": {"ctc": {"type": "ctc", "gains": {"kp": 1600.0, "kd": 80.0}}},
        "episodes": {"x": {"scenario": "ideal", "controller": "ctc", "seed": 0}},
    }
    path = folder / ("params-nominal.yaml" if nominal else "params.yaml")
    path.write_text(yaml.safe_dump(params))
    return path


def round_trip(folder: Path, robot: str) -> None:
    """excite (CSV export too) -> fit (exact) -> validate -> a nominal: episode recorded."""
    params = ideal_params(folder, robot)
    kw = {"scenario_name": "ideal", "evaluations": 400, "periods": 1, "span_rad": 0.6, "seed": 0}
    kw["variant"] = 0
    record_excitation(params, out=folder / "fit", export=folder / "fit.csv", **kw)  # type: ignore[arg-type]
    assert (folder / "fit.csv").stat().st_size > 0
    model_path = folder / "model.yaml"
    fit_command([folder / "fit"], out=model_path, cutoff_hz=0.0, min_speed_rad_s=0.0)
    spec = load_spec(robot)
    model = load_model(model_path)
    assert model.spec.format == spec.format and model.spec.joint_names == spec.joint_names
    base = base_parameters(spec)
    truth = base.of(standard_parameters(spec))  # the ideal plant is the description
    scale = np.maximum(np.abs(truth), 1e-3)  # friction and offsets are 0 on this plant
    wls = np.array([b["wls"] for b in model.identification["base_parameters"]])
    assert np.max(np.abs(wls - truth) / scale) < 1e-6
    # the physically consistent model's (a hair of margin on near-degenerate links)
    assert np.max(np.abs(base.of(model_parameters(model)) - truth) / scale) < 1e-5
    check = validate_command(model_path, [folder / "fit"], figure=folder / "v.png")
    assert max(check["rms_error_pct"]) < 1e-6
    # a scenario whose nominal: is the model records an episode
    nominal = ideal_params(folder, robot, nominal=str(model_path))
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(nominal), "--out",
         str(folder / "rec"), "--only", "x"],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert (folder / "rec" / "x").is_dir()


@pytest.mark.slow
def test_urdf_panda_excite_fit_validate_and_nominal(tmp_path: Path) -> None:
    round_trip(tmp_path, "panda")


@pytest.mark.slow
def test_mjcf_panda_excite_fit_validate_and_nominal(
    tmp_path: Path,
    panda_xml: Path,
) -> None:
    round_trip(tmp_path, str(panda_xml))


def test_a_urdf_model_applies_to_the_scenario_robot_whatever_the_format(tmp_path: Path) -> None:
    """The format-neutral model file: its links replace the spec's inertials and armature,
    its friction the stated damping and friction loss; other joints are refused."""
    from pipeline.identify.model_file import FORMAT, model_robot_document

    panda = load_spec("panda")
    doc = {
        "format": FORMAT,
        **model_robot_document(panda),
        "friction": {
            "coulomb_nm": [0.5] * 7,
            "viscous_nm_s_rad": [0.2] * 7,
            "offset_nm": [0.0] * 7,
        },
    }
    doc["links"][2]["inertial"]["mass"] = 9.0
    doc["links"][2]["armature"] = 0.3
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    spec = nominal_spec(panda, str(path))
    assert spec.joints[2].inertial is not None and spec.joints[2].inertial.mass == 9.0
    assert spec.armature[2] == 0.3 and spec.damping == (0.2,) * 7
    assert spec.format == "urdf" and spec.joints[0].inertial == panda.joints[0].inertial
    with pytest.raises(IdentificationError, match=r"scenarios.x.nominal: .* is a model of joints"):
        nominal_spec(load_spec("ur5"), str(path), where="scenarios.x")


def test_excite_refuses_a_robot_without_dynamics_before_any_work(tmp_path: Path) -> None:
    robot = yaml.safe_load((Path(__file__).parents[2] / "pipeline/robots/ur5.yaml").read_text())
    for joint in robot["joints"]:
        joint.pop("inertial", None)
    (tmp_path / "k.yaml").write_text(yaml.safe_dump(robot))
    params = ideal_params(tmp_path, str(tmp_path / "k.yaml"))
    data = yaml.safe_load(params.read_text())
    data["scenarios"]["ideal"].update(start=[0.0] * 6, goal={"joints": [0.5] * 6})
    params.write_text(yaml.safe_dump(data))
    with pytest.raises(IdentificationError, match="needs link dynamics"):
        record_excitation(
            params, scenario_name="ideal", seed=0, variant=0, out=tmp_path / "e", budget_s=60.0
        )
    assert not (tmp_path / "e").exists()
