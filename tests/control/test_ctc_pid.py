"""ctc_pid: eq. 18 with an integral outer loop. Poles on the MuJoCo plant, integral
action against a mismatch the nominal model does not know, and anti-windup."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from pipeline.control import DEFAULT_OMEGA_N_RAD_S, default_gains, make_controller
from pipeline.errors import ParamsError
from pipeline.model.mjcf import PlantOptions, build_mujoco_model
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode

W = DEFAULT_OMEGA_N_RAD_S
P = 0.1 * W  # the designed integral pole


def test_default_gains_match_the_third_order_design_polynomial(ur5):
    """s^3 + Kd s^2 + Kp s + Ki has roots -p, -w, -w (numpy's poly, not our algebra)."""
    for w, zeta in ((40.0, 1.0), (25.0, 0.7)):
        g = default_gains(ur5, "ctc_pid", omega_n_rad_s=w, zeta=zeta)
        pd_roots = np.roots([1.0, 2 * zeta * w, w**2])
        expected = np.real(np.poly(np.concatenate([[-0.1 * w], pd_roots])))
        for j in range(ur5.dof):
            coeffs = [1.0, g["kd"][j], g["kp"][j], g["ki"][j]]
            np.testing.assert_allclose(coeffs, expected, rtol=1e-12)


def test_default_clamp_lets_the_integral_ask_for_half_the_effort_limit(ur5):
    """m_jj Ki i_clamp = effort / 2, with m_jj from MuJoCo (not Pinocchio)."""
    g = default_gains(ur5, "ctc_pid")
    model = build_mujoco_model(ur5)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    torque = np.diag(mass) * np.array(g["ki"]) * np.array(g["i_clamp"])
    np.testing.assert_allclose(torque, 0.5 * ur5.effort_limits, rtol=1e-9)


def test_settings_are_json_complete_and_bad_gains_are_refused(ur5):
    settings = make_controller("ctc_pid", ur5).gains_in_effect()
    assert set(settings) == {
        *("kp", "kd", "ki", "i_clamp", "omega_n_rad_s", "zeta"),
        *("design_at", "design_inertia_kg_m2"),  # the clamp is scaled by the inertia
    }
    assert json.loads(json.dumps(settings)) == settings
    with pytest.raises(ParamsError, match=r"^gains\.i_clamp: must be >= 0"):
        make_controller("ctc_pid", ur5, {"i_clamp": -1.0})
    with pytest.raises(ParamsError, match=r"^gains\.ki: expected a number or a list of 6"):
        make_controller("ctc_pid", ur5, {"ki": [1.0, 2.0]})


def test_integral_state_is_clamped_and_unwinds_at_once_and_reset_clears_it(ur5):
    """Anti-windup on the state: after a reversal the integral falls from the clamp,
    not from the wound-up value; the commanded acceleration shows it through M_n."""
    ctl = make_controller("ctc_pid", ur5, {"kp": 0.0, "kd": 0.0, "ki": 100.0, "i_clamp": 0.5})
    zero, one = np.zeros(6), np.ones(6)
    at_rest = ctl.compute(zero, zero, zero, zero, zero, 0.01).copy()
    for _ in range(100):  # unclamped the state would reach 1.0 rad s
        ctl.compute(zero, zero, one, zero, zero, 0.01)
    np.testing.assert_allclose(ctl.integral_rad_s, 0.5)
    tau = ctl.compute(zero, zero, -one, zero, zero, 0.01)
    np.testing.assert_allclose(ctl.integral_rad_s, 0.49)
    model = build_mujoco_model(ur5)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = np.zeros((6, 6))
    mujoco.mj_fullM(model, data, mass)
    np.testing.assert_allclose(tau - at_rest, mass @ np.full(6, 100.0 * 0.49), rtol=1e-9)
    ctl.reset()
    np.testing.assert_allclose(ctl.integral_rad_s, 0.0)


def _closed_loop_poles_with_integral(spec, q0):
    """Eigenvalues of plant + ctc_pid linearized at rest at q0: state (q, qd, z), z' = e.

    The integral state is set through the public interface: one compute with
    q_ref - q = z and dt = 1 s leaves it at z; a compute with dt = 0 reads it.
    """
    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    ctl = make_controller("ctc_pid", spec)
    n = spec.dof
    zero = np.zeros(n)

    def flow(x):
        q, qd, z = x[:n], x[n : 2 * n], x[2 * n :]
        ctl.reset()
        ctl.compute(q0, zero, q0 + z, zero, zero, 1.0)
        data.qpos[:], data.qvel[:] = q, qd
        data.ctrl[:] = ctl.compute(q, qd, q0, zero, zero, 0.0)
        mujoco.mj_forward(model, data)
        return np.concatenate([qd, data.qacc, q0 - q])

    x0, h = np.concatenate([q0, zero, zero]), 1e-6
    jac = np.column_stack([(flow(x0 + h * e) - flow(x0 - h * e)) / (2 * h) for e in np.eye(3 * n)])
    return np.sort_complex(np.linalg.eigvals(jac))


@pytest.mark.parametrize("q0", [np.zeros(6), np.array(PAPER_GOAL_RAD)], ids=["zeros", "goal"])
def test_ctc_pid_places_its_poles_at_the_design_on_the_mujoco_plant(ur5, q0):
    poles = _closed_loop_poles_with_integral(ur5, q0)
    assert np.abs(poles.imag).max() < 0.01  # zeta = 1
    slow, fast = poles.real[poles.real > -2 * P], poles.real[poles.real <= -2 * P]
    assert len(slow) == 6 and len(fast) == 12
    np.testing.assert_allclose(slow, -P, atol=1e-4)
    np.testing.assert_allclose(fast, -W, atol=0.01)


def _mass_and_gravity(model, q):
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    return mass, data.qfrc_bias.copy()


def test_integral_removes_the_steady_state_error_a_payload_leaves_under_ctc(ur5):
    """A 1 kg payload the nominal model does not know: ctc settles at M_n Kp e = dg (a few
    mrad on the wrists, whose rotor armature dominates M_n), ctc_pid drives it to zero."""
    reference = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=1.0)
    plant = PlantOptions(payload_kg=1.0)
    final, rest = {}, {}
    for name in ("ctc", "ctc_pid"):
        result = run_episode(
            ur5,
            reference=reference,
            controller=make_controller(name, ur5),
            seed=0,
            plant=plant,
            hold_s=3.0,  # 12 time constants of the integral pole (1 / 4 rad/s)
        )
        assert result.ok, result.reason
        final[name] = result.q_ref[-1] - result.q_true[-1]
        rest[name] = result.q_true[-1]
    # ctc's offset is the physical one: at rest M_n(q) Kp e = g_plant(q) - g_nominal(q)
    q = rest["ctc"]
    mass_n, gravity_n = _mass_and_gravity(build_mujoco_model(ur5), q)
    _, gravity_p = _mass_and_gravity(build_mujoco_model(ur5, plant=plant), q)
    kp = np.array(default_gains(ur5, "ctc")["kp"])
    predicted = np.linalg.solve(mass_n, gravity_p - gravity_n) / kp
    np.testing.assert_allclose(final["ctc"], predicted, rtol=1e-3, atol=1e-7)
    loaded = np.abs(final["ctc"]) > 1e-4
    assert loaded.sum() >= 4 and np.abs(final["ctc"]).max() > 1e-3
    ratio = np.abs(final["ctc_pid"][loaded]) / np.abs(final["ctc"][loaded])
    assert ratio.max() < 1e-3, (final["ctc"], final["ctc_pid"])


