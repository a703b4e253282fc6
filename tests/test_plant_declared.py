"""A plant field params pass through is declared once (``knob(..., given=True)`` on
``pipeline.knobs.PlantSettings``): params take it with its range, the recording keeps it,
the exact-plant check wants its default and the setup line shows it. The loop's ``ideal``
and the ``added`` fields' omission are derived from the declaration too."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import pytest
from pydantic import ValidationError

from pipeline.contract import (
    NonNegative,
    added_defaults,
    at_defaults,
    given_fields,
    knob,
    meta_of,
    omit_added,
    plain,
    shown_fields,
)
from pipeline.experiment.assemble import _plant_is_exact, given_plant
from pipeline.knobs import LoopSettings, PlantSettings
from pipeline.params import PlantParams, _PlantParamsOwn, load_params, with_given
from pipeline.report.setup import _fields_line
from pipeline.robots.loaders import load_spec
from pipeline.settings import EpisodeSettings, plant_as_recorded
from tests.analysis.bagfactory import default_settings, paper_like

REPO = Path(__file__).parents[1]


@dataclass(frozen=True, kw_only=True)
class _PlantPlus(PlantSettings):
    """The plant with one more field, declared as a maintainer would add it."""

    backlash_rad: NonNegative = knob(
        0.0, ge=0, le=0.1, unit="rad", given=True, added=True, description="gear backlash"
    )


def _recorded_plant() -> PlantSettings:
    data = default_settings(paper_like("paper-ctc", "ctc"))
    return EpisodeSettings.from_dict(data).plant


def test_a_declared_plant_field_reaches_params_settings_and_the_setup_line() -> None:
    params = with_given("PlantPlusParams", _PlantParamsOwn, _PlantPlus)
    # params: accepted with its declared range, refused outside it naming the field
    assert params.model_validate({"backlash_rad": 0.02}).backlash_rad == 0.02
    with pytest.raises(ValidationError, match=r"backlash_rad\s+Input should be less than"):
        params.model_validate({"backlash_rad": 0.5})
    # the recording: kept, read back; absent in an older bag (its default stands in)
    base = _recorded_plant()
    plus = _PlantPlus(
        **{f.name: getattr(base, f.name) for f in dataclasses.fields(base)}, backlash_rad=0.02
    )
    data = plain(dataclasses.asdict(plus))
    assert _PlantPlus.from_dict(data).backlash_rad == 0.02
    del data["backlash_rad"]
    assert _PlantPlus.from_dict(data).backlash_rad == 0.0
    # left out of the recording while at its default (older bags keep their bytes)
    assert "backlash_rad" not in omit_added(
        _PlantPlus, plain(dataclasses.asdict(dataclasses.replace(plus, backlash_rad=0.0)))
    )
    # the report's plant line shows it, in declaration order, as recorded
    assert ("backlash_rad", "backlash_rad") in list(shown_fields(_PlantPlus))
    assert _fields_line(plus, _PlantPlus).endswith("backlash_rad = 0.02")
    # at its default it is not recorded, so not shown: older bags' lines stay as they were
    at_default = dataclasses.replace(plus, backlash_rad=0.0)
    assert _fields_line(at_default, _PlantPlus) == _fields_line(base, PlantSettings)


@pytest.mark.parametrize("name", [f.name for f in given_fields(PlantSettings)])
def test_every_given_plant_field_is_a_param_recorded_as_given_and_breaks_exactness(
    name: str,
) -> None:
    """A field declared given cannot be forgotten by params, the fill or ``plant.exact``."""
    declared = next(f for f in dataclasses.fields(PlantSettings) if f.name == name)
    field = PlantParams.model_fields[name]
    assert field.default == declared.default
    top = meta_of(declared).bounds["le"]  # the declared range is params' range
    assert getattr(PlantParams.model_validate({name: top}), name) == top
    for outside in (top * 2, -0.001):
        with pytest.raises(ValidationError, match=rf"{name}\s+Input should be"):
            PlantParams.model_validate({name: outside})
    scenario = load_params(REPO / "params.yaml").scenarios["paper"]
    spec = load_spec(scenario.robot)
    assert _plant_is_exact(spec, spec, scenario)
    changed = scenario.model_copy(
        update={"plant": PlantParams.model_validate({name: 0.01}), "loop": LoopSettings()}
    )
    assert given_plant(changed)[name] == 0.01
    assert not _plant_is_exact(spec, spec, changed)


def test_the_issue_28_fields_are_left_out_at_their_default_as_before() -> None:
    plant = _recorded_plant()
    data = plant_as_recorded(plain(dataclasses.asdict(plant)))
    for key in ("profile", "sigmoid_friction", "effort_offset_nm", "effort_noise_std_nm"):
        assert key not in data
    for key in ("coulomb_rel", "viscous_rel", "transition_rel", "payload_kg"):
        assert key not in data["uncertainty"]
    assert set(added_defaults(PlantSettings)) >= {
        "profile",
        "sigmoid_friction",
        "effort_offset_nm",
        "effort_noise_std_nm",
    }
    assert PlantParams().model_dump()["uncertainty"] == {
        "mass_rel": 0.0,
        "com_m": 0.0,
        "inertia_rel": 0.0,
        "armature_rel": 0.0,
    }
    assert "effort_noise_std_nm" not in PlantParams().model_dump()
    assert PlantParams(effort_noise_std_nm=0.5).model_dump()["effort_noise_std_nm"] == 0.5


@dataclass(frozen=True)
class _LoopPlus(LoopSettings):
    backlash_rad: NonNegative = knob(0.0, ge=0, le=0.1, unit="rad")


def test_the_ideal_loop_is_every_field_at_its_default_but_a_refining_one() -> None:
    off = {float: 0.001, int: 1, str: "encoder"}
    for f in dataclasses.fields(LoopSettings):
        changed = LoopSettings(**{f.name: off[type(f.default)]})
        assert changed.ideal is bool(meta_of(f).refines), f.name
    # a new field is seen without a hand list
    assert _LoopPlus().ideal and not _LoopPlus(backlash_rad=0.01).ideal
    assert at_defaults(_LoopPlus(backlash_rad=0.01), ["delay_s"])
