"""The plant is converged: halving the default physics step moves no reported metric."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from pipeline.constants import PLANT_FRICTION, PLANT_INTEGRATOR
from pipeline.params import load_params

REPO = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("convergence", REPO / "benches/convergence.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_halving_the_default_physics_step_moves_no_metric_of_the_default_experiment():
    """The paper scenario under pid and ctc and paper-realistic seed 0, recorded at the
    default physics step and at half of it (same 1 kHz control, zero-order hold): every
    metric the report computes from the bags agrees within 5 % (or its noise floor)."""
    bench = _bench()
    params = load_params(REPO / "params.yaml")
    n = params.sim.control_period_steps
    result = bench.convergence(params, substeps=[n, 2 * n])
    [halving] = result["halvings"]
    worst = max(halving["per_metric"].items(), key=lambda kv: kv[1]["rel"])
    assert halving["max_rel_change"] <= bench.TOLERANCE, worst
    assert {"paper-pid", "paper-ctc", "paper-realistic.pid.s0"} <= set(result["episodes"])
    # the bags say which plant ran; they log at the control rate whatever the step
    coarse, fine = result["plants"][str(n)], result["plants"][str(2 * n)]
    for episode, plant in coarse.items():
        assert plant["integrator"] == PLANT_INTEGRATOR
        assert plant["friction_model"] == PLANT_FRICTION
        assert plant["physics_dt_s"] == pytest.approx(params.sim.physics_dt_s)
        assert fine[episode]["physics_dt_s"] == pytest.approx(params.sim.physics_dt_s / 2)
        assert fine[episode]["control_rows"] == plant["control_rows"]
    sizes = [result["cost"][str(k)]["bag_bytes"] for k in (n, 2 * n)]
    assert sizes[1] == pytest.approx(sizes[0], rel=0.01)