class _Recording:
    """Wraps ctc_pid and keeps its integral state after every compute."""

    def __init__(self, inner):
        self.inner = inner
        self.name = inner.name
        self.states = []

    def gains_in_effect(self):
        return self.inner.gains_in_effect()

    def reset(self):
        self.inner.reset()

    def compute(self, q, qd, q_ref, qd_ref, qdd_ref, dt_s):
        tau = self.inner.compute(q, qd, q_ref, qd_ref, qdd_ref, dt_s)
        self.states.append(self.inner.integral_rad_s)
        return tau


def test_clamp_limits_windup_while_the_torques_saturate(ur5):
    """A 0.5 rad shoulder-pan move in 0.1 s saturates the motors for a while; the error
    piles up in the integral. The clamped state stays within i_clamp and the
    overshoot stays far below that of an (effectively) unclamped integral."""
    goal = np.zeros(6)
    goal[0] = 0.5
    reference = QuinticReference.between(np.zeros(6), goal, duration_s=0.1)
    runs = {}
    for label, gains in (("clamped", None), ("unclamped", {"i_clamp": 1e9})):
        ctl = _Recording(make_controller("ctc_pid", ur5, gains))
        result = run_episode(ur5, reference=reference, controller=ctl, seed=0, hold_s=1.5)
        assert result.ok, result.reason
        assert result.saturated[:, 0].sum() > 20
        runs[label] = (
            result,
            np.array(ctl.states),
            np.array(ctl.inner.gains_in_effect()["i_clamp"]),
        )
    result, states, clamp = runs["clamped"]
    assert (np.abs(states) <= clamp + 1e-15).all()
    assert np.isclose(np.abs(states[:, 0]).max(), clamp[0])  # the clamp was reached
    overshoot = {k: r.q_true[:, 0].max() - 0.5 for k, (r, _, _) in runs.items()}
    assert overshoot["unclamped"] > 1.5 * overshoot["clamped"], overshoot  # 0.19 vs 0.09 rad
    assert np.abs(runs["unclamped"][1][:, 0]).max() > 5 * clamp[0]  # it did wind up (7.8x)
    assert abs(result.q_true[-1, 0] - 0.5) < 1e-3
