"""Whatever params.yaml holds, validation answers in one line or accepts: a seeded fuzz.

Random leaves of the default params (plus an obstacle and a Cartesian goal, so those
branches are reached) get extreme or random values. ``prepare`` (everything `pipeline
record` checks before work: schema, ranges, robot, joint vectors, IK of the goal,
gains, resource estimate) must raise a one-line PipelineError or accept; nothing else.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from pipeline.errors import PipelineError
from pipeline.params import load_params
from pipeline.stages.record import prepare

REPO = Path(__file__).parents[1]
BASE = yaml.safe_load((REPO / "params.yaml").read_text())
BASE["scenarios"]["paper"]["obstacles"] = [
    {"name": "box", "center": [0.6, 0.6, 0.2], "half_size": [0.05, 0.05, 0.05]}
]
BASE["scenarios"]["pose"] = {
    **copy.deepcopy(BASE["scenarios"]["paper"]),
    "goal": {"pose": {"position": [0.4, 0.2, 0.4], "rpy": [3.14159, 0.0, 0.0]}},
}
BASE["episodes"]["pose-ctc"] = {"scenario": "pose", "controller": "ctc"}
SPECIAL: list[Any] = [0, -1, 1e-300, 1e308, -1e308, float("nan"), float("inf"), True, False,
                      "x", None, [], {}, [1e308] * 6, 10**400, "e" * 300]  # fmt: skip


def _leaves(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [path] if path else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += _leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _leaves(v, (*path, i))
    return out


PATHS = _leaves(BASE)


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("seed", range(4))
def test_validation_refuses_in_one_line_or_accepts(tmp_path, seed):
    rng = np.random.default_rng(seed)
    for k in range(60):
        data = copy.deepcopy(BASE)
        path = PATHS[rng.integers(len(PATHS))]
        node = data
        for key in path[:-1]:
            node = node[key]
        if rng.random() < 0.5:
            value = SPECIAL[rng.integers(len(SPECIAL))]
        else:
            value = float(rng.choice([-1, 1]) * 10.0 ** rng.uniform(-12, 12))
        node[path[-1]] = value
        params = tmp_path / f"p{k}.yaml"
        params.write_text(yaml.safe_dump(data))
        try:
            prepare(load_params(params), out_dir=tmp_path / "out", force=True)
        except PipelineError as err:
            assert "\n" not in str(err), (path, value, str(err))
            assert str(params) in str(err) or "robot" in str(err), (path, value, str(err))
