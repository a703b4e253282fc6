"""A controller's own ``plant:``: the same law on two plants in one scenario, recorded side
by side, compared by seed in one report, each bag recording the plant it ran on; a
hand-listed comparison of plants that shares no seed refused in one line."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.stages.controller_study import cli, settings_of
from tests.stages.controller_study import params_file as study_params

SEEDS = (0, 1)
REALISTIC = {
    "frictionloss": [3.0, 3.0, 2.0, 0.8, 0.8, 0.8],
    "damping": [1.0, 1.0, 0.8, 0.3, 0.3, 0.3],
    "uncertainty": {"mass_rel": 0.1, "coulomb_rel": 0.2},
    "payload_kg": 1.0,
}


def params_file(folder: Path, *, seeds: dict[str, tuple[int, ...]] | None = None) -> Path:
    """UR5, short episodes: pid on the scenario's ideal plant and pid on a realistic one."""
    controllers: dict[str, Any] = {
        "pid": {"type": "pid"},
        "pid_real": {"type": "pid", "plant": REALISTIC},
    }
    return study_params(
        folder, controllers=controllers, seeds=seeds or {c: SEEDS for c in controllers}
    )


@pytest.mark.slow
def test_one_controller_on_two_plants_is_compared_by_seed_in_one_report(tmp_path: Path) -> None:
    params = params_file(tmp_path)
    rec = cli("record", "--params", str(params), "--out", str(tmp_path / "rec"), cwd=tmp_path)
    assert rec.returncode == 0, rec.stderr
    for seed in SEEDS:
        ideal = settings_of(tmp_path / "rec" / f"pid-{seed}")
        real = settings_of(tmp_path / "rec" / f"pid_real-{seed}")
        assert "plant" not in ideal["controller"]  # the scenario's: recorded as before
        assert real["controller"]["plant"]["frictionloss"] == REALISTIC["frictionloss"]
        # each bag's scenario and drawn plant are the plant it ran on
        assert ideal["plant"]["exact"] and not real["plant"]["exact"]
        assert real["scenario"]["plant"]["payload_kg"] == 1.0
        assert ideal["scenario"]["plant"]["payload_kg"] == 0.0
        assert ideal["plant"]["frictionloss"] == [0.0] * 6
        assert real["plant"]["frictionloss"] != REALISTIC["frictionloss"]  # drawn per seed
    out = tmp_path / "report"
    rep = cli("report", "--recordings", str(tmp_path / "rec"), "--out", str(out),
              "--baseline", "pid", cwd=tmp_path)  # fmt: skip
    assert rep.returncode == 0, rep.stderr
    text = (out / "report.md").read_text()
    assert "**pid_real vs pid** in `s` (2 seed pairs" in text
    assert "Plant per controller" in text
    assert '- pid_real: its own `plant: {"armature": 0.0, "damping": [1.0, 1.0, 0.8' in text
    assert "- pid: the scenario's `plant: " in text
    # the plants differ on purpose: not a set-up that differs within the group
    assert "Settings differ within this group" not in text


def test_a_comparison_of_plants_sharing_no_seed_is_refused_in_one_line(tmp_path: Path) -> None:
    params = params_file(tmp_path, seeds={"pid": (0, 1), "pid_real": (2, 3)})
    proc = cli("record", "--params", str(params), "--out", str(tmp_path / "rec"), cwd=tmp_path)
    assert proc.returncode != 0
    assert proc.stderr.strip().count("\n") == 0, proc.stderr
    assert "controllers.pid_real.plant: its episodes of scenario s share no seed with pid" in (
        proc.stderr
    )
    assert not (tmp_path / "rec").exists() or not any((tmp_path / "rec").iterdir())


def test_a_controller_plant_of_another_robot_is_refused_naming_the_controller(
    tmp_path: Path,
) -> None:
    data = yaml.safe_load(params_file(tmp_path).read_text())
    data["controllers"]["pid_real"]["plant"] = {"profile": "gaz-panda"}  # a Panda's, on a UR5
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(data))
    proc = cli("record", "--params", "params.yaml", "--out", "rec", cwd=tmp_path)
    assert proc.returncode != 0
    assert proc.stderr.strip().count("\n") == 0, proc.stderr
    assert "controllers.pid_real.plant.profile: gaz-panda describes the Franka" in proc.stderr


def test_a_controller_plant_is_kept_by_a_campaign_and_unused_dumps_as_before(
    tmp_path: Path,
) -> None:
    from pipeline.params import load_params
    from pipeline.stages.campaign_expand import expand

    data = yaml.safe_load(params_file(tmp_path).read_text())
    data["campaigns"] = {"c": {"scenario": "s", "controllers": ["pid", "pid_real"], "seeds": 2}}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(data))
    params = load_params(tmp_path / "params.yaml")
    episodes = {e.controller_name: e for e in expand(params, "c")}
    assert episodes["pid_real"].scenario.plant.payload_kg == 1.0
    assert episodes["pid"].scenario.plant.payload_kg == 0.0
    assert episodes["pid"].scenario == params.scenarios["s"]
    # a controller without one dumps (and fingerprints) as before the field existed
    assert "plant" not in episodes["pid"].controller.model_dump()
    # a sweep of the scenario's plant would not reach the controller's own: refused
    data["campaigns"]["c"]["sweep"] = {"plant.payload_kg": [0.0, 0.5]}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(data))
    from pipeline.errors import ParamsError

    with pytest.raises(ParamsError, match=r"sweeps plant.payload_kg, but controller pid_real"):
        expand(load_params(tmp_path / "params.yaml"), "c")


@pytest.mark.parametrize(
    ("owner", "plant", "expected"),
    [
        ("pid_real", {"profile": "gaz-panda"}, "controllers.pid_real.plant.profile: gaz-panda "),
        (
            "pid_real",
            {"uncertainty": {"transition_rel": 0.2}},
            "controllers.pid_real.plant.uncertainty.transition_rel: 0.2 spreads",
        ),
        ("s", {"profile": "gaz-panda"}, "scenarios.s.plant.profile: gaz-panda "),
    ],
)
def test_the_episode_runner_names_whose_plant_it_refuses(
    tmp_path: Path, owner: str, plant: dict[str, Any], expected: str
) -> None:
    """The runner's own check (an episode handed to a worker as it is, the record stage's
    check aside) names the field the plant is set in: a controller's own ``plant:`` or
    its scenario's."""
    from pipeline.params import load_params
    from pipeline.stages.episode import run_one
    from pipeline.stages.plans import plan_scenario

    data = yaml.safe_load(params_file(tmp_path).read_text())
    if owner == "s":
        data["scenarios"]["s"]["plant"] = plant
    else:
        data["controllers"][owner]["plant"] = plant
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(data))
    params = load_params(tmp_path / "params.yaml")
    controller = "pid" if owner == "s" else owner
    episode = next(e for e in params.episodes if e.controller_name == controller)
    plan = plan_scenario("s", episode.scenario, params.source)
    outcome = run_one(episode, plan, out_dir=tmp_path / "rec", force=False, commit="test")
    assert outcome.status == "failed"
    assert outcome.reason.startswith(expected), outcome.reason
    assert not (tmp_path / "rec" / episode.name).exists()
