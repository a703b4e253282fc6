from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from pipeline.errors import ParamsError
from pipeline.params import load_params
from pipeline.settings import LoopSettings

REPO = Path(__file__).parents[1]


def _default() -> dict:
    return yaml.safe_load((REPO / "params.yaml").read_text())


def _write(tmp_path: Path, data: object) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_default_params_hold_the_papers_scenario_under_pid_and_ctc():
    params = load_params(REPO / "params.yaml")
    names = [e.name for e in params.episodes]
    assert names[:2] == ["paper-pid", "paper-ctc"]
    paper = params.scenarios["paper"]
    assert paper.reproduces_paper and params.scenarios["paper-realistic"].reproduces_paper
    # the realistic plant differs from the nominal model, with seeds for an interval
    real = params.scenarios["paper-realistic"]
    assert real.plant.uncertainty.mass_rel > 0 and real.goal == paper.goal
    from pipeline.stages.campaign_expand import expand

    realistic = expand(params, "paper-realistic")
    for controller in ("pid", "ctc", "ctc_pid"):
        seeds = {e.seed for e in realistic if e.scenario_name == "paper-realistic"
                 and e.controller_name == controller}  # fmt: skip
        assert len(seeds) >= 5
    assert paper.robot == "ur5"
    assert paper.start == [0.0] * 6
    assert paper.goal.joints == [-0.15, -0.5, 0.785, -1.15, -0.3925, 0.0]
    assert {"pid", "ctc"} <= {e.controller.type for e in params.episodes}


@pytest.mark.parametrize(
    ("mutate", "expected"),
    [
        (
            lambda d: d["episodes"]["paper-ctc"].update(controller="lqr"),
            r"episodes\.paper-ctc\.controller: unknown controller 'lqr'; "
            r"valid: ctc, ctc_pid, pid",
        ),
        (
            lambda d: d["episodes"]["paper-ctc"].update(scenario="nope"),
            r"episodes\.paper-ctc\.scenario: unknown scenario 'nope'",
        ),
        (
            lambda d: d["scenarios"]["paper"]["timing"].update(velocity_scaling=1.5),
            r"scenarios\.paper\.timing\.velocity_scaling: .*less than or equal to 1",
        ),
        (
            lambda d: d["scenarios"]["paper"]["plant"].update(payload_kg=-1),
            r"scenarios\.paper\.plant\.payload_kg: .*greater than or equal to 0",
        ),
        (
            lambda d: d["scenarios"]["paper"]["goal"].update(
                pose={"position": [0.3, 0.1, 0.4], "rpy": [0, 0, 0]}
            ),
            r"scenarios\.paper\.goal: .*exactly one of joints or pose",
        ),
        (
            lambda d: d["scenarios"]["paper"].update(hold="1s"),
            r"scenarios\.paper\.hold: Extra inputs are not permitted",
        ),
        (
            lambda d: d["sim"].update(physics_dt_s=0.0),
            r"sim\.physics_dt_s: .*greater than or equal to 1e-05|0.00001",
        ),
        (
            lambda d: d["episodes"].update(
                {"bad/name": {"scenario": "paper", "controller": "pid"}}
            ),
            r"episode names are directory names",
        ),
    ],
)
def test_bad_params_name_the_field(tmp_path, mutate, expected):
    data = _default()
    mutate(data)
    path = _write(tmp_path, data)
    with pytest.raises(ParamsError, match=expected) as err:
        load_params(path)
    assert str(err.value).startswith(f"{path}: ")


def test_unknown_only_episode_lists_the_known_ones():
    params = load_params(REPO / "params.yaml")
    with pytest.raises(
        ParamsError, match=r"unknown episode 'paper-lqr' .*; valid: paper-pid, paper-ctc$"
    ):
        params.select(["paper-lqr"])


def test_missing_params_file_says_how_to_fix(tmp_path):
    with pytest.raises(ParamsError, match=r"no such params file \(pass --params PATH\)"):
        load_params(tmp_path / "nope.yaml")


@pytest.mark.parametrize("path", sorted((REPO / "examples").glob("*.yaml")), ids=lambda p: p.name)
def test_shipped_example_params_are_valid_and_runnable(path):
    from pipeline.stages.record import validate_episodes

    params = load_params(path)
    validate_episodes(params, params.episodes)


def test_pid_flag_gain_from_params_reaches_the_controller(tmp_path):
    from pipeline.stages.record import validate_episodes

    data = _default()
    data["controllers"]["pid"]["gains"]["antiwindup"] = False
    params = load_params(_write(tmp_path, data))
    assert params.controllers["pid"].gains["antiwindup"] is False
    validate_episodes(params, params.episodes)


@pytest.mark.parametrize("key", ["damping", "frictionloss", "armature"])
@pytest.mark.parametrize("value", [-1.0, [0.0, 0.0, -0.1, 0.0, 0.0, 0.0]])
def test_negative_plant_mismatch_is_refused_with_the_field(tmp_path, key, value):
    data = _default()
    data["scenarios"]["paper"]["plant"][key] = value
    with pytest.raises(
        ParamsError, match=rf"scenarios\.paper\.plant\.{key}(\[2\])?: .*greater than or equal to 0"
    ):
        load_params(_write(tmp_path, data))


