"""SRDF named states by name as a scenario's start or goal (``start: default``)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.errors import ParamsError
from pipeline.experiment.goals import resolve_goal
from pipeline.params import parse_params
from pipeline.robots import load_spec
from pipeline.robots.packages import package_search_path

REPO = Path(__file__).parents[2]
PARAMS = yaml.safe_load((REPO / "params.yaml").read_text())
pytestmark = pytest.mark.skipif(
    not any((p / "example-robot-data").is_dir() for p in package_search_path()),
    reason="example-robot-data is not installed",
)
GOAL = [1.3, -0.5, 0.0, -2.0, 0.0, 1.5, 0.785398]


def _resolve(start, goal):
    data = copy.deepcopy(PARAMS)
    scenario = data["scenarios"]["paper"]
    scenario.update(robot="panda", start=start, goal=goal)
    params = parse_params(data, source="params.yaml")
    return resolve_goal(
        load_spec("panda"), params.scenarios["paper"], name="paper", source="params.yaml"
    )


def test_a_named_state_is_a_start_and_a_goal():
    default = load_spec("panda").named_state("default")
    start, goal = _resolve("default", {"joints": GOAL})
    np.testing.assert_array_equal(start, default)
    np.testing.assert_array_equal(goal, GOAL)
    start, goal = _resolve(GOAL, "default")  # short for goal: {state: default}
    np.testing.assert_array_equal(goal, default)
    _, goal = _resolve(GOAL, {"state": "default"})
    np.testing.assert_array_equal(goal, default)
    assert default[3] == pytest.approx(-2.35619)  # the SRDF's own value


def test_an_unknown_named_state_lists_the_ones_the_srdf_defines():
    with pytest.raises(ParamsError) as err:
        _resolve("ready", {"joints": GOAL})
    message = str(err.value)
    assert "scenarios.paper.start: robot panda (SRDF " in message
    assert message.endswith("defines no state 'ready'; defined: default")
