"""A URDF's ``<dynamics damping friction>``: the plant's joint friction where nothing more
specific gives it (sidecar over URDF, scenario over both), and the settings name the source."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.errors import SpecError
from pipeline.experiment.assemble import draw_scenario_plant, scenario_spec
from pipeline.model.mjcf import build_mujoco_model
from pipeline.params import ScenarioParams
from pipeline.robots import load_spec
from tests.robots.test_urdf_loader import THREE_JOINT

# j1 states both, j2 damping only, j3 nothing (0)
DYNAMICS = {
    "<limit lower=\"-3\" upper=\"3\" velocity=\"2\" effort=\"50\"/>":
        '<dynamics damping="0.5" friction="0.2"/>',
    "<limit lower=\"-2\" upper=\"2\" velocity=\"2\" effort=\"30\"/>": '<dynamics damping="0.7"/>',
}  # fmt: skip
DAMPING = (0.5, 0.7, 0.0)
FRICTION = (0.2, 0.0, 0.0)


def _robot(tmp_path: Path, sidecar: str | None = None, dynamics: dict[str, str] = DYNAMICS) -> str:
    text = THREE_JOINT
    for limit, extra in dynamics.items():
        assert limit in text
        text = text.replace(limit, limit + extra)
    path = tmp_path / "three.urdf"
    path.write_text(text)
    if sidecar is not None:
        (tmp_path / "three.armlab.yaml").write_text(sidecar)
    return str(path)


def _scenario(robot: str, plant: dict[str, Any]) -> ScenarioParams:
    return ScenarioParams.model_validate(
        {"robot": robot, "start": [0.0, 0.0, 0.0], "goal": {"joints": [0.1, 0.1, 0.1]},
         "plant": plant}
    )  # fmt: skip


def _plant_friction(scenario: ScenarioParams) -> tuple[np.ndarray, np.ndarray, dict[str, str]]:
    """The compiled plant's dof_damping and dof_frictionloss, and the recorded sources."""
    spec = scenario_spec(scenario)
    plant_spec, plant, _ = draw_scenario_plant(spec, scenario, seed=0)
    model = build_mujoco_model(plant_spec, plant=plant)
    sources = dict(spec.settings_sources)
    return model.dof_damping.copy(), model.dof_frictionloss.copy(), sources


def test_urdf_dynamics_are_the_plants_friction_and_the_settings_say_so(tmp_path):
    damping, friction, sources = _plant_friction(_scenario(_robot(tmp_path), {}))
    np.testing.assert_array_equal(damping, DAMPING)
    np.testing.assert_array_equal(friction, FRICTION)
    assert sources["damping"] == sources["frictionloss"] == "URDF <dynamics>"


def test_the_scenario_plant_overrides_the_urdf_and_the_settings_say_so(tmp_path):
    scenario = _scenario(_robot(tmp_path), {"damping": [1.0, 2.0, 3.0]})
    damping, friction, sources = _plant_friction(scenario)
    np.testing.assert_array_equal(damping, (1.0, 2.0, 3.0))
    np.testing.assert_array_equal(friction, FRICTION)  # not given: still the URDF's
    assert sources["damping"] == "scenario plant.damping (the robot's: URDF <dynamics>)"
    assert sources["frictionloss"] == "URDF <dynamics>"
    # an explicit 0 is given too: the nominal plant, whatever the URDF states
    damping, friction, _ = _plant_friction(
        _scenario(_robot(tmp_path), {"damping": 0.0, "frictionloss": 0.0})
    )
    assert not damping.any() and not friction.any()


def test_the_sidecar_overrides_the_urdf_dynamics(tmp_path):
    robot = _robot(tmp_path, sidecar="frictionloss: [0.1, 0.3, 0.4]\n")
    damping, friction, sources = _plant_friction(_scenario(robot, {}))
    np.testing.assert_array_equal(damping, DAMPING)
    np.testing.assert_array_equal(friction, (0.1, 0.3, 0.4))
    assert sources["frictionloss"] == str(tmp_path / "three.armlab.yaml")
    assert sources["damping"] == "URDF <dynamics>"


def test_a_urdf_without_dynamics_keeps_the_scenarios_default(tmp_path):
    robot = _robot(tmp_path, dynamics={})
    spec = load_spec(robot)
    assert dict(spec.settings_sources)["damping"] == "not stated (0)"
    damping, friction, _ = _plant_friction(_scenario(robot, {}))
    assert not damping.any() and not friction.any()


def test_a_campaign_keeps_the_robots_friction_where_its_scenario_gives_none(tmp_path):
    from pipeline.params import parse_params
    from pipeline.stages.campaign_expand import expand

    robot = _robot(tmp_path)
    params = parse_params(
        {
            "scenarios": {"s": {"robot": robot, "start": [0.0, 0.0, 0.0],
                                "goal": {"joints": [0.1, 0.1, 0.1]}}},
            "controllers": {"pid": {"type": "pid"}},
            "campaigns": {"c": {"scenario": "s", "controllers": ["pid"], "seeds": 1,
                                "sweep": {"plant.payload_kg": [0.0, 0.5]}}},
        },
        source="p.yaml",
    )  # fmt: skip
    for episode in expand(params, "c"):
        damping, friction, _ = _plant_friction(episode.scenario)
        np.testing.assert_array_equal(damping, DAMPING)
        np.testing.assert_array_equal(friction, FRICTION)


def test_builtin_robots_state_no_friction_but_the_panda():
    for name in ("ur5", "ur10", "arm3_example", "panda_dh"):
        spec = load_spec(name)
        assert not any(spec.damping) and not any(spec.frictionloss), name


@pytest.mark.parametrize(
    ("dynamics", "says"),
    [
        ('<dynamics damping="-1"/>', "dynamics damping -1.0 must be >= 0"),
        ('<dynamics friction="x"/>', "dynamics.friction: expected 1 finite numbers"),
    ],
)
def test_bad_dynamics_are_one_line_naming_the_joint(tmp_path, dynamics, says):
    limit = next(iter(DYNAMICS))
    robot = _robot(tmp_path, dynamics={limit: dynamics})
    with pytest.raises(SpecError, match="joint 'j1'") as err:
        load_spec(robot)
    assert says in str(err.value) and "\n" not in str(err.value)


def test_a_sidecar_velocity_replaces_the_urdfs_and_says_so(tmp_path):
    spec = load_spec(_robot(tmp_path, sidecar="velocity: [1.0, 1.5, 2.5]\n"))
    assert spec.velocity_limits.tolist() == [1.0, 1.5, 2.5]  # the URDF's: 2, 2, 3
    assert dict(spec.settings_sources)["velocity"] == str(tmp_path / "three.armlab.yaml")
