"""An episode on the published Panda plant (``plant.profile: gaz-panda``) runs, records
the profile and what it drew, and is reproduced by its seed; the same friction draws and
torque-sensor errors work on the UR5's realistic plant."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.errors import ModelError, ParamsError
from pipeline.experiment.assemble import draw_scenario_plant, scenario_friction
from pipeline.log.reader import read_recording
from pipeline.params import parse_params
from pipeline.robots import load_spec
from pipeline.robots.packages import package_search_path
from pipeline.stages.record import record, validate_episodes

REPO = Path(__file__).parents[2]
EXAMPLE = REPO / "examples" / "params-panda-gaz.yaml"
pytestmark = pytest.mark.skipif(
    not any((p / "example-robot-data").is_dir() for p in package_search_path()),
    reason="example-robot-data is not installed",
)


def _params(episodes: dict[str, dict[str, object]], **plant: object):
    data = yaml.safe_load(EXAMPLE.read_text())
    for s in data["scenarios"].values():
        s.update(preroll_s=0.1, hold_s=0.1, hold_max_s=0.1)
        s["plant"].update(plant)
    data["episodes"] = episodes
    return parse_params(data, source=str(EXAMPLE))


def _column(rec, name: str) -> np.ndarray:
    """One column of the joint states, (samples, joints)."""
    return rec.samples.get_column(name).to_numpy().reshape(-1, len(rec.joint_names))


def test_a_short_episode_on_the_published_plant_records_the_profile(tmp_path):
    params = _params(
        {
            "a": {"scenario": "panda-gaz", "controller": "ctc", "seed": 4},
            "b": {"scenario": "panda-gaz", "controller": "ctc", "seed": 4},
        }
    )
    outcomes = record(params, params.episodes, out_dir=tmp_path, commit="test")
    assert [o.status for o in outcomes] == ["ok", "ok"]
    rec = read_recording(tmp_path / "a")
    plant = rec.settings.plant
    assert plant.profile.startswith("gaz-panda: Gaz et al., IEEE RA-L 2019")
    assert "sigmoid" in plant.friction_model
    assert not plant.exact
    spec = load_spec("panda")
    drawn = scenario_friction(spec, params.scenarios["panda-gaz"], seed=4)
    assert plant.sigmoid_friction is not None
    assert plant.sigmoid_friction.phi1_nm == drawn.sigmoid.phi1_nm
    assert plant.sigmoid_friction.phi2_s_rad == drawn.sigmoid.phi2_s_rad
    assert plant.effort_offset_nm == drawn.effort_offset_nm and len(drawn.effort_offset_nm) == 7
    assert plant.effort_noise_std_nm == 0.05
    assert 0 < plant.payload_kg <= 0.5
    # the plant's links are the published ones; the controllers' nominal is the URDF's
    assert plant.links[3].mass == 3.587895
    # same params, same seed: the same bytes (a second episode key, same settings but its
    # name: compare the joint states instead of the files)
    other = read_recording(tmp_path / "b")
    for column in ("position_rad", "effort_nm"):
        np.testing.assert_array_equal(_column(rec, column), _column(other, column))


def test_the_recorded_effort_carries_the_sensors_offset_and_noise(tmp_path):
    params = _params(
        {
            "exact": {"scenario": "panda-gaz", "controller": "pid", "seed": 1},
        },
        effort_offset_nm=0.0,
        effort_noise_std_nm=0.0,
    )
    sensed = _params(
        {"exact": {"scenario": "panda-gaz", "controller": "pid", "seed": 1}},
        effort_offset_nm=0.2,
        effort_noise_std_nm=0.05,
    )
    record(params, params.episodes, out_dir=tmp_path / "p", commit="test")
    record(sensed, sensed.episodes, out_dir=tmp_path / "s", commit="test")
    exact = read_recording(tmp_path / "p" / "exact")
    noisy = read_recording(tmp_path / "s" / "exact")
    efforts = [_column(r, "effort_nm") for r in (exact, noisy)]
    # the sensor changes only what is recorded: the motion is the same
    np.testing.assert_array_equal(_column(exact, "position_rad"), _column(noisy, "position_rad"))
    error = efforts[1] - efforts[0]
    offset = np.array(noisy.settings.plant.effort_offset_nm)
    assert np.abs(error.mean(axis=0) - offset).max() < 0.01
    assert error.std(axis=0) == pytest.approx(np.full(7, 0.05), rel=0.1)


def test_same_seed_same_plant_other_seed_other_plant():
    params = _params({"a": {"scenario": "ur5-draws", "controller": "pid"}})
    spec = load_spec("ur5")
    scenario = params.scenarios["ur5-draws"]
    draws = [scenario_friction(spec, scenario, seed=s) for s in (3, 3, 4)]
    assert draws[0] == draws[1]
    assert draws[0].frictionloss != draws[2].frictionloss
    assert draws[0].damping != draws[2].damping
    assert draws[0].effort_offset_nm != draws[2].effort_offset_nm
    given = np.array([3.0, 3.0, 2.0, 0.8, 0.8, 0.8])
    ratio = np.array(draws[0].frictionloss) / given
    assert np.all((ratio >= 0.8) & (ratio <= 1.2)) and np.ptp(ratio) > 0  # per joint
    plants = [draw_scenario_plant(spec, scenario, seed=s) for s in (3, 3)]
    assert plants[0][0] == plants[1][0] and plants[0][1] == plants[1][1]


def test_friction_draws_leave_the_link_draws_of_a_seed_alone():
    """The friction, payload and sensor draws have their own stream: turning them on does
    not change the links an existing scenario draws for a seed."""
    spec = load_spec("ur5")
    with_draws = _params({"a": {"scenario": "ur5-draws", "controller": "pid"}})
    data = yaml.safe_load(EXAMPLE.read_text())
    data["episodes"] = {"a": {"scenario": "ur5-draws", "controller": "pid"}}
    u = data["scenarios"]["ur5-draws"]["plant"]["uncertainty"]
    for key in ("coulomb_rel", "viscous_rel", "payload_kg"):
        u.pop(key)
    without = parse_params(data, source="x")
    a = draw_scenario_plant(spec, with_draws.scenarios["ur5-draws"], seed=2)[0]
    b = draw_scenario_plant(spec, without.scenarios["ur5-draws"], seed=2)[0]
    assert a == b


def test_a_transition_spread_without_a_sigmoid_is_refused_in_one_line():
    params = _params({"a": {"scenario": "ur5-draws", "controller": "pid"}})
    scenario = params.scenarios["ur5-draws"]
    plant = scenario.plant.model_copy(
        update={"uncertainty": dataclasses.replace(scenario.plant.uncertainty, transition_rel=0.2)}
    )
    with pytest.raises(ModelError) as err:
        scenario_friction(load_spec("ur5"), scenario.model_copy(update={"plant": plant}), seed=0)
    assert "\n" not in str(err.value)
    assert str(err.value).startswith("plant.uncertainty.transition_rel: 0.2 spreads a sigmoid")


def test_a_profile_on_the_ur5_is_refused_naming_the_scenario(tmp_path):
    params = _params({"a": {"scenario": "ur5-draws", "controller": "pid"}}, profile="gaz-panda")
    with pytest.raises(ParamsError) as err:  # before any work (pipeline record, --check)
        validate_episodes(params, params.episodes)
    message = str(err.value)
    assert message.startswith(f"{EXAMPLE}: scenarios.ur5-draws.plant.profile: gaz-panda describes")
    assert "\n" not in message
    outcomes = record(params, params.episodes, out_dir=tmp_path, commit="test")
    assert outcomes[0].status == "failed"  # and the episode alone, if called without it
    assert "scenarios.ur5-draws.plant.profile: gaz-panda describes the Franka" in outcomes[0].reason
