"""The recording contract: from_dict inverts to_dict and names the field path of what it refuses."""

from __future__ import annotations

import copy
import dataclasses
import json
from typing import Any

import pytest

from pipeline.settings import (
    SETTINGS_VERSION,
    EpisodeSettings,
    LinkInertial,
    LoopSettings,
    SettingsError,
)
from tests.analysis.bagfactory import default_settings, paper_like


def _settings() -> dict[str, Any]:
    data = default_settings(paper_like("s", "pid", duration_s=0.6, motion_end_s=0.4))
    data["safety"]["clearances"] = [
        {"kind": "obstacle", "bodies": ["wrist", "box"], "distance_m": 0.01, "stamp_ns": 5}
    ]
    data["mujoco_warnings"] = {"nefc": 3}
    data["campaign"] = {"name": "c", "condition": "", "swept": {"seed": 1, "x": None}}
    return EpisodeSettings.from_dict(data).to_dict()  # the safety's derived keys agree


def test_from_dict_inverts_to_dict_byte_for_byte() -> None:
    data = _settings()
    back = EpisodeSettings.from_dict(data)
    assert json.dumps(back.to_dict()) == json.dumps(data)
    assert back.planner.start == tuple(data["planner"]["start"])  # tuples inside, typed
    with pytest.raises(AttributeError):
        back.seed = 3  # type: ignore[misc]


def test_the_motion_end_counts_from_the_recordings_first_sample() -> None:
    data = _settings()
    data["protocol"]["motion_start_s"] = 0.5
    data["planner"]["trajectory_duration_s"] = 0.4
    settings = EpisodeSettings.from_dict(data)
    assert settings.motion_end_from_first_sample_s == pytest.approx(0.9)


def _set(path: str, value: Any) -> dict[str, Any]:
    data = _settings()
    *parents, last = path.split(".")
    node: Any = data
    for key in parents:
        node = node[int(key)] if key.isdigit() else node[key]
    if value is KeyError:
        del node[last]
    else:
        node[int(last) if last.isdigit() else last] = value
    return data


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (
            "planner.trajectory_duration_s",
            -1.0,
            "planner.trajectory_duration_s: expected a finite number >= 0, got -1.0",
        ),
        ("planner.time_limit_s", 0, "planner.time_limit_s: expected a finite number > 0, got 0"),
        ("planner.seed", True, "planner.seed: expected an integer >= 0, got True"),
        ("planner.start.2", "x", "planner.start[2]: expected a finite number, got 'x'"),
        ("planner.goal", 3, "planner.goal: expected a list of numbers, got 3"),
        ("protocol.hold_s", KeyError, "protocol.hold_s: missing (required by the contract)"),
        ("plant.links.1.com", [0, 0], "plant.links[1].com: expected 3 numbers, got [0, 0]"),
        ("plant.links", {}, "plant.links: expected a list of link inertials, got {}"),
        (
            "plant.uncertainty.com_m",
            float("nan"),
            "plant.uncertainty.com_m: expected a finite number, got nan",
        ),
        (
            "safety.clearances.0.kind",
            "wall",
            "safety.clearances[0].kind: expected one of obstacle, floor, self, got 'wall'",
        ),
        (
            "safety.clearances.0.bodies",
            ["a"],
            "safety.clearances[0].bodies: expected two names, got ['a']",
        ),
        ("controller.gains", [], "controller.gains: expected a mapping, got []"),
        ("mujoco_warnings.nefc", -1, "mujoco_warnings.nefc: expected an integer >= 0, got -1"),
        ("campaign.swept.seed", [1], "campaign.swept.seed: expected a JSON scalar, got [1]"),
        ("status", "crashed", "status: expected 'ok' or 'diverged', got 'crashed'"),
        ("episode", KeyError, "episode: missing (required by the contract)"),
        ("version", 1, f"version: expected settings version {SETTINGS_VERSION}, got 1"),
        ("loop.delay_s", -0.001, "loop.delay_s: expected a finite number >= 0, got -0.001"),
        (
            "loop.encoder_counts_per_rev",
            4096.5,
            "loop.encoder_counts_per_rev: expected an integer >= 0, got 4096.5",
        ),
        (
            "loop.velocity",
            "observer",
            "loop.velocity: expected one of plant, encoder, got 'observer'",
        ),
        ("loop.jitter_s", KeyError, "loop.jitter_s: missing (required by the contract)"),
    ],
)
def test_from_dict_names_the_field_path_of_what_it_refuses(
    path: str, value: Any, message: str
) -> None:
    with pytest.raises(SettingsError) as err:
        EpisodeSettings.from_dict(_set(path, value))
    assert str(err.value) == message


def test_settings_that_are_not_a_mapping_are_refused() -> None:
    with pytest.raises(SettingsError, match=r"^settings: expected a mapping, got \[\]$"):
        EpisodeSettings.from_dict([])


def test_unknown_keys_are_ignored_and_a_later_field_may_be_absent_from_older_bags() -> None:
    data = _settings()
    data["safety"].pop("skip_within_m")
    data["planner"]["from_a_newer_recorder"] = 1
    back = EpisodeSettings.from_dict(copy.deepcopy(data))
    assert back.safety.skip_within_m == 0.0


def test_a_bag_written_before_the_loop_settings_reads_as_the_ideal_loop() -> None:
    data = _settings()
    assert data["loop"] == {
        f.name: f.default for f in dataclasses.fields(LoopSettings)
    }  # every declared field at its default (a new one needs no edit here)
    data.pop("loop")
    back = EpisodeSettings.from_dict(data)
    assert back.loop == LoopSettings()
    assert back.loop.ideal


def test_a_loop_with_delay_or_encoder_is_not_ideal_but_a_cutoff_alone_is() -> None:
    assert not LoopSettings(delay_s=0.001).ideal
    assert not LoopSettings(jitter_s=0.001).ideal
    assert not LoopSettings(encoder_counts_per_rev=4096).ideal
    assert not LoopSettings(velocity="encoder").ideal
    assert LoopSettings(velocity_cutoff_hz=100.0).ideal  # only read for encoder velocity
    data = _settings()
    data["loop"] = {**data["loop"], "delay_s": 0.001, "velocity": "encoder"}
    assert EpisodeSettings.from_dict(data).loop == LoopSettings(delay_s=0.001, velocity="encoder")


def test_a_part_validated_alone_names_the_path_given() -> None:
    with pytest.raises(SettingsError, match=r"^links\[4\]\.mass: expected a finite number > 0"):
        LinkInertial.from_dict({"mass": 0, "com": [0, 0, 0], "inertia": [1] * 6}, "links[4]")


def test_the_settling_flags_read_back_and_default_for_older_bags() -> None:
    data = _settings()
    data["protocol"]["preroll_settled"] = False
    data["protocol"]["hold_settled"] = False
    settings = EpisodeSettings.from_dict(data)
    assert settings.protocol.preroll_settled is False
    assert settings.protocol.hold_settled is False
    # a bag written before the settled pre-roll: a fixed pre-roll, hold not judged
    for key in ("preroll_settled", "hold_settled"):
        del data["protocol"][key]
    older = EpisodeSettings.from_dict(data)
    assert older.protocol.preroll_settled is True
    assert older.protocol.hold_settled is None
    data["protocol"]["hold_settled"] = "yes"
    expected = r"protocol\.hold_settled: expected true, false or null"
    with pytest.raises(SettingsError, match=expected):
        EpisodeSettings.from_dict(data)
