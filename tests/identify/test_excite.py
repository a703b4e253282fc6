"""Excitation design and recording, and identification on the realistic plant."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from pipeline.errors import IdentificationError
from pipeline.identify.excitation import (
    check_excitation,
    design_excitation,
    limit_ratios,
    record_excitation,
    scenario_plant,
)
from pipeline.identify.fourier import FourierReference
from pipeline.identify.stage import fit_command, validate_command
from pipeline.log.reader import read_recording
from pipeline.params import load_params
from pipeline.robots.loaders import load_spec
from tests.robots.test_urdf_loader import SHARE

PARAMS = Path(__file__).parents[2] / "params.yaml"


def test_fourier_reference_starts_and_ends_at_rest() -> None:
    rng = np.random.default_rng(0)
    ref = FourierReference.from_free(
        np.zeros(6), rng.normal(size=48) * 0.1, harmonics=5, base_frequency_hz=0.1, periods=2
    )
    q, qd, qdd = ref.sample_many(np.array([0.0, 1e-9, ref.duration_s - 1e-9, ref.duration_s]))
    np.testing.assert_allclose(qd, 0.0, atol=1e-7)
    np.testing.assert_allclose(qdd, 0.0, atol=1e-7)
    np.testing.assert_allclose(q[0], q[-1], atol=1e-12)
    # velocity is the derivative of position
    t = np.linspace(1.0, 2.0, 3)
    h = 1e-6
    numeric = (ref.sample_many(t + h)[0] - ref.sample_many(t - h)[0]) / (2 * h)
    np.testing.assert_allclose(numeric, ref.sample_many(t)[1], atol=1e-6)


def test_excitation_exports_as_csv_for_a_robot(tmp_path: Path) -> None:
    from pipeline.identify.fourier import write_csv

    rng = np.random.default_rng(1)
    ref = FourierReference.from_free(
        np.zeros(6), rng.normal(size=48) * 0.1, harmonics=5, base_frequency_hz=0.1, periods=1
    )
    names = load_spec("ur5").joint_names
    rows = write_csv(tmp_path / "x.csv", ref, names, rate_hz=100.0)
    table = np.loadtxt(tmp_path / "x.csv", delimiter=",", skiprows=1)
    assert rows == table.shape[0] == 1001 and table.shape[1] == 1 + 18
    q, qd, _ = ref.sample_many(table[:, 0])
    np.testing.assert_array_equal(table[:, 1:7], q)
    np.testing.assert_array_equal(table[:, 7:13], qd)


def test_design_stays_within_limits_and_beats_a_random_series() -> None:
    spec = load_spec("ur5")
    q0 = np.array([0.0, -1.2, 1.2, -1.0, 0.5, 0.0])
    design = design_excitation(spec, q0=q0, variant=0, evaluations=1500)
    for ratios in limit_ratios(spec, design.reference, span_rad=1.0, samples=2000):
        assert ratios.max() <= 1.0 + 1e-4  # peaks between the design's samples
    check_excitation(spec, design.reference)
    assert design.condition_number_scaled < 1e3


def test_same_inputs_give_the_same_design_bit_for_bit_even_under_load() -> None:
    """The design spends a count of evaluations, not a time: a second design while a
    busy-loop process spins on a core gives the same coefficients, bit for bit."""
    spec = load_spec("ur5")
    q0 = np.array([0.0, -1.2, 1.2, -1.0, 0.5, 0.0])
    kw = {"q0": q0, "variant": 3, "evaluations": 250}
    quiet = design_excitation(spec, **kw)  # type: ignore[arg-type]
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.2)  # spinning before the design starts
        assert spinner.poll() is None
        loaded = design_excitation(spec, **kw)  # type: ignore[arg-type]
    finally:
        spinner.kill()
        spinner.wait()
    assert quiet.evaluations == loaded.evaluations == 250
    assert quiet.reference == loaded.reference  # tuples of floats: bitwise equal
    assert quiet.condition_number_scaled == loaded.condition_number_scaled


def test_the_wall_clock_cap_fails_in_one_line_naming_the_count() -> None:
    spec = load_spec("ur5")
    q0 = np.array([0.0, -1.2, 1.2, -1.0, 0.5, 0.0])
    with pytest.raises(IdentificationError) as err:
        design_excitation(spec, q0=q0, variant=0, evaluations=10**7, budget_s=0.5)
    message = str(err.value)
    assert "\n" not in message
    assert re.match(
        r"the excitation design ran past --budget-s 0.5 s after \d+ of 10000000 "
        r"evaluations: raise --budget-s or lower --evaluations$",
        message,
    ), message


def test_excite_cli_cap_is_one_error_line_and_nothing_written(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "identify", "excite", "--params", str(PARAMS),
         "--scenario", "paper", "--budget-s", "0.2", "--out", str(tmp_path / "e")],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "error: the excitation design ran past --budget-s 0.2 s after "
    ), proc.stderr
    assert "--evaluations" in lines[0]
    assert not (tmp_path / "e").exists()
    shown = subprocess.run(
        [sys.executable, "-m", "pipeline", "identify", "excite", "--help"],
        capture_output=True, text=True, timeout=300, check=True,
        env={**os.environ, "COLUMNS": "200", "NO_COLOR": "1", "TERM": "dumb"},
    ).stdout  # fmt: skip
    assert "--evaluations" in shown and "6000" in shown


def test_an_excitation_beyond_the_limits_is_refused() -> None:
    spec = load_spec("ur5")
    free = np.full(48, 2.0)  # rad/s per harmonic: far beyond pi rad/s
    ref = FourierReference.from_free(
        np.zeros(6), free, harmonics=5, base_frequency_hz=0.1, periods=1
    )
    with pytest.raises(IdentificationError, match=r"leaves the (position|velocity) limit"):
        check_excitation(spec, ref)


def test_the_plant_a_scenario_draws_depends_on_the_seed_only() -> None:
    params = load_params(PARAMS)
    scenario = params.scenarios["paper-realistic"]
    spec = load_spec(scenario.robot)
    a, _, sa = scenario_plant(spec, scenario, seed=4)
    b, _, sb = scenario_plant(spec, scenario, seed=4)
    c, _, _ = scenario_plant(spec, scenario, seed=5)
    assert a == b and sa == sb
    assert a != c


@pytest.fixture(scope="module")
def realistic_fit(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """An excitation of the drawn realistic plant (seed 3) and the model fitted to it: the
    two tests below only read them."""
    root = tmp_path_factory.mktemp("realistic")
    record_excitation(
        PARAMS, variant=1, out=root / "fit", scenario_name="paper-realistic", seed=3,
        evaluations=1200, periods=2,
    )  # fmt: skip
    fit_command([root / "fit"], out=root / "model.yaml")
    return root / "fit", root / "model.yaml"


@pytest.mark.slow
def test_realistic_plant_identifies_friction_and_predicts_torque(
    tmp_path: Path, realistic_fit: tuple[Path, Path]
) -> None:
    """Drawn links and armature, MuJoCo frictionloss and damping, sensor noise: Coulomb
    friction within 10 % (frictionloss acts as Coulomb friction at the excitation's
    speeds; it is soft only near rest, which the fit leaves out), and another excitation
    of the same plant predicted within 5 % RMS per joint."""
    fit, model = realistic_fit
    kw = {"scenario_name": "paper-realistic", "seed": 3, "evaluations": 1200, "periods": 2}
    record_excitation(PARAMS, variant=2, out=tmp_path / "check", **kw)  # type: ignore[arg-type]
    # an excitation's settings are its own (not the episode contract): read them raw
    settings = json.loads(read_recording(fit).metadata["settings"])
    plant = settings["plant"]
    assert settings["excitation"]["evaluations"] == 1200  # the count, never the wall time
    from pipeline.identify.model_file import load_model

    coulomb = np.array(load_model(model).friction.coulomb_nm)
    np.testing.assert_allclose(coulomb, plant["frictionloss"], rtol=0.10)
    check = validate_command(model, [tmp_path / "check"])
    assert max(check["rms_error_pct"]) <= 5.0, check["rms_error_pct"]


def test_nominal_of_another_robot_is_refused(tmp_path: Path) -> None:
    from pipeline.identify.model_file import FORMAT, nominal_spec, spec_document

    ur10 = load_spec("ur10")
    path = tmp_path / "m.yaml"
    doc = {
        "format": FORMAT,
        "robot": {**spec_document(ur10), "joints": spec_document(ur10)["joints"][:5]},
        "friction": {k: [0.0] * 5 for k in ("coulomb_nm", "viscous_nm_s_rad", "offset_nm")},
    }
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(IdentificationError, match=r"scenarios.x.nominal: .* is a model of joints"):
        nominal_spec(load_spec("ur5"), str(path), where="scenarios.x")
    assert nominal_spec(load_spec("ur5"), None) == load_spec("ur5")


@pytest.mark.slow
def test_ctc_on_the_identified_model_beats_ctc_on_cad(realistic_fit: tuple[Path, Path]) -> None:
    """The paper's motion on a drawn realistic plant: CTC whose nominal model is identified
    from an excitation of that plant has a smaller max error on shoulder lift and elbow
    than CTC on the CAD model (the gravity error is what identification removes)."""
    from pipeline.control import make_controller
    from pipeline.identify.model_file import nominal_spec
    from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
    from pipeline.sim.runner import run_episode

    _, model = realistic_fit
    scenario = load_params(PARAMS).scenarios["paper-realistic"]
    spec = load_spec("ur5")
    plant_spec, plant, _ = scenario_plant(spec, scenario, seed=3)
    reference = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=3.0)
    max_error = {}
    for label, nominal in (
        ("cad", spec),
        ("identified", nominal_spec(spec, str(model))),
    ):
        result = run_episode(
            spec, reference=reference, controller=make_controller("ctc", nominal), seed=3,
            plant=plant, plant_spec=plant_spec, hold_s=1.0, preroll_s=1.0,
        )  # fmt: skip
        assert result.status == "ok"
        max_error[label] = np.abs(result.q_ref - result.q_true).max(axis=0)
    for j in (1, 2):  # shoulder lift, elbow
        assert max_error["identified"][j] < max_error["cad"][j], max_error


def test_params_accept_a_nominal_model_path() -> None:
    from pipeline.params import parse_params
    from pipeline.yamlio import parse_yaml

    data = parse_yaml(PARAMS.read_text(), source="params.yaml", error=IdentificationError)
    data["scenarios"]["paper-realistic"]["nominal"] = "models/ur5.yaml"
    params = parse_params(data, source="params.yaml")
    assert params.scenarios["paper-realistic"].nominal == "models/ur5.yaml"
    assert params.scenarios["paper"].nominal is None


OLD_PLANT_KEYS = {
    "links", "armature", "damping", "frictionloss", "payload_kg", "position_noise_std_rad",
    "velocity_noise_std_rad_s", "uncertainty",
}  # fmt: skip


def test_an_excitation_records_the_torque_sensor_it_ran_and_nothing_new_without_one() -> None:
    """The UR5 with per-seed draws and a torque sensor: the excitation's plant records the
    drawn offset and the noise as the plant ran them; a plant without them (the paper's
    realistic one) records the keys it did before (the same bytes)."""
    from pipeline.experiment.assemble import plant_run_options

    gaz = load_params(Path(__file__).parents[2] / "examples" / "params-panda-gaz.yaml")
    scenario = gaz.scenarios["ur5-draws"]
    spec = load_spec(scenario.robot)
    _, _, plant = scenario_plant(spec, scenario, seed=2)
    ran = plant_run_options(spec, scenario, seed=2)  # what run_episode is given
    assert plant["effort_offset_nm"] == list(ran["effort_offset_nm"])
    assert len(plant["effort_offset_nm"]) == 6 and max(map(abs, plant["effort_offset_nm"])) > 0
    assert plant["effort_noise_std_nm"] == ran["effort_noise_std_nm"] == 0.1
    assert "sigmoid_friction" not in plant and "profile" not in plant
    realistic = load_params(PARAMS).scenarios["paper-realistic"]
    assert set(scenario_plant(spec, realistic, seed=2)[2]) == OLD_PLANT_KEYS


def _excited_plant(tmp_path: Path, data: dict[str, Any], scenario: str) -> dict[str, Any]:
    """The ``plant`` settings of a short excitation (seed 1, variant 0, 20
    evaluations, one 1 Hz period, 0.3 rad) of ``scenario`` under params ``data``, written
    to ``tmp_path/params.yaml`` and recorded into ``tmp_path/e``."""
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    record_excitation(
        params, scenario_name=scenario, seed=1, variant=0, out=tmp_path / "e",
        evaluations=20, periods=1, base_frequency_hz=1.0, span_rad=0.3,
    )  # fmt: skip
    plant: dict[str, Any] = json.loads(read_recording(tmp_path / "e").metadata["settings"])["plant"]
    return plant


@pytest.mark.skipif(SHARE is None, reason="example-robot-data share not found")
def test_an_excitation_bag_of_the_published_plant_records_the_plant_that_ran(
    tmp_path: Path,
) -> None:
    """``identify excite`` on Gaz et al.'s Panda (seeded sigmoid, offset, payload draws):
    the bag's plant settings name the profile and hold the drawn sigmoid friction, the
    drawn torque-sensor offset and its noise, as the plant ran them (a short excitation,
    no obstacle: what is checked is the settings, not the design)."""
    from pipeline.experiment.assemble import scenario_friction
    from pipeline.model.published import PROFILES
    from pipeline.settings import SigmoidFrictionSettings
    from pipeline.sim.plant import SIGMOID_FRICTION

    data = yaml.safe_load((PARAMS.parent / "examples" / "params-panda-gaz.yaml").read_text())
    data["scenarios"]["panda-gaz"].update(
        {"obstacles": [], "preroll_s": 0.1, "hold_s": 0.1, "hold_max_s": 0.1}
    )
    plant = _excited_plant(tmp_path, data, "panda-gaz")
    scenario = load_params(tmp_path / "params.yaml").scenarios["panda-gaz"]
    drawn = scenario_friction(load_spec("panda"), scenario, seed=1)
    assert drawn.sigmoid is not None and drawn.effort_offset_nm
    assert plant["profile"] == f"gaz-panda: {PROFILES['gaz-panda'].source}"
    sigmoid = SigmoidFrictionSettings.from_dict(plant["sigmoid_friction"])
    assert sigmoid.phi1_nm == drawn.sigmoid.phi1_nm
    assert sigmoid.phi2_s_rad == drawn.sigmoid.phi2_s_rad
    assert sigmoid.phi3_rad_s == drawn.sigmoid.phi3_rad_s
    assert sigmoid.phi1_nm != PROFILES["gaz-panda"].friction.phi1_nm  # drawn, not as published
    assert tuple(plant["effort_offset_nm"]) == drawn.effort_offset_nm
    assert plant["effort_noise_std_nm"] == 0.05
    assert plant["payload_kg"] == drawn.payload_kg > 0
    assert plant["friction_model"] == SIGMOID_FRICTION  # the law the plant ran


def test_an_excitation_bag_records_how_its_plant_was_stepped_as_an_episode_bag_does(
    tmp_path: Path,
) -> None:
    """``identify excite`` with a sim other than the default (2 ms Euler steps, control
    every other step): the bag's plant settings carry the physics step, control period,
    integrator and friction law the plant ran, as an episode's plant does (a short
    excitation: what is checked is the settings, not the design)."""
    from pipeline.constants import PLANT_FRICTION
    from pipeline.settings import PlantSettings

    data = yaml.safe_load(PARAMS.read_text())
    data["sim"].update({"physics_dt_s": 0.002, "control_period_steps": 2, "integrator": "Euler"})
    data["scenarios"]["paper-realistic"].update({"preroll_s": 0.1, "hold_s": 0.1})
    plant = _excited_plant(tmp_path, data, "paper-realistic")
    assert plant["physics_dt_s"] == 0.002
    assert plant["control_period_s"] == 0.004
    assert plant["integrator"] == "Euler"
    assert plant["friction_model"] == PLANT_FRICTION  # frictionloss, no sigmoid
    ran = {"physics_dt_s", "control_period_s", "integrator", "friction_model"}
    assert ran <= {f.name for f in dataclasses.fields(PlantSettings)}  # the episode's names
