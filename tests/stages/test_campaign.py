"""Campaign expansion: deterministic, stable keys, seeded draws, validated at the edge."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from pipeline.errors import ParamsError
from pipeline.params import load_params, parse_params
from pipeline.stages.campaign_expand import campaign_axes, episode_fingerprint, expand

REPO = Path(__file__).parents[2]


def _base() -> dict[str, Any]:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["campaigns"], data["extra_campaigns"] = {}, {}
    return data


def _params(campaign: dict[str, Any], data: dict[str, Any] | None = None) -> Any:
    data = copy.deepcopy(data or _base())
    data["campaigns"]["c"] = campaign
    return parse_params(data, source="p.yaml")


SWEEP = {
    "scenario": "paper-realistic",
    "controllers": ["pid", "ctc"],
    "seeds": 2,
    "sweep": {"plant.payload_kg": [0.0, 0.5], "gains.omega_n_rad_s": [30, 40]},
}


def test_expansion_is_the_full_product_with_keys_from_the_values():
    episodes = expand(_params(SWEEP), "c")
    assert len(episodes) == 2 * 2 * 2 * 2
    names = [e.name for e in episodes]
    assert len(set(names)) == len(names)
    assert "payload_kg-0.5.omega_n_rad_s-30.ctc.s1" in names
    e = next(e for e in episodes if e.name == "payload_kg-0.5.omega_n_rad_s-30.ctc.s1")
    assert e.scenario.plant.payload_kg == 0.5 and e.seed == 1 and e.controller_name == "ctc"
    assert e.campaign is not None
    assert e.campaign.condition == "payload_kg=0.5,omega_n_rad_s=30"
    assert dict(e.campaign.swept) == {
        "controller": "ctc",
        "seed": 1,
        "plant.payload_kg": 0.5,
        "gains.omega_n_rad_s": 30.0,
    }
    # the rest of the scenario is the base scenario's
    base = _params(SWEEP).scenarios["paper-realistic"]
    assert e.scenario.plant.frictionloss == base.plant.frictionloss
    assert e.scenario.goal == base.goal


def test_expansion_is_deterministic_and_keys_survive_an_added_value():
    first = expand(_params(SWEEP), "c")
    again = expand(_params(SWEEP), "c")
    assert first == again
    grown = copy.deepcopy(SWEEP)
    grown["sweep"]["plant.payload_kg"] = [0.0, 0.25, 0.5]
    grown["seeds"] = [0, 1, 7]
    more = {e.name: e for e in expand(_params(grown), "c")}
    # every old episode keeps its key and exactly its settings (so resume skips it)
    for e in first:
        assert more[e.name] == e
        assert episode_fingerprint(more[e.name], commit="x") == episode_fingerprint(e, commit="x")
    assert len(more) == 3 * 2 * 2 * 3


def test_random_draws_are_seeded_per_index_so_more_draws_keep_the_first():
    few = dict(SWEEP, sweep={"plant.frictionloss": {"uniform": [0.5, 2.0], "n": 3, "seed": 4}})
    many = dict(SWEEP, sweep={"plant.frictionloss": {"uniform": [0.5, 2.0], "n": 6, "seed": 4}})
    a = campaign_axes(_params(few), "c").axes[0].values
    b = campaign_axes(_params(many), "c").axes[0].values
    assert b[:3] == a and len(set(b)) == 6
    assert all(0.5 <= float(v) <= 2.0 for v in b)
    other = dict(SWEEP, sweep={"plant.frictionloss": {"uniform": [0.5, 2.0], "n": 3, "seed": 5}})
    assert campaign_axes(_params(other), "c").axes[0].values != a


def test_random_goals_are_within_limits_the_region_and_clear_of_an_obstacle():
    from pipeline.model.scene import Box
    from pipeline.robots.loaders import load_spec
    from pipeline.sim.safety import assess_execution

    data = _base()
    # a box next to the paper's goal pose: some draws in the region hit it
    data["scenarios"]["boxed"] = copy.deepcopy(data["scenarios"]["paper"])
    data["scenarios"]["boxed"]["obstacles"] = [
        {"name": "box", "center": [0.45, -0.05, 0.35], "half_size": [0.08, 0.08, 0.08]}
    ]
    params = _params(
        {"scenario": "boxed", "controllers": ["pid"],
         "goals": {"random": 8, "seed": 3, "radius_rad": 0.6}},
        data,
    )  # fmt: skip
    axis = campaign_axes(params, "c").axes[0]
    assert axis.values == tuple(f"r{i}" for i in range(8))
    spec = load_spec("ur5")
    base = np.array(data["scenarios"]["boxed"]["goal"]["joints"])
    box = Box("box", (0.45, -0.05, 0.35), (0.08, 0.08, 0.08))
    for q in axis.goals:
        assert np.all(np.abs(np.array(q) - base) <= 0.6)
        assert np.all(np.array(q) >= spec.lower) and np.all(np.array(q) <= spec.upper)
        # an independent check (exact robot-box distances of the execution safety code)
        safety = assess_execution(spec, q=np.array([q]), stamp_ns=np.array([0]), obstacles=[box])
        assert not safety.touched and safety.min_clearance_m > 0
    episodes = expand(params, "c")
    assert [e.scenario.goal.joints for e in episodes] == [list(q) for q in axis.goals]
    assert episodes[0].name == "goal-r0.pid.s0"


def test_a_swept_tuning_knob_replaces_the_explicit_gains_it_derives():
    from pipeline.control import make_controller
    from pipeline.robots.loaders import load_spec

    episodes = expand(_params(SWEEP), "c")
    ctc = next(e for e in episodes if e.controller_name == "ctc" and e.campaign
               and e.campaign.swept["gains.omega_n_rad_s"] == 30)  # fmt: skip
    assert "kp" not in ctc.controller.gains  # params.yaml gives ctc explicit kp/kd
    gains = make_controller("ctc", load_spec("ur5"), ctc.controller.gains).gains_in_effect()
    assert gains["kp"] == pytest.approx([30.0**2] * 6)  # CTC's poles: kp = w^2, kd = 2 zeta w
    assert gains["kd"] == pytest.approx([2 * 30.0] * 6)


def test_default_campaign_replaces_the_hand_listed_realistic_seeds():
    params = load_params(REPO / "params.yaml")
    episodes = expand(params, "paper-realistic")
    assert {(e.controller_name, e.seed) for e in episodes} == {
        (c, s) for c in ("pid", "ctc", "ctc_pid") for s in range(10)
    }
    assert {e.name for e in params.episodes} == {"paper-pid", "paper-ctc"}


@pytest.mark.parametrize(
    ("campaign", "expected"),
    [
        ({"scenario": "nope", "controllers": ["pid"]}, r"campaigns\.c\.scenario: unknown scenario"),
        ({"scenario": "paper", "controllers": ["pid", "lqr"]},
         r"campaigns\.c\.controllers\[1\]: unknown controller 'lqr'"),
        ({"scenario": "paper", "controllers": ["pid"], "sweep": {"plant.mass": [1]}},
         r"campaigns\.c\.sweep\.plant\.mass: 'mass' is not a field of plant \(valid: damping"),
        ({"scenario": "paper", "controllers": ["pid"], "sweep": {"start": [1]}},
         r"campaigns\.c\.sweep\.start: 'start' is not a field of a scenario"),
        ({"scenario": "paper", "controllers": ["pid"], "sweep": {"plant.uncertainty": [1]}},
         r"plant\.uncertainty is a group"),
        ({"scenario": "paper", "controllers": ["pid"], "sweep": {"plant.payload_kg": []}},
         r"campaigns\.c\.sweep\.plant\.payload_kg: give at least one value"),
        ({"scenario": "paper", "controllers": ["pid"], "seeds": 0}, r"campaigns\.c\.seeds"),
        ({"scenario": "paper", "controllers": ["pid", "pid"]}, r"controllers: listed twice: pid"),
        ({"scenario": "paper", "controllers": ["pid"],
          "sweep": {"plant.payload_kg": {"uniform": [2, 1], "n": 3}}},
         r"sweep\.plant\.payload_kg.*low <= high"),
    ],
)  # fmt: skip
def test_bad_campaigns_fail_in_one_line_naming_the_field(campaign, expected):
    with pytest.raises(ParamsError, match=expected) as info:
        _params(campaign)
    assert "\n" not in str(info.value)


def test_a_swept_value_the_scenario_refuses_is_named_at_expansion():
    bad = dict(SWEEP, sweep={"plant.payload_kg": [0.5, -1.0]})
    with pytest.raises(ParamsError, match=r"campaigns\.c \(payload_kg=-1\): scenario: "
                       r"plant\.payload_kg: .*greater than or equal to 0") as info:  # fmt: skip
        expand(_params(bad), "c")
    assert "\n" not in str(info.value)


def test_unknown_campaign_lists_the_defined_ones():
    with pytest.raises(ParamsError, match=r"unknown campaign 'x'; valid: c$"):
        expand(_params(SWEEP), "x")


def test_campaign_and_episode_names_cannot_collide():
    data = _base()
    data["campaigns"]["paper-pid"] = {"scenario": "paper", "controllers": ["pid"]}
    with pytest.raises(ParamsError, match=r"campaigns\.paper-pid: also an episode name"):
        parse_params(data, source="p.yaml")


def test_keys_are_directory_names():
    episodes = expand(_params(dict(SWEEP, sweep={"plant.payload_kg": [1e-5, -0.0]})), "c")
    for e in episodes:
        assert "/" not in e.name and not e.name.startswith(".")
    assert not math.isnan(episodes[0].scenario.plant.payload_kg)


def test_campaigns_command_lists_sizes_that_match_the_expansion():
    import json
    import subprocess
    import sys

    result = subprocess.run(
        [sys.executable, "-m", "pipeline", "campaigns", "--json", "--params",
         "examples/gain-sweep.yaml"],
        cwd=REPO, capture_output=True, text=True, timeout=120, check=True,
    )  # fmt: skip
    (row,) = json.loads(result.stdout)["campaigns"]
    params = load_params(REPO / "examples" / "gain-sweep.yaml")
    assert row["campaign"] == "gain-sweep"
    assert row["episodes"] == len(expand(params, "gain-sweep")) == 4 * 2 * 3
    assert [a["axis"] for a in row["axes"]] == ["controller", "gains.omega_n_rad_s", "seed"]
    assert row["axes"][1]["values"] == ["20", "30", "40", "60"]


def test_a_campaign_too_large_is_refused_before_any_work(tmp_path, monkeypatch):
    import shutil
    from collections import namedtuple

    from pipeline.stages import campaign_run

    huge = dict(SWEEP, seeds=1_000_000)  # 8 million episodes: refused before expanding
    with pytest.raises(ParamsError, match=r"campaigns\.c: 8,000,000 episodes, more than"):
        expand(_params(huge), "c")
    params = _params(SWEEP)
    run = campaign_run.plan_run(params, "c", out=tmp_path)
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda _: usage(10**9, 10**9 - 10**6, 10**6))
    with pytest.raises(ParamsError, match=r"campaigns\.c: 16 episodes would write about "
                       r"[0-9.]+ GB, more than the 0.0009 GB free") as info:  # fmt: skip
        campaign_run.check_campaign_size(params, run, motion_s=1.0, jobs=2)
    assert "\n" not in str(info.value)
    monkeypatch.setattr(shutil, "disk_usage", lambda _: usage(10**13, 0, 10**13))
    n_bytes, wall_s = campaign_run.check_campaign_size(params, run, motion_s=1.0, jobs=2)
    # 16 episodes of at most (2 s pre-roll + 1 s motion + 2 s hold: the caps) at 1 kHz,
    # 6 joints (the pre-roll ends when settled, the hold goes on until settled)
    assert n_bytes == 16 * 5001 * 6 * campaign_run.BAG_BYTES_PER_JOINT_STEP
    assert wall_s > 0


def test_a_key_too_long_for_a_directory_name_is_refused():
    axes = {f"plant.uncertainty.{k}": [0.05, 0.1] for k in ("mass_rel", "com_m", "inertia_rel")}
    axes |= {f"plant.{k}": [0.123456789, 0.2] for k in ("damping", "frictionloss", "armature")}
    axes |= {"plant.position_noise_std_rad": [1.23456789e-5], "gains.omega_n_rad_s": [30]}
    axes |= {"plant.velocity_noise_std_rad_s": [1.23456789e-3], "gains.zeta": [0.7071067811]}
    with pytest.raises(ParamsError, match=r"is longer than 200 characters"):
        expand(_params(dict(SWEEP, sweep=axes)), "c")
