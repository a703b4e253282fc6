"""One declaration per concept: a settings field's ``knob`` is its params range, its
recorded form and its report line; gains and the scenario are typed in the settings."""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import pickle
from dataclasses import dataclass
from typing import Annotated

import pytest
from pydantic import ValidationError

from pipeline.contract import Contract, Count, NonNegative, knob, shown_fields
from pipeline.params import AsParams, ScenarioParams, _Strict, params_model, sweep_path_problem
from pipeline.report import md
from pipeline.report.setup import _fields_line
from pipeline.settings import (
    ControllerSettings,
    EpisodeSettings,
    Gains,
    LoopSettings,
    SettingsError,
)
from tests.analysis.bagfactory import default_settings, paper_like


@dataclass(frozen=True)
class _Probe(Contract):
    _where = "probe"

    gap_s: NonNegative = knob(0.5, ge=0, le=2.0, unit="s", label="gap")
    hidden: Count = knob(0, ge=0, shown=False)
    plain_name: NonNegative = knob(1.0, ge=0)


class _Holder(_Strict):
    probe: Annotated[_Probe, AsParams()] = _Probe()


def test_a_knob_is_the_params_range_and_default() -> None:
    assert _Holder().probe == _Probe()
    assert _Holder.model_validate({"probe": {"gap_s": 1.5}}).probe == _Probe(gap_s=1.5)
    with pytest.raises(ValidationError, match=r"probe\.gap_s\s+Input should be less than"):
        _Holder.model_validate({"probe": {"gap_s": 2.5}})
    with pytest.raises(ValidationError, match=r"probe\.typo\s+Extra inputs are not permitted"):
        _Holder.model_validate({"probe": {"typo": 1}})
    with pytest.raises(ValidationError, match=r"hidden: expected a number, got the boolean"):
        _Holder.model_validate({"probe": {"hidden": True}})  # no bool numbers, as all params
    assert _Holder(probe=_Probe(gap_s=1.0)).model_dump() == {
        "probe": {"gap_s": 1.0, "hidden": 0, "plain_name": 1.0}
    }


def test_a_knob_drives_the_report_line_in_declaration_order() -> None:
    assert list(shown_fields(_Probe)) == [("gap_s", "gap"), ("plain_name", "plain_name")]
    line = _fields_line(_Probe(gap_s=1.25, hidden=3), _Probe)
    assert line == f"gap = {md.value(1.25)}; plain_name = {md.value(1.0)}"
    assert _fields_line(None, _Probe) == md.NA


def test_the_scenario_loop_is_the_recorded_type_and_its_fields_are_sweepable() -> None:
    assert set(params_model(LoopSettings).model_fields) == set(LoopSettings.__dataclass_fields__)
    assert sweep_path_problem("loop.delay_s", {}) == ""
    assert sweep_path_problem("plant.uncertainty.mass_rel", {}) == ""
    assert "is a group" in sweep_path_problem("loop", {})
    assert "'typo' is not a field of loop" in sweep_path_problem("loop.typo", {})


def test_gains_keep_their_recorded_order_and_type_the_per_joint_ones() -> None:
    gains = Gains({"zeta": 1.0, "kp": [1, 2], "antiwindup": True, "est": {"m": [1.0]}})
    assert list(gains) == ["zeta", "kp", "antiwindup", "est"]
    assert gains.kp == (1.0, 2.0) and gains.kd is None
    assert dict(gains) == {"zeta": 1.0, "kp": [1, 2], "antiwindup": True, "est": {"m": [1.0]}}
    assert Gains({"kp": 5.0}).kp is None  # a plug-in's scalar kp stays as recorded
    with pytest.raises(SettingsError, match=r"controller\.gains\.kd: expected a JSON value"):
        Gains({"kd": [math.nan]})
    ctrl = ControllerSettings(name="a", type="pid", gains={"kp": [1.0]})
    assert isinstance(ctrl.gains, Gains)
    with pytest.raises(TypeError, match="read only"):
        ctrl.gains["kp"] = [2.0]
    back = pickle.loads(pickle.dumps(ctrl))  # report workers send settings across processes
    assert back == ctrl and isinstance(back.gains, Gains)
    assert copy.deepcopy(gains) == gains
    assert json.loads(json.dumps(dataclasses.asdict(ctrl)))["gains"] == {"kp": [1.0]}


def test_a_bag_with_non_json_gains_is_refused_naming_the_field() -> None:
    data = default_settings(paper_like("s", "pid", duration_s=0.6, motion_end_s=0.4))
    data["controller"]["gains"] = [1, 2]
    with pytest.raises(SettingsError, match=r"^controller\.gains: expected a mapping"):
        EpisodeSettings.from_dict(data)


def test_the_recorded_scenario_is_typed_and_written_as_given() -> None:
    data = default_settings(paper_like("s", "pid", duration_s=0.6, motion_end_s=0.4))
    settings = EpisodeSettings.from_dict(data)
    assert settings.scenario.name == "paper" and settings.scenario.robot == "ur5"
    assert isinstance(settings.scenario.loop, LoopSettings)
    written = settings.to_dict()["scenario"]
    assert next(iter(written)) == "name"
    rest = {k: v for k, v in written.items() if k != "name"}
    params = ScenarioParams.model_validate(rest)
    assert params.model_dump(mode="json") == rest
    data["scenario"]["hold_s"] = "long"
    with pytest.raises(SettingsError, match=r"^scenario\.hold_s: "):
        EpisodeSettings.from_dict(data)
