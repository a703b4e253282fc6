"""Per-process model caches (MuJoCo compile, Pinocchio build): shared build, private copies."""

from __future__ import annotations

import mujoco
import numpy as np

from pipeline.model.mjcf import PlantOptions, build_mujoco_model, compiled_model
from pipeline.model.scene import Box


def test_models_come_from_one_compile_but_each_caller_gets_its_own_copy(ur5):
    compiled_model.cache_clear()
    box = Box("crate", (0.4, 0.0, 0.2), (0.05, 0.05, 0.05))
    a = build_mujoco_model(ur5, obstacles=[box])
    b = build_mujoco_model(ur5, obstacles=(box,))  # list or tuple: the same key
    info = compiled_model.cache_info()
    assert (info.misses, info.hits) == (1, 1)
    assert a is not b
    a.geom_margin[:] = 0.25
    a.opt.timestep = 0.01
    assert np.all(b.geom_margin == 0.0) and b.opt.timestep == 0.001
    c = build_mujoco_model(ur5, obstacles=[box])
    assert np.all(c.geom_margin == 0.0)  # the cached compile was not touched
    # a different plant is a different model, and auto-reset stays off in every copy
    heavy = build_mujoco_model(ur5, plant=PlantOptions(payload_kg=2.0))
    assert heavy.body_mass.sum() > build_mujoco_model(ur5).body_mass.sum() + 1.9
    for m in (a, b, c, heavy):
        assert m.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)


def test_pinocchio_models_are_private_copies_of_one_build(ur5):
    from pipeline.robots.urdf import build_pinocchio_model, pinocchio_model

    pinocchio_model.cache_clear()
    a, b = build_pinocchio_model(ur5), build_pinocchio_model(ur5)
    assert pinocchio_model.cache_info().misses == 1
    assert a is not b and a == b
    a.armature[:] = 7.0
    assert not np.any(b.armature == 7.0)
    assert np.allclose(build_pinocchio_model(ur5).armature, ur5.armature)
