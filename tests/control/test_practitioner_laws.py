"""pid_ff, pid_humble, passivity and adaptive: each law against an independent engine,
and each on the MuJoCo plant (a few seconds of simulation per test)."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from pipeline.control import adaptive, make_controller, pid_humble
from pipeline.control.adaptive import nominal_parameters
from pipeline.errors import ParamsError
from pipeline.model.mjcf import PlantOptions, build_mujoco_model
from pipeline.robots.urdf import build_pinocchio_model
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode

DT_S = 0.001
PAPER_MOTION = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=1.0)


def _max_error(spec, name, gains=None, **kwargs):
    """Per-joint max |q_ref - q_true| from the motion start (settled start, 1 s pre-roll)."""
    result = run_episode(
        spec,
        reference=PAPER_MOTION,
        controller=make_controller(name, spec, gains),
        seed=0,
        hold_s=0.5,
        preroll_s=1.0,
        **kwargs,
    )
    assert result.ok, result.reason
    k0 = result.motion_start_row
    return np.abs(result.q_ref[k0:] - result.q_true[k0:]).max(axis=0)


def _random_states(seed, n=6, count=10):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        q, q_ref = rng.uniform(-np.pi, np.pi, (2, n))
        qd, qd_ref, qdd_ref = rng.normal(0.0, 1.0, (3, n))
        yield q, qd, q_ref, qd_ref, qdd_ref


# --- pid_ff -----------------------------------------------------------------------


def test_pid_ff_more_than_halves_the_pids_max_error_with_an_exact_model(ur5):
    """Ideal plant (nominal = plant), the paper's motion: the model's efforts do the
    work and the PID only corrects (measured: 4-20 % of the PID's error, joints 1-5)."""
    pid = _max_error(ur5, "pid")
    pid_ff = _max_error(ur5, "pid_ff")
    ratio = pid_ff[:5] / pid[:5]
    assert (ratio < 0.5).all(), ratio


def test_pid_ff_adds_mujocos_inverse_dynamics_of_the_next_reference_sample(ur5):
    """With the PID gains at zero the command is the effort of the setpoint at t + dt
    (Jazzy's command_next_), checked against MuJoCo's mj_inverse at that sample."""
    ctl = make_controller("pid_ff", ur5, {"kp": 0.0, "ki": 0.0, "kd": 0.0})
    model = build_mujoco_model(ur5)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    data = mujoco.MjData(model)
    zero = np.zeros(6)
    for t in (0.2, 0.5, 0.8):
        ctl.reset()
        ctl.compute(zero, zero, *PAPER_MOTION.sample(t - DT_S), DT_S)  # the jerk's first sample
        tau = ctl.compute(zero, zero, *PAPER_MOTION.sample(t), DT_S)
        data.qpos[:], data.qvel[:], data.qacc[:] = PAPER_MOTION.sample(t + DT_S)
        mujoco.mj_inverse(model, data)
        ahead = data.qfrc_inverse.copy()
        data.qpos[:], data.qvel[:], data.qacc[:] = PAPER_MOTION.sample(t)
        mujoco.mj_inverse(model, data)
        # the jerk extrapolation is off by ~snap dt^2: 2e-4 N m at most on this motion
        np.testing.assert_allclose(tau, ahead, rtol=0.0, atol=5e-4)
        assert np.abs(tau - ahead).max() < 0.2 * np.abs(tau - data.qfrc_inverse).max()
    same_instant = make_controller(
        "pid_ff", ur5, {"kp": 0.0, "ki": 0.0, "kd": 0.0, "ff_at_next_sample": False}
    )
    tau = same_instant.compute(zero, zero, *PAPER_MOTION.sample(0.5), DT_S)
    data.qpos[:], data.qvel[:], data.qacc[:] = PAPER_MOTION.sample(0.5)
    mujoco.mj_inverse(model, data)
    np.testing.assert_allclose(tau, data.qfrc_inverse, rtol=1e-9, atol=1e-9)


def test_pid_ff_pid_part_and_gains_are_the_pids(ur5):
    settings = make_controller("pid_ff", ur5).gains_in_effect()
    assert settings.pop("ff_at_next_sample") is True
    assert settings == make_controller("pid", ur5).gains_in_effect()
    with pytest.raises(ParamsError, match=r"^gains\.ff_at_next_sample: expected true or false"):
        make_controller("pid_ff", ur5, {"ff_at_next_sample": 1})


# --- pid_humble -------------------------------------------------------------------


def test_pid_humble_integral_is_off_by_default_and_equals_pid_with_ki_zero(ur5, monkeypatch):
    monkeypatch.setattr(pid_humble, "_warned", False)
    with pytest.warns(pid_humble.IntegralOffWarning, match="i_clamp = 0 on all joints"):
        humble = make_controller("pid_humble", ur5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make_controller("pid_humble", ur5)  # printed once per process, not per controller
    assert not humble.integral_on
    assert "integral" in humble.gains_in_effect()["warning"]
    assert humble.gains_in_effect()["i_clamp"] == [0.0] * 6
    assert humble.gains_in_effect()["ki"] == make_controller("pid", ur5).gains_in_effect()["ki"]
    pid = make_controller("pid", ur5, {"ki": 0.0})
    for state in _random_states(3, count=20):  # the integral state would build up here
        np.testing.assert_array_equal(
            humble.compute(*state, DT_S).copy(), pid.compute(*state, DT_S).copy()
        )


def test_pid_humble_clamps_only_the_integral_output_as_without_antiwindup(ur5):
    """Humble's Pid(p, i, d, i_clamp, -i_clamp) has antiwindup false: the same as pid
    with antiwindup off and a symmetric clamp (the state winds up past the clamp)."""
    common = {"kp": 2.0, "kd": 0.3, "ki": 50.0, "ff_velocity_scale": 0.5}
    humble = make_controller("pid_humble", ur5, {**common, "i_clamp": 0.2})
    pid = make_controller(
        "pid", ur5, {**common, "antiwindup": False, "i_clamp_min": -0.2, "i_clamp_max": 0.2}
    )
    assert humble.integral_on and "warning" not in humble.gains_in_effect()
    zero, one = np.zeros(6), np.ones(6)
    for _ in range(30):  # wind up: ki dt e = 0.5 per step
        np.testing.assert_allclose(
            humble.compute(zero, zero, one, zero, zero, 0.01),
            pid.compute(zero, zero, one, zero, zero, 0.01),
        )
    back = humble.compute(zero, zero, -one, zero, zero, 0.01)
    np.testing.assert_allclose(back, pid.compute(zero, zero, -one, zero, zero, 0.01))
    np.testing.assert_allclose(back, -2.0 + 0.2)  # still at the clamp: the state wound up
    with pytest.raises(ParamsError, match=r"^gains\.i_clamp: must be >= 0"):
        make_controller("pid_humble", ur5, {"i_clamp": -1.0})
    with pytest.raises(
        ParamsError, match=r"^gains\.antiwindup: unknown pid_humble gain 'antiwindup'"
    ):
        make_controller("pid_humble", ur5, {"antiwindup": True})


def test_pid_humble_at_its_defaults_sags_under_gravity(ur5):
    """The warning is physical: without the integral the held start pose is off by
    about g / kp on the gravity-loaded shoulder and elbow (the default pid is not)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pid_humble.IntegralOffWarning)
        humble = _max_error(ur5, "pid_humble")
    pid = _max_error(ur5, "pid")
    assert (humble[1:3] > 5 * pid[1:3]).all(), (humble, pid)


# --- passivity --------------------------------------------------------------------


def test_passivity_torque_is_slotine_li_with_pinocchios_mass_and_coriolis_matrices(ur5):
    """The RNEA polarization equals M qr_dd + C(q, qd) qr_d + g + Kd s with M from crba
    and C from computeCoriolisMatrix (another code path of Pinocchio)."""
    ctl = make_controller("passivity", ur5, {"lambda": [5.0, 10, 15, 20, 25, 30], "kd": 7.0})
    lam = np.array([5.0, 10, 15, 20, 25, 30])
    model = build_pinocchio_model(ur5)
    data = model.createData()
    for q, qd, q_ref, qd_ref, qdd_ref in _random_states(11):
        s = (qd_ref - qd) + lam * (q_ref - q)
        qr_d, qr_dd = qd_ref + lam * (q_ref - q), qdd_ref + lam * (qd_ref - qd)
        mass = pin.crba(model, data, q).copy()
        coriolis = pin.computeCoriolisMatrix(model, data, q, qd).copy()
        gravity = pin.computeGeneralizedGravity(model, data, q).copy()
        expected = mass @ qr_dd + coriolis @ qr_d + gravity + 7.0 * s
        tau = ctl.compute(q, qd, q_ref, qd_ref, qdd_ref, DT_S)
        np.testing.assert_allclose(tau, expected, rtol=1e-10, atol=1e-9)


def test_passivity_default_gains_put_the_cascade_poles_at_the_target(ur5):
    """(s + Lambda)(s + Kd/m_jj) = s^2 + 2 zeta w s + w^2 for zeta >= 1 (numpy's roots)."""
    model = build_mujoco_model(ur5)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = np.zeros((6, 6))
    mujoco.mj_fullM(model, data, mass)
    for w, zeta in ((40.0, 1.0), (25.0, 1.5)):
        g = make_controller("passivity", ur5, {"omega_n_rad_s": w, "zeta": zeta}).gains_in_effect()
        poles = np.sort(np.stack([g["lambda"], np.array(g["kd"]) / np.diag(mass)]), axis=0)
        target = np.sort(-np.real(np.roots([1.0, 2 * zeta * w, w**2])))
        np.testing.assert_allclose(poles, np.repeat(target[:, None], 6, axis=1), rtol=1e-9)


def test_passivity_tracks_the_ideal_plant_about_as_well_as_ctc(ur5):
    """Bound checked: on joints 1-5 passivity's max error is within 1.25x CTC's (both a
    double pole at -40 rad/s with an exact model; measured 0.5-1.0x)."""
    ctc = _max_error(ur5, "ctc")
    passivity = _max_error(ur5, "passivity")
    assert (passivity[:5] <= 1.25 * ctc[:5]).all(), (passivity, ctc)
    assert passivity.max() < 5e-4


# --- adaptive ---------------------------------------------------------------------


def test_adaptive_regressor_reproduces_the_model_and_passivity_at_nominal(ur5):
    passivity = make_controller("passivity", ur5)
    ctl = make_controller("adaptive", ur5, {"gamma": 0.0})
    model = build_pinocchio_model(ur5)
    data = model.createData()
    theta = nominal_parameters(model)
    for q, qd, q_ref, qd_ref, qdd_ref in _random_states(5):
        np.testing.assert_allclose(
            ctl.regressor(q, qd, qd, qdd_ref) @ theta,
            pin.rnea(model, data, q, qd, qdd_ref),
            rtol=1e-10,
            atol=1e-9,
        )
        np.testing.assert_allclose(
            ctl.compute(q, qd, q_ref, qd_ref, qdd_ref, DT_S),
            passivity.compute(q, qd, q_ref, qd_ref, qdd_ref, DT_S),
            rtol=1e-10,
            atol=1e-9,
        )
    np.testing.assert_array_equal(ctl.estimates(), theta)  # gamma = 0: no adaptation


def _heavier_link(spec, joint, factor):
    joints = list(spec.joints)
    inertial = joints[joint].inertial
    joints[joint] = replace(joints[joint], inertial=replace(inertial, mass=inertial.mass * factor))
    return replace(spec, joints=tuple(joints))


def test_adaptive_estimates_move_toward_the_true_plant_on_a_realistic_plant(ur5):
    """The upper arm (link 2) is 20 % heavier than the model says, with friction, damping
    and encoder noise. Its first moment m c_x, which the gravity torque on the shoulder
    excites, starts 0.36 kg m off and ends within a third of that (measured 0.02);
    the estimate the recording keeps (settings) is the final one."""
    plant = _heavier_link(ur5, 1, 1.2)
    true = nominal_parameters(build_pinocchio_model(plant))
    ctl = make_controller("adaptive", ur5)
    result = run_episode(
        ur5,
        reference=PAPER_MOTION,
        controller=ctl,
        seed=0,
        hold_s=1.0,
        preroll_s=1.0,
        plant_spec=plant,
        plant=PlantOptions(
            frictionloss=(3.0, 3.0, 2.0, 0.8, 0.8, 0.8), damping=(1.0, 1.0, 0.8, 0.3, 0.3, 0.3)
        ),
        position_noise_std_rad=1e-5,
        velocity_noise_std_rad_s=1e-3,
    )
    assert result.ok, result.reason
    k = 10 * 1 + 1  # link 2's m c_x
    before = abs(ctl.nominal()[k] - true[k])
    after = abs(ctl.estimates()[k] - true[k])
    assert before > 0.3 and after < before / 3, (before, after)
    history = ctl.estimate_history()[:, k]
    assert len(history) > 100 and abs(history[len(history) // 2] - true[k]) < before
    recorded = result.gains_in_effect["estimates"]
    assert recorded["mass_kg"] == pytest.approx(ctl.estimates()[0:60:10].tolist())
    assert json.loads(json.dumps(result.gains_in_effect))


def test_adaptive_projection_keeps_the_estimates_in_their_box_and_masses_positive(ur5):
    ctl = make_controller("adaptive", ur5, {"gamma": 1e6, "box_rel": 0.3})
    lower, upper = ctl.bounds()
    masses = slice(0, 60, 10)
    np.testing.assert_allclose(lower[masses], 0.7 * ctl.nominal()[masses])
    for state in _random_states(9, count=50):
        ctl.compute(*state, 0.01)
    theta = ctl.estimates()
    assert ((theta >= lower) & (theta <= upper)).all()
    assert (theta[masses] > 0).all()
    assert np.isclose(theta, lower).sum() + np.isclose(theta, upper).sum() > 20  # it pushed
    ctl.reset()
    np.testing.assert_array_equal(ctl.estimates(), ctl.nominal())
    assert ctl.estimate_history().shape == (0, adaptive.PARAMS_PER_LINK * 6 + 6)
    with pytest.raises(ParamsError, match=r"^gains\.box_rel: must be < 1"):
        make_controller("adaptive", ur5, {"box_rel": 1.0})
