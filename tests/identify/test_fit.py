"""Identification round trips on the ideal plant, the model file, and the physical check."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.errors import IdentificationError
from pipeline.identify.fit import identify, violations
from pipeline.identify.model_file import load_model
from pipeline.identify.regressor import PER_JOINT, standard_parameters
from pipeline.identify.samples import joint_samples
from pipeline.identify.stage import fit_command, validate_command
from pipeline.log.reader import read_recording
from pipeline.robots.loaders import load_spec


def test_exact_round_trip_recovers_the_base_parameters(ideal_bags: tuple[Path, Path]) -> None:
    """Noise-free data, unfiltered: the recorded velocity and its forward difference are
    the plant's own semi-implicit Euler step, so the model holds to rounding."""
    spec = load_spec("ur5")
    samples = joint_samples(read_recording(ideal_bags[0]), spec, cutoff_hz=0.0)
    fit = identify(spec, [samples])
    truth = fit.base.of(standard_parameters(spec))  # the ideal plant is the CAD model
    # relative to each parameter, with a floor of 1e-3 for the true zeros (friction)
    rel = np.abs(fit.beta_wls - truth) / np.maximum(np.abs(truth), 1e-3)
    assert rel.max() < 1e-6, fit.base.names[int(np.argmax(rel))]
    np.testing.assert_allclose(fit.beta, truth, rtol=1e-6, atol=1e-9)
    assert not violations(spec, fit.theta)


def test_filtered_round_trip_predicts_another_recording(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    """The default 5 Hz zero-phase filter and central differences are not the plant's
    Euler step (velocity lags half a step): the model is then good to well below 1 % of
    the torque, not to rounding."""
    model = tmp_path / "model.yaml"
    summary = fit_command([ideal_bags[0]], out=model)
    assert summary["base_parameters"] == 58
    check = validate_command(model, [ideal_bags[1]], figure=tmp_path / "fig.png")
    assert max(check["rms_error_pct"][:3]) < 1.0, check["rms_error_pct"]
    assert (tmp_path / "fig.png").stat().st_size > 10_000


def test_model_file_records_the_stuck_row_rule_it_was_fitted_with(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    """A filtered fit's ``method`` names the stuck-row rule with its numbers, and those
    numbers, applied to the samples by hand, give the fit's equation count; an unfiltered
    fit (no low-pass to spread a stuck sample) records no such rule."""
    spec = load_spec("ur5")
    filtered = tmp_path / "filtered.yaml"
    fit_command([ideal_bags[0]], out=filtered)
    method = load_model(filtered).identification["method"]
    rule = method["stuck_rows"]
    assert (rule["speed_rad_s"], rule["max_share"]) == (1e-3, 0.01)
    assert "left out of fit and validate" in rule["rule"]
    samples = joint_samples(
        read_recording(ideal_bags[0]), spec, cutoff_hz=method["filter"]["cutoff_hz"]
    )
    share = samples.stuck_share(rule["speed_rad_s"])
    assert share is not None
    kept = (np.abs(samples.qd) >= method["min_speed_rad_s"]) & (share < rule["max_share"])
    assert (share >= rule["max_share"]).any()  # the rule leaves rows out here
    assert load_model(filtered).identification["equations"] == int(kept.sum())
    unfiltered = tmp_path / "unfiltered.yaml"
    fit_command([ideal_bags[0]], out=unfiltered, cutoff_hz=0.0)
    assert "stuck_rows" not in load_model(unfiltered).identification["method"]


def test_model_file_is_a_loadable_robot_with_provenance(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    model_path = tmp_path / "model.yaml"
    fit_command([ideal_bags[0]], out=model_path, cutoff_hz=0.0)
    model = load_model(model_path)
    spec = load_spec("ur5")
    assert model.spec.joint_names == spec.joint_names
    ident = model.identification
    recording = read_recording(ideal_bags[0])
    assert ident["recordings"][0]["sha256"] == recording.sha256
    assert ident["condition_number"] > 1
    assert all(p["std_error"] >= 0 for p in ident["base_parameters"])
    # the identified robot's shoulder-lift mass moment equals the CAD one (ideal plant)
    theta = standard_parameters(model.spec)
    cad = standard_parameters(spec)
    k = PER_JOINT + 1  # shoulder_lift m*c_x, identifiable
    assert theta[k] == pytest.approx(cad[k], rel=1e-6)
    assert model.friction.coulomb_nm == pytest.approx((0.0,) * 6, abs=1e-6)


def test_consistency_check_rejects_a_non_physical_set() -> None:
    spec = load_spec("ur5")
    theta = standard_parameters(spec)
    assert violations(spec, theta) == []
    bad = theta.copy()
    bad[PER_JOINT * 2 + 4 : PER_JOINT * 2 + 10] *= -1  # elbow: negative inertia
    bad[PER_JOINT * 3 + 11] = -0.5  # wrist 1: negative Coulomb friction
    problems = violations(spec, bad)
    assert any(p.startswith("elbow_joint: link pseudo-inertia") for p in problems)
    assert any(p.startswith("wrist_1_joint.fc") for p in problems)


def test_a_model_file_of_another_format_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump({"format": "something/9"}))
    with pytest.raises(IdentificationError, match=r"m.yaml: format: expected"):
        load_model(path)
