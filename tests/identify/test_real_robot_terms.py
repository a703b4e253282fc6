"""The terms a real robot's torque has and a simulation's does not: a torque-sensor offset
per joint, torque sensed on the link side of the gearbox (no rotor inertia in it), and
friction that changes sign smoothly. Each is added to the ideal plant's exact samples
(conftest), and the fit must recover it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.errors import IdentificationError
from pipeline.identify.fit import fitted_transition_speed, identify
from pipeline.identify.model_file import load_model
from pipeline.identify.regressor import OFFSET, PER_JOINT, base_parameters, standard_parameters
from pipeline.identify.samples import JointSamples, joint_samples
from pipeline.identify.stage import fit_command, model_document, validate_command
from pipeline.log.reader import read_recording
from pipeline.robots.loaders import load_spec

OFFSETS_NM = np.array([0.7, -1.2, 0.4, 0.05, -0.3, 0.2])


@pytest.fixture(scope="module")
def exact(ideal_bags: tuple[Path, Path]) -> JointSamples:
    spec = load_spec("ur5")
    return joint_samples(read_recording(ideal_bags[0]), spec, cutoff_hz=0.0)


def test_a_sensor_offset_per_joint_is_fitted(exact: JointSamples) -> None:
    spec = load_spec("ur5")
    fit = identify(spec, [replace(exact, tau_nm=exact.tau_nm + OFFSETS_NM)], min_speed_rad_s=0.0)
    np.testing.assert_allclose(fit.theta[OFFSET::PER_JOINT], OFFSETS_NM, atol=1e-6)
    truth = base_parameters(spec).of(standard_parameters(spec, offset_nm=OFFSETS_NM))
    np.testing.assert_allclose(fit.beta_wls, truth, rtol=1e-6, atol=1e-8)


@pytest.mark.slow
def test_link_side_torque_is_declared_or_detected_and_the_model_says_so(
    exact: JointSamples, tmp_path: Path
) -> None:
    """Torque sensed after the gearbox lacks the rotor's ``armature * qdd``: declared or
    detected, the fit leaves the armature out (keeps the description's) and fits the rest
    exactly; motor-side torque is detected as such."""
    spec = load_spec("ur5")
    link = replace(exact, tau_nm=exact.tau_nm - spec.armature * exact.qdd)
    base = base_parameters(spec, armature=False)
    truth = base.of(standard_parameters(spec))
    for side in ("link", "auto"):
        fit = identify(spec, [link], min_speed_rad_s=0.0, torque_side=side)
        assert fit.torque_side == "link", fit.torque_side_reason
        assert fit.torque_side_reason.startswith("declared" if side == "link" else "detected")
        np.testing.assert_allclose(fit.beta_wls, truth, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(fit.theta[10::PER_JOINT], spec.armature)  # kept
    assert identify(spec, [exact], min_speed_rad_s=0.0, torque_side="auto").torque_side == "motor"
    doc = model_document(spec, fit, [link], method={})
    assert doc["torque_side"] == "link"
    assert "not observable" in doc["identification"]["torque_side"]["armature"]
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert load_model(path).torque_side == "link"


def test_sigmoid_friction_is_fitted_where_coulomb_is_not(exact: JointSamples) -> None:
    spec = load_spec("ur5")
    fc, v_s = np.array([3.0, 3.0, 2.0, 0.8, 0.8, 0.8]), 0.1
    smooth = replace(exact, tau_nm=exact.tau_nm + fc * np.tanh(exact.qd / v_s))
    sigmoid = identify(spec, [smooth], min_speed_rad_s=0.0, transition_speed_rad_s=v_s)
    np.testing.assert_allclose(sigmoid.theta[11::PER_JOINT], fc, rtol=1e-6)
    assert sigmoid.residual_rms_nm.max() < 1e-6
    coulomb = identify(spec, [smooth], min_speed_rad_s=0.0)
    assert coulomb.residual_rms_nm.max() > 1e-3
    # the transition speed, when not stated, is the one the data fit best
    assert fitted_transition_speed(spec, [smooth], min_speed_rad_s=0.0)[0] == v_s


def test_a_transition_speed_per_joint_is_fitted_and_round_trips(
    exact: JointSamples, tmp_path: Path
) -> None:
    """Joints whose friction changes sign over different speeds (a real arm's: Gaz et al.'s
    Panda 0.12-0.39 rad/s): the per-joint search finds each; one common speed cannot fit."""
    spec = load_spec("ur5")
    fc = np.array([3.0, 3.0, 2.0, 0.8, 0.8, 0.8])
    v_s = (0.05, 0.2, 0.1, 0.3, 0.13, 0.07)
    smooth = replace(exact, tau_nm=exact.tau_nm + fc * np.tanh(exact.qd / np.array(v_s)))
    found, _ = fitted_transition_speed(spec, [smooth], min_speed_rad_s=0.0, per_joint=True)
    assert found == v_s
    fit = identify(spec, [smooth], min_speed_rad_s=0.0, transition_speed_rad_s=found)
    np.testing.assert_allclose(fit.theta[11::PER_JOINT], fc, rtol=1e-6)
    common, _ = fitted_transition_speed(spec, [smooth], min_speed_rad_s=0.0)
    one = identify(spec, [smooth], min_speed_rad_s=0.0, transition_speed_rad_s=common)
    assert fit.residual_rms_nm.max() < 1e-6 < one.residual_rms_nm.max()
    doc = model_document(spec, fit, [smooth], method={})
    assert doc["friction"]["transition_speed_rad_s"] == list(v_s)
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert load_model(path).friction.transition_speed_rad_s == v_s
    doc["friction"]["transition_speed_rad_s"] = [0.1, 0.2]  # not one per joint
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(IdentificationError, match=r"transition_speed_rad_s: expected .* 6, one"):
        load_model(path)


@pytest.mark.slow
def test_the_sigmoid_model_file_validates_with_its_own_friction(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    model = tmp_path / "m.yaml"
    fit_command(
        [ideal_bags[0]], out=model, cutoff_hz=0.0, transition_speed_rad_s=0.15,
        torque_side="auto",
    )  # fmt: skip
    m = load_model(model)
    assert (m.friction.model, m.friction.transition_speed_rad_s) == ("sigmoid", 0.15)
    assert m.torque_side == "motor"
    check = validate_command(model, [ideal_bags[1]])
    assert max(check["rms_error_pct"]) < 1e-3


def test_friction_options_are_checked_before_reading() -> None:
    from pipeline.cli.identify_app import _transition_speed
    from pipeline.errors import IdentificationError
    from pipeline.identify.stage import FIT_TRANSITION_SPEED, FIT_TRANSITION_SPEED_PER_JOINT

    assert _transition_speed("sigmoid", None) == 0.1
    assert _transition_speed("sigmoid", "auto") == FIT_TRANSITION_SPEED
    assert _transition_speed("sigmoid", "per-joint") == FIT_TRANSITION_SPEED_PER_JOINT
    assert _transition_speed("sigmoid", "0.05") == 0.05
    assert _transition_speed("coulomb", None) == 0.0
    for friction, text, words in (
        ("coulomb", "0.1", "only with --friction sigmoid"),
        ("sigmoid", "0", "> 0"),
        ("sigmoid", "fast", "auto or per-joint"),
        ("stribeck", None, "--friction: expected one of coulomb, sigmoid"),
    ):
        with pytest.raises(IdentificationError, match=words):
            _transition_speed(friction, text)