def test_repeated_only_runs_the_episode_once():
    params = load_params(REPO / "params.yaml")
    assert [e.name for e in params.select(["paper-ctc", "paper-ctc"])] == ["paper-ctc"]


def test_params_path_that_is_a_directory_says_so(tmp_path):
    with pytest.raises(ParamsError, match=r"is a directory, expected a params YAML file"):
        load_params(tmp_path)


def test_a_scenario_loop_is_validated_and_defaults_to_the_ideal_loop(tmp_path):
    params = load_params(REPO / "params.yaml")
    assert params.scenarios["paper"].loop == LoopSettings()  # the recorded type itself
    assert params.scenarios["paper"].model_dump()["loop"] == {
        f.name: f.default for f in dataclasses.fields(LoopSettings)
    }  # every declared field at its default (a new one needs no edit here)
    data = _default()
    data["scenarios"]["paper"]["loop"] = {"delay_s": 0.001, "velocity": "observer"}
    with pytest.raises(ParamsError, match=r"scenarios\.paper\.loop\.velocity: Input should be"):
        load_params(_write(tmp_path, data))


def test_encoder_velocity_beside_independent_velocity_noise_is_refused(tmp_path):
    data = _default()
    data["scenarios"]["paper-realistic"]["loop"] = {"velocity": "encoder"}
    with pytest.raises(
        ParamsError, match=r"scenarios\.paper-realistic: .*plant\.velocity_noise_std_rad_s"
    ):
        load_params(_write(tmp_path, data))


def test_a_delay_off_the_physics_step_grid_is_refused_before_any_work(tmp_path):
    from pipeline.stages.record import validate_episodes

    data = _default()
    data["scenarios"]["paper"]["loop"] = {"delay_s": 0.00025}
    params = load_params(_write(tmp_path, data))
    with pytest.raises(
        ParamsError,
        match=r"scenarios\.paper\.loop\.delay_s: 0\.00025 s is not a whole number of physics "
        r"steps of 0\.0005 s",
    ):
        validate_episodes(params, params.episodes)


def test_the_delay_can_be_swept_by_a_campaign(tmp_path):
    from pipeline.stages.campaign_expand import expand

    data = _default()
    data["campaigns"]["paper-realistic"]["sweep"] = {"loop.delay_s": [0.0, 0.002]}
    params = load_params(_write(tmp_path, data))
    episodes = expand(params, "paper-realistic")
    assert {e.scenario.loop.delay_s for e in episodes} == {0.0, 0.002}
    assert "delay_s-0.002.pid.s0" in {e.name for e in episodes}


def test_the_controller_study_is_a_valid_params_file_outside_the_demo():
    """studies/controllers.yaml: the six laws x 20 seeds x {0, 1 ms}; not in params.yaml,
    whose campaigns are all DVC stages of `make demo`."""
    from pipeline.stages.campaign_expand import expand
    from pipeline.stages.record import validate_episodes

    study = load_params(REPO / "studies" / "controllers.yaml")
    episodes = expand(study, "controllers-delay")
    assert len(episodes) == 6 * 20 * 2
    validate_episodes(study, episodes[::20])
    assert "controllers-delay" not in load_params(REPO / "params.yaml").campaigns


def test_the_default_integrator_is_the_plant_s():
    from pipeline.constants import PLANT_INTEGRATOR
    from pipeline.params import SimParams

    assert SimParams().integrator == PLANT_INTEGRATOR


def test_a_relative_robot_path_is_read_from_the_params_files_folder(tmp_path, monkeypatch):
    """As a user keeps arm.urdf beside params.yaml and runs from anywhere."""
    folder = tmp_path / "cell"
    folder.mkdir()
    (folder / "arm.yaml").write_text((REPO / "pipeline" / "robots" / "ur5.yaml").read_text())
    data = _default()
    data["scenarios"]["paper"]["robot"] = "arm.yaml"
    path = _write(folder, data)
    monkeypatch.chdir(tmp_path)
    params = load_params(path)
    robot = params.scenarios["paper"].robot
    assert Path(robot).resolve() == (folder / "arm.yaml").resolve()
    monkeypatch.chdir(folder)  # run from its own folder: the text as written
    assert load_params(path).scenarios["paper"].robot == "arm.yaml"


def test_a_missing_robot_file_names_the_field_and_the_folder(tmp_path):
    data = _default()
    data["scenarios"]["paper"]["robot"] = "arms/nope.urdf"
    with pytest.raises(ParamsError) as err:
        load_params(_write(tmp_path, data))
    message = str(err.value)
    assert "scenarios.paper.robot: no such robot file 'arms/nope.urdf'" in message
    assert str(tmp_path) in message and "\n" not in message
