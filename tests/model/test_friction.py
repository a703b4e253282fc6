"""The plant's joint friction sticks below its breakaway torque and slides above it."""

from __future__ import annotations

import math
import re

import mujoco
import numpy as np
import pytest

from pipeline.constants import PLANT_FRICTION
from pipeline.model.mjcf import PlantOptions, build_mjcf, build_mujoco_model
from pipeline.sim.references import PAPER_GOAL_RAD

# paper-realistic's friction and damping (harmonic drives)
FRICTION_NM = (3.0, 3.0, 2.0, 0.8, 0.8, 0.8)
DAMPING_NM_S = (1.0, 1.0, 0.8, 0.3, 0.3, 0.3)
PLANT = PlantOptions(damping=DAMPING_NM_S, frictionloss=FRICTION_NM)
HELD_S = 1.0


def _push(model, joint: int, fraction: float):
    """Hold the arm at the paper's goal pose against gravity and Coriolis (RNEA of the
    current state every step), push ``joint`` with ``fraction`` x its friction torque for
    ``HELD_S``; return the displacement [rad] and final velocity [rad/s] per joint."""
    data = mujoco.MjData(model)
    q0 = np.array(PAPER_GOAL_RAD)
    data.qpos[:] = q0
    mujoco.mj_forward(model, data)
    for _ in range(round(HELD_S / model.opt.timestep)):
        mujoco.mj_rne(model, data, 0, data.qfrc_applied)
        data.qfrc_applied[joint] += fraction * FRICTION_NM[joint]
        mujoco.mj_step(model, data)
    assert not data.warning.number.any()
    return data.qpos - q0, data.qvel.copy()


STEPS = [("RK4", 0.0005), ("RK4", 0.001), ("Euler", 0.001), ("RK4", 0.00025)]


@pytest.mark.parametrize(("integrator", "dt_s"), STEPS)
def test_joint_below_its_friction_torque_does_not_move(ur5, integrator, dt_s):
    model = build_mujoco_model(ur5, timestep_s=dt_s, plant=PLANT, integrator=integrator)
    for j in range(ur5.dof):
        moved, _ = _push(model, j, 0.9)
        assert np.abs(moved).max() < 1e-5, (ur5.joint_names[j], moved)


@pytest.mark.parametrize(("integrator", "dt_s"), STEPS[:3])
def test_joint_above_its_friction_torque_slides_at_the_coulomb_viscous_velocity(
    ur5, integrator, dt_s
):
    """1.1 x the friction torque leaves 0.1 x of it to accelerate the joint against its
    viscous damping, the other joints stuck: M_jj v' = 0.1 F_c - D v, so
    v(t) = 0.1 F_c / D (1 - exp(-D t / M_jj)), the joint's inertia from MuJoCo at the pose."""
    model = build_mujoco_model(ur5, timestep_s=dt_s, plant=PLANT, integrator=integrator)
    data = mujoco.MjData(model)
    data.qpos[:] = PAPER_GOAL_RAD
    mujoco.mj_forward(model, data)
    inertia = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, inertia)
    for j in range(ur5.dof):
        moved, qd = _push(model, j, 1.1)
        f, d, m = FRICTION_NM[j], DAMPING_NM_S[j], inertia[j, j]
        expected = 0.1 * f / d * (1 - math.exp(-d * HELD_S / m))
        assert moved[j] > 0.01, (ur5.joint_names[j], moved)
        assert qd[j] == pytest.approx(expected, rel=0.05), ur5.joint_names[j]


def test_mujoco_default_friction_creeps_which_is_why_the_plant_makes_it_stiff(ur5):
    """The same push on MuJoCo's default (soft) friction loss: the joints creep by
    mrad in a second, a thousand times the stiff plant's bound."""
    xml = build_mjcf(ur5, timestep_s=0.001, plant=PLANT)
    soft = re.sub(r' solreffriction="[^"]*" solimpfriction="[^"]*"', "", xml)
    assert soft != xml
    model = mujoco.MjModel.from_xml_string(soft)
    moved = [abs(_push(model, j, 0.9)[0][j]) for j in range(ur5.dof)]
    assert min(moved) > 1e-4, moved


def test_a_joint_without_friction_gets_no_friction_constraint_settings(ur5):
    xml = build_mjcf(ur5, plant=PlantOptions(frictionloss=(1.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
    assert xml.count("solimpfriction") == 1
    assert "solimpfriction" not in build_mjcf(ur5)
    assert "stick-slip" in PLANT_FRICTION
