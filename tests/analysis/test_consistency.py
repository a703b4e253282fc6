"""Settings that differ within a group: a field one bag leaves out (added after others were
recorded, or left out of the dump at its default) counts as its declared default."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pipeline.analysis.consistency import mixed_settings
from pipeline.log.reader import read_recording
from pipeline.log.recording import Recording
from tests.analysis.bagfactory import default_settings, paper_like, write_bag


def recordings(
    folder: Path, plants: dict[str, tuple[dict[str, Any], dict[str, Any] | None]]
) -> list[Recording]:
    """One short synthetic bag per ``name: (scenario plant, controller's own plant)``,
    named ``controller-seed``, all of scenario ``s``; read back."""
    out = []
    for name, (plant, own) in plants.items():
        controller, seed = name.rsplit("-", 1)
        ep = paper_like(name, controller, duration_s=0.2, motion_end_s=0.1, scenario="s",
                        seed=int(seed))  # fmt: skip
        settings = default_settings(ep)
        settings["scenario"]["plant"] = plant
        if own is not None:  # as the record stage writes it: the scenario's plant is its own
            settings["controller"]["plant"] = settings["scenario"]["plant"] = own
        ep.settings = settings
        write_bag(folder, ep)
        out.append(read_recording(folder / name))
    return out


def test_an_added_plant_field_set_in_one_episode_only_is_named(tmp_path: Path) -> None:
    recs = recordings(
        tmp_path,
        {
            "pid-0": ({"profile": "gaz-panda"}, None),
            "pid-1": ({}, None),
            "ctc-0": ({"uncertainty": {"coulomb_rel": 0.2}}, None),
        },
    )
    notes = {m.field: m.note() for m in mixed_settings({"s": recs})}
    assert notes == {
        "plant.profile": 'plant.profile: null vs "gaz-panda" in 1 of 3 episodes (pid-0)',
        "plant.uncertainty.coulomb_rel": (
            "plant.uncertainty.coulomb_rel: 0.0 vs 0.2 in 1 of 3 episodes (ctc-0)"
        ),
    }


def test_a_controllers_own_plant_differs_on_purpose_but_not_among_its_episodes(
    tmp_path: Path,
) -> None:
    gaz = {"profile": "gaz-panda"}
    recs = recordings(
        tmp_path,
        {
            "pid-0": ({}, None),
            "pid-1": ({}, None),
            "real-0": ({}, gaz),
            "real-1": ({}, {**gaz, "effort_noise_std_nm": 0.1}),
        },
    )
    found = mixed_settings({"s": recs})
    assert [m.note() for m in found] == [
        "real plant.effort_noise_std_nm: 0.0 vs 0.1 in 1 of 2 episodes (real-1)"
    ]
    # the same plant on every episode of each: nothing differs
    same = recordings(tmp_path / "same", {"pid-0": ({}, None), "real-0": ({}, gaz),
                                           "real-1": ({}, gaz)})  # fmt: skip
    assert mixed_settings({"s": same}) == []
