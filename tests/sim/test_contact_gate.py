"""The contact gate: the plant's collision detection skipped only where no contact is
possible, so gated and always-on episodes are the same bit for bit."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from pipeline.control import make_controller
from pipeline.model.mjcf import PlantOptions
from pipeline.model.scene import Box
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode

ARRAYS = ("q_true", "qd_true", "q", "qd", "tau_cmd_nm", "tau_nm")


def _pair(spec, reference, name, gains, **kwargs):
    """The same episode with the gate and with MuJoCo's collision in every step."""
    out = []
    for gate in (True, False):
        out.append(
            run_episode(
                spec,
                reference=reference,
                controller=make_controller(name, spec, gains),
                seed=0,
                physics_dt_s=0.0005,
                control_period_steps=2,
                integrator="RK4",
                contact_gate=gate,
                **kwargs,
            )
        )
    return out


def _same(a, b):
    assert a.status == b.status and a.reason == b.reason
    for field in ARRAYS:
        x, y = getattr(a, field), getattr(b, field)
        assert x.shape == y.shape and x.tobytes() == y.tobytes(), field


def _touches(spec, q_rows, obstacles=()):
    """Rows where the plant's own collision finds a contact."""
    from pipeline.model.mjcf import build_mujoco_model

    model = build_mujoco_model(spec, obstacles=obstacles)
    data = mujoco.MjData(model)
    hits = 0
    for q in q_rows:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        hits += data.ncon > 0
    return hits


def test_a_free_space_episode_on_a_realistic_plant_is_unchanged_by_the_gate(ur5):
    reference = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=0.5)
    plant = PlantOptions(damping=(1.0,), frictionloss=(3.0, 3.0, 2.0, 0.8, 0.8, 0.8))
    gated, always = _pair(
        ur5, reference, "pid", None, plant=plant, hold_s=0.3, preroll_s=0.3,
        position_noise_std_rad=1e-5, velocity_noise_std_rad_s=1e-3,
    )  # fmt: skip
    assert gated.ok
    assert _touches(ur5, gated.q_true[::10]) == 0
    _same(gated, always)


def test_an_arm_falling_onto_its_pedestal_and_the_floor_is_unchanged_by_the_gate(ur5):
    """Gains of almost nothing: the UR5 falls from the horizontal under gravity, hits its
    pedestal and the floor and lies there; contacts happen, and the states with the gate
    (contacts on near them) are those with MuJoCo's collision in every step."""
    start = np.zeros(6)
    reference = QuinticReference.between(start, start, duration_s=0.1)
    weak = {"kp": 1e-3, "kd": 1e-3, "ki": 0.0}
    plant = PlantOptions(damping=(0.3,), frictionloss=(0.8,))  # the solver runs throughout
    gated, always = _pair(ur5, reference, "pid", weak, hold_s=1.5, settle=False, plant=plant)
    touching = _touches(ur5, gated.q_true[::10])
    assert touching > 10, "the arm should come to rest against something"
    _same(gated, always)


def test_an_arm_falling_onto_a_box_is_unchanged_by_the_gate(ur5):
    """A table under the outstretched arm: it falls onto the box (robot-obstacle pairs)."""
    table = Box(name="table", center=(-0.6, 0.0, -0.1), half_size=(0.15, 0.3, 0.05))
    start = np.zeros(6)
    reference = QuinticReference.between(start, start, duration_s=0.1)
    weak = {"kp": 1e-3, "kd": 1e-3, "ki": 0.0}
    gated, always = _pair(ur5, reference, "pid", weak, hold_s=1.0, settle=False, obstacles=[table])
    assert _touches(ur5, gated.q_true[::10], obstacles=[table]) > 10
    _same(gated, always)


@pytest.mark.parametrize("robot", ["ur10"])
def test_the_gate_turns_contacts_off_in_free_space_and_back_on(robot):
    from pipeline.model.mjcf import build_mujoco_model
    from pipeline.robots import load_spec
    from pipeline.sim.contact_gate import ContactGate

    spec = load_spec(robot)
    model = build_mujoco_model(spec)
    gate = ContactGate(model, spec, obstacles=(), control_dt_s=0.001)
    contact = int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    rest = np.zeros(spec.dof)
    gate.before_period(rest, rest, 0.0)  # the first row: no acceleration known yet
    assert not model.opt.disableflags & contact and gate.checks == 1
    gate.cooldown = 0
    gate.before_period(rest, rest, 0.0)
    assert model.opt.disableflags & contact and gate.checks == 2
    slow = np.full(spec.dof, 1e-3)
    for k in range(100):  # slow motion: no new check
        gate.before_period(1e-6 * k * np.ones(spec.dof), slow, float(np.linalg.norm(slow)))
    assert gate.checks == 2 and model.opt.disableflags & contact
    fast = np.full(spec.dof, 1e3)  # far too fast to prove anything
    gate.before_period(rest, fast, float(np.linalg.norm(fast)))
    assert not model.opt.disableflags & contact and gate.checks == 3
