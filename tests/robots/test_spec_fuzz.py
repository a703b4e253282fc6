"""Whatever the robot loader accepts, every engine can build: a seeded fuzz.

Random leaves of ur5.yaml get extreme or random values (every magnitude, both signs,
NaN, infinities, booleans, strings, lists). Each mutated file is either refused with a
one-line SpecError, or it builds the MuJoCo plant and the Pinocchio model and gives a
finite forward-kinematics pose. A value the loader lets through and an engine then
chokes on is a range missing from pipeline/robots/spec.py.
"""

from __future__ import annotations

import copy
import warnings
from importlib import resources
from typing import Any

import numpy as np
import pytest
import yaml

from pipeline.errors import SpecError
from pipeline.model.dh import forward_kinematics
from pipeline.model.mjcf import build_mujoco_model
from pipeline.robots.dh_yaml import parse_spec
from pipeline.robots.urdf import build_pinocchio_model

UR5 = yaml.safe_load((resources.files("pipeline.robots") / "ur5.yaml").read_text())
SPECIAL: list[Any] = [0.0, -0.0, 1e-300, -1e-300, 1e308, -1e308, float("nan"), float("inf"),
                      -float("inf"), True, "1.0", None, [], [1.0], 10**400]  # fmt: skip


def _leaves(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [path] if path else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += _leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _leaves(v, (*path, i))
    return out


PATHS = [p for p in _leaves(UR5) if not isinstance(p[-1], str) or p[-1] != "name"]


def _value(rng: np.random.Generator) -> Any:
    if rng.random() < 0.4:
        return SPECIAL[rng.integers(len(SPECIAL))]
    return float(rng.choice([-1, 1]) * 10.0 ** rng.uniform(-12, 12))


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("seed", range(10))
def test_what_the_loader_accepts_every_engine_builds(seed):
    rng = np.random.default_rng(seed)
    accepted = 0
    for _ in range(100):
        data = copy.deepcopy(UR5)
        for _ in range(int(rng.integers(1, 4))):
            path = PATHS[rng.integers(len(PATHS))]
            node = data
            try:
                for key in path[:-1]:
                    node = node[key]
                node[path[-1]] = _value(rng)
            except (TypeError, KeyError, IndexError):
                pass  # an earlier mutation replaced a container on this path
        try:
            spec = parse_spec(data, source="arm.yaml")
        except SpecError as err:
            assert "\n" not in str(err) and str(err).startswith("arm.yaml"), str(err)
            continue
        accepted += 1
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            build_mujoco_model(spec)
            build_pinocchio_model(spec)
            pose = forward_kinematics(spec, 0.5 * (spec.lower + spec.upper))
        assert np.all(np.isfinite(pose))
    assert accepted > 0  # the fuzz must also reach the engines
