"""A drawn plant set on one compiled model is the recompiled model, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.experiment.assemble import draw_scenario_plant
from pipeline.model.mjcf import build_mujoco_model
from pipeline.params import load_params
from pipeline.robots import load_spec
from pipeline.sim.plant import plant_model, principal_axes
from pipeline.stages.plans import obstacle_boxes


def _arrays(model) -> dict[str, bytes]:
    out = {}
    for name in dir(model):
        if name.startswith("_"):
            continue
        value = getattr(model, name)
        if isinstance(value, np.ndarray):
            out[name] = value.tobytes()
    for group in ("opt", "stat"):
        struct = getattr(model, group)
        for name in dir(struct):
            if not name.startswith("_"):
                value = getattr(struct, name)
                if isinstance(value, float | int | np.ndarray):
                    out[f"{group}.{name}"] = np.asarray(value).tobytes()
    return out


@pytest.mark.parametrize("seed", [0, 1, 7, 123])
def test_drawn_plant_on_the_compiled_model_equals_a_recompile(seed):
    params = load_params("params.yaml")
    scenario = params.scenarios["paper-realistic"]
    spec = load_spec(scenario.robot)
    plant_spec, plant, _ = draw_scenario_plant(spec, scenario, seed=seed)
    kwargs = dict(
        timestep_s=0.0005, plant=plant, obstacles=obstacle_boxes(scenario), integrator="RK4"
    )
    fast = _arrays(plant_model(spec, plant_spec, **kwargs))
    slow = _arrays(build_mujoco_model(plant_spec, **kwargs))
    assert fast.keys() == slow.keys()
    assert [k for k in slow if fast[k] != slow[k]] == []


def test_principal_axes_rebuild_the_inertia():
    inertia = np.array([[0.3, 0.01, -0.02], [0.01, 0.2, 0.03], [-0.02, 0.03, 0.25]])
    moments, quat = principal_axes(inertia.tolist())
    w, x, y, z = quat
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    assert moments == sorted(moments, reverse=True)
    # the compiler's Jacobi iteration stops at a 1e-12 rotation, not at round-off
    np.testing.assert_allclose(r @ np.diag(moments) @ r.T, inertia, atol=1e-6)
    np.testing.assert_allclose(moments, np.linalg.eigvalsh(inertia)[::-1], atol=1e-6)
