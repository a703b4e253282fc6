"""Controllers: registry, gain validation, and each control law against an independent engine."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from pipeline.control import (
    CONTROLLERS,
    DEFAULT_OMEGA_N_RAD_S,
    DEFAULT_ZETA,
    UnknownControllerError,
    controller_names,
    default_gains,
    make_controller,
)
from pipeline.errors import ParamsError, PipelineError, SpecError
from pipeline.model.mjcf import build_mujoco_model
from pipeline.robots import load_spec
from pipeline.sim.references import PAPER_GOAL_RAD

DT_S = 0.001


def _mujoco_mass_and_bias(spec, q, qd=None):
    """Mass matrix and bias torques from MuJoCo (independent of Pinocchio)."""
    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    data.qpos[:] = q
    data.qvel[:] = 0.0 if qd is None else qd
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    return mass, data.qfrc_bias.copy()


# --- registry ---------------------------------------------------------------------


def test_registry_offers_the_paper_baselines_among_its_built_ins():
    assert {"pid", "ctc", "ctc_pid", "pd_gravity"} <= set(controller_names())
    assert controller_names() == tuple(sorted(CONTROLLERS))


@pytest.mark.parametrize("name", controller_names())
def test_each_entry_declares_its_gains_with_units_and_a_one_line_description(name):
    entry = CONTROLLERS[name]
    assert entry.gain_specs and all(g.unit or g.flag for g in entry.gain_specs)
    assert entry.summary and "\n" not in entry.summary


@pytest.mark.parametrize("name", controller_names())
def test_each_controller_reports_its_registry_name(ur5, name):
    assert make_controller(name, ur5).name == name


def test_unknown_controller_lists_the_valid_names(ur5):
    with pytest.raises(UnknownControllerError) as err:
        make_controller("ctcc", ur5)
    message = str(err.value)
    assert isinstance(err.value, PipelineError)
    assert "'ctcc'" in message and "did you mean 'ctc'" in message
    assert ", ".join(controller_names()) in message
    assert "\n" not in message


def test_unknown_controller_for_default_gains_is_refused_too(ur5):
    with pytest.raises(UnknownControllerError, match=f"valid: {', '.join(controller_names())}"):
        default_gains(ur5, "lqr")


# --- gains ------------------------------------------------------------------------


def test_unknown_gain_key_names_the_key_and_the_valid_ones(ur5):
    with pytest.raises(ParamsError) as err:
        make_controller("pid", ur5, {"Kp": 1.0})
    message = str(err.value)
    assert message.startswith("gains.Kp: unknown pid gain 'Kp'")
    assert "did you mean 'kp'" in message
    assert "kp, ki, kd, i_clamp_min, i_clamp_max, antiwindup, ff_velocity_scale" in message
    assert "\n" not in message


def test_errors_name_the_params_entry_they_came_from(ur5):
    with pytest.raises(ParamsError, match=r"^controllers\.slow\.gains\.kd: must be >= 0"):
        make_controller("pid", ur5, {"kd": -1.0}, source="controllers.slow")
    with pytest.raises(
        UnknownControllerError, match=r"^controllers\.slow\.type: unknown controller"
    ):
        make_controller("pdi", ur5, source="controllers.slow")
    with pytest.raises(ParamsError, match=r"^gains: expected a mapping"):
        make_controller("ctc", ur5, [1.0, 2.0])


def test_wrong_length_gain_vector_names_the_key_and_the_expected_count(ur5):
    with pytest.raises(ParamsError, match=r"gains\.kd: expected a number or a list of 6 .* got 5"):
        make_controller("ctc", ur5, {"kd": [1.0] * 5})


@pytest.mark.parametrize(
    ("gains", "match"),
    [
        ({"kp": -1.0}, r"gains\.kp: must be >= 0"),
        ({"kp": "high"}, r"gains\.kp: expected a number"),
        ({"kp": [1, 2, 3, 4, 5, float("nan")]}, r"gains\.kp: must be finite"),
        ({"kp": True}, r"gains\.kp: expected a number"),
        ({"antiwindup": 1}, r"gains\.antiwindup: expected true or false"),
        ({"i_clamp_min": 5.0, "i_clamp_max": 1.0}, r"gains\.i_clamp_min: must be <= i_clamp_max"),
    ],
)
def test_bad_gain_values_are_refused_with_the_key(ur5, gains, match):
    with pytest.raises(ParamsError, match=match):
        make_controller("pid", ur5, gains)


def test_scalar_gain_applies_to_every_joint_and_settings_report_every_gain(ur5):
    ctl = make_controller("pid", ur5, {"kp": 100.0, "ff_velocity_scale": [0, 0, 0, 0, 0, 0.5]})
    settings = ctl.gains_in_effect()
    assert set(settings) == {
        "kp",
        "ki",
        "kd",
        "i_clamp_min",
        "i_clamp_max",
        "antiwindup",
        "ff_velocity_scale",
        "omega_n_rad_s",
        "zeta",
        "design_at",
        "design_inertia_kg_m2",
    }
    assert settings["kp"] == [100.0] * 6
    assert settings["ff_velocity_scale"] == [0.0] * 5 + [0.5]
    # keys not given keep their defaults
    assert settings["kd"] == pytest.approx(default_gains(ur5, "pid")["kd"])
    assert json.loads(json.dumps(settings)) == settings


@pytest.mark.parametrize(
    ("name", "design"),
    [("ctc", set()), ("pd_gravity", {"design_at", "design_inertia_kg_m2"})],
)
def test_model_based_settings_are_json_and_complete(ur5, name, design):
    """CTC's gains do not depend on the configuration, so no design configuration is
    recorded for it; pd_gravity's are scaled by the inertia there, so it is."""
    settings = make_controller(name, ur5).gains_in_effect()
    assert set(settings) == {"kp", "kd", "omega_n_rad_s", "zeta"} | design
    assert json.loads(json.dumps(settings)) == settings


def test_model_based_controllers_need_dynamics():
    mdh = load_spec("mdh_example")
    for name in ("ctc", "ctc_pid", "pd_gravity", "pid"):
        with pytest.raises(SpecError, match="kinematics-only"):
            make_controller(name, mdh)


def test_decoupled_design_scales_each_joint_by_its_own_inertia(ur5):
    """kp/m_jj = w^2 and kd/m_jj = 2 zeta w, with m_jj from MuJoCo (not Pinocchio)."""
    w, zeta = 25.0, 0.8
    mass, _ = _mujoco_mass_and_bias(ur5, np.zeros(6))
    m = np.diag(mass)
    for name in ("pid", "pd_gravity"):
        g = default_gains(ur5, name, omega_n_rad_s=w, zeta=zeta)
        np.testing.assert_allclose(np.array(g["kp"]) / m, w**2, rtol=1e-9)
        np.testing.assert_allclose(np.array(g["kd"]) / m, 2 * zeta * w, rtol=1e-9)
    ctc = default_gains(ur5, "ctc", omega_n_rad_s=w, zeta=zeta)
    assert ctc == {"kp": [w**2] * 6, "kd": [2 * zeta * w] * 6}
    pid = default_gains(ur5, "pid", omega_n_rad_s=w, zeta=zeta)
    np.testing.assert_allclose(np.array(pid["ki"]) / m, 0.1 * w**3, rtol=1e-9)
    assert pid["i_clamp_max"] == ur5.effort_limits.tolist()
    assert pid["i_clamp_min"] == (-ur5.effort_limits).tolist()


def test_default_gains_are_the_stated_defaults(ur5):
    assert default_gains(ur5, "ctc") == default_gains(
        ur5, "ctc", omega_n_rad_s=DEFAULT_OMEGA_N_RAD_S, zeta=DEFAULT_ZETA
    )


@pytest.mark.parametrize("bad", [0.0, -3.0, float("inf")])
def test_default_gains_refuse_a_non_positive_frequency(ur5, bad):
    with pytest.raises(ParamsError, match="omega_n_rad_s"):
        default_gains(ur5, "pid", omega_n_rad_s=bad)


# --- control laws -----------------------------------------------------------------


def test_ctc_makes_the_mujoco_plant_accelerate_exactly_as_commanded(dynamic_robot):
    """Eq. 15: with the nominal model equal to the plant, qdd = qdd_r + Kd e' + Kp e."""
    spec = dynamic_robot
    ctl = make_controller("ctc", spec, {"kp": [50.0, 80, 120, 200, 300, 400], "kd": 14.0})
    kp = np.array(ctl.gains_in_effect()["kp"])
    kd = np.array(ctl.gains_in_effect()["kd"])
    model = build_mujoco_model(spec)
    # random poses put links through the floor and each other: contact forces are
    # not part of eq. 15
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(7)
    for _ in range(20):
        q, q_ref = rng.uniform(-np.pi, np.pi, (2, spec.dof))
        qd, qd_ref, qdd_ref = rng.normal(0.0, 1.0, (3, spec.dof))
        tau = ctl.compute(q, qd, q_ref, qd_ref, qdd_ref, DT_S)
        data.qpos[:] = q
        data.qvel[:] = qd
        data.ctrl[:] = 0.0
        data.qfrc_applied[:] = tau  # unclipped: this checks the model, not the motors
        mujoco.mj_forward(model, data)
        commanded = qdd_ref + kd * (qd_ref - qd) + kp * (q_ref - q)
        np.testing.assert_allclose(data.qacc, commanded, rtol=1e-8, atol=1e-8)


def test_pd_gravity_holds_a_resting_arm_still_where_mujoco_agrees(ur5):
    ctl = make_controller("pd_gravity", ur5)
    q = np.array([0.3, -1.0, 1.2, -0.4, 0.8, 0.1])
    zero = np.zeros(6)
    tau = ctl.compute(q, zero, q, zero, zero, DT_S)
    _, gravity = _mujoco_mass_and_bias(ur5, q)
    np.testing.assert_allclose(tau, gravity, rtol=1e-9, atol=1e-12)


def test_pd_gravity_adds_pd_on_position_and_velocity_error(ur5):
    ctl = make_controller("pd_gravity", ur5, {"kp": 10.0, "kd": 2.0})
    q = np.zeros(6)
    zero = np.zeros(6)
    at_rest = ctl.compute(q, zero, q, zero, zero, DT_S)
    q_ref = np.full(6, 0.1)
    qd = np.full(6, -0.5)
    tau = ctl.compute(q, qd, q_ref, zero, zero, DT_S)
    np.testing.assert_allclose(tau - at_rest, 10.0 * 0.1 + 2.0 * 0.5)


def test_pid_is_p_on_position_error_and_d_on_velocity_error_without_derivative_kick(ur5):
    ctl = make_controller("pid", ur5, {"kp": 3.0, "kd": 0.5, "ki": 0.0})
    zero = np.zeros(6)
    # a reference step: the D term sees the velocity error only, so no spike
    tau = ctl.compute(zero, zero, np.full(6, 0.2), zero, zero, DT_S)
    np.testing.assert_allclose(tau, 3.0 * 0.2)
    tau = ctl.compute(zero, np.full(6, 1.0), zero, np.full(6, 3.0), zero, DT_S)
    np.testing.assert_allclose(tau, 0.5 * (3.0 - 1.0))


def test_pid_integrator_clamps_its_state_with_antiwindup_like_control_toolbox(ur5):
    """i_term += ki dt e; antiwindup clamps the state, otherwise only the output."""
    zero = np.zeros(6)
    common = {"kp": 0.0, "kd": 0.0, "ki": 10.0, "i_clamp_min": -0.5, "i_clamp_max": 0.5}
    dt = 0.01  # ki dt e = 0.1 per step for e = 1
    outputs = {}
    for antiwindup in (True, False):
        ctl = make_controller("pid", ur5, {**common, "antiwindup": antiwindup})
        for _ in range(10):  # state would reach 1.0
            up = ctl.compute(zero, zero, np.ones(6), zero, zero, dt)
        np.testing.assert_allclose(up, 0.5)
        down = ctl.compute(zero, zero, -np.ones(6), zero, zero, dt)
        outputs[antiwindup] = down
    np.testing.assert_allclose(outputs[True], 0.4)  # clamped state 0.5 - 0.1
    np.testing.assert_allclose(outputs[False], 0.5)  # wound-up state 0.9, output clamp 0.5


def test_pid_reset_forgets_the_integral(ur5):
    ctl = make_controller("pid", ur5, {"kp": 0.0, "kd": 0.0, "ki": 1.0})
    zero = np.zeros(6)
    first = ctl.compute(zero, zero, np.ones(6), zero, zero, 0.1).copy()
    ctl.compute(zero, zero, np.ones(6), zero, zero, 0.1)
    ctl.reset()
    again = ctl.compute(zero, zero, np.ones(6), zero, zero, 0.1)
    np.testing.assert_allclose(again, first)
    np.testing.assert_allclose(first, 0.1)


def test_pid_velocity_feed_forward_scales_the_reference_velocity(ur5):
    scale = [0.0, 1.0, 2.0, 0.0, 0.0, 4.0]
    ctl = make_controller("pid", ur5, {"kp": 0.0, "kd": 0.0, "ki": 0.0, "ff_velocity_scale": scale})
    qd_ref = np.full(6, 0.5)
    tau = ctl.compute(np.zeros(6), qd_ref, np.zeros(6), qd_ref, np.zeros(6), DT_S)
    np.testing.assert_allclose(tau, np.array(scale) * 0.5)


@pytest.mark.parametrize("name", controller_names())
def test_tuning_knobs_choose_the_defaults_and_explicit_gains_override_them(ur5, name):
    from pipeline.control import default_gains

    first, second = [g.key for g in CONTROLLERS[name].gain_specs if not g.flag][:2]
    fast = make_controller(name, ur5, {"omega_n_rad_s": 60.0, "zeta": 0.8})
    expected = default_gains(ur5, name, omega_n_rad_s=60.0, zeta=0.8)
    settings = fast.gains_in_effect()
    assert settings["omega_n_rad_s"] == 60.0 and settings["zeta"] == 0.8
    for key, value in expected.items():
        assert np.broadcast_to(settings[key], ur5.dof) == pytest.approx(
            np.broadcast_to(value, ur5.dof)
        )
    override = make_controller(name, ur5, {"omega_n_rad_s": 60.0, first: 5.0}).gains_in_effect()
    assert override[first] == [5.0] * ur5.dof
    assert np.broadcast_to(override[second], ur5.dof) == pytest.approx(
        np.broadcast_to(default_gains(ur5, name, omega_n_rad_s=60.0)[second], ur5.dof)
    )


def test_tuning_knobs_are_not_reported_when_explicit_gains_override_them_all(ur5):
    settings = make_controller("ctc", ur5, {"kp": 900.0, "kd": 60.0}).gains_in_effect()
    assert "omega_n_rad_s" not in settings and "zeta" not in settings
    assert settings["kp"] == [900.0] * ur5.dof


def test_bad_tuning_knob_names_the_key(ur5):
    with pytest.raises(ParamsError, match=r"controllers\.ctc\.gains\.zeta: expected a positive"):
        make_controller("ctc", ur5, {"zeta": -1.0}, source="controllers.ctc")


def _closed_loop_poles(spec, name, q0):
    """Eigenvalues of the MuJoCo plant + controller, linearized at rest at q0 (FD)."""
    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    ctl = make_controller(name, spec)
    n = spec.dof
    zero = np.zeros(n)

    def flow(x):
        q, qd = x[:n], x[n:]
        data.qpos[:], data.qvel[:] = q, qd
        data.ctrl[:] = ctl.compute(q, qd, q0, zero, zero, 0.001)
        mujoco.mj_forward(model, data)
        return np.concatenate([qd, data.qacc])

    x0, h = np.concatenate([q0, zero]), 1e-6
    jac = np.column_stack([(flow(x0 + h * e) - flow(x0 - h * e)) / (2 * h) for e in np.eye(2 * n)])
    return np.linalg.eigvals(jac)


@pytest.mark.parametrize("q0", [np.zeros(6), np.array(PAPER_GOAL_RAD)], ids=["zeros", "goal"])
def test_ctc_places_every_closed_loop_pole_at_the_design_frequency_on_mujoco(ur5, q0):
    poles = _closed_loop_poles(ur5, "ctc", q0)
    np.testing.assert_allclose(poles.real, -DEFAULT_OMEGA_N_RAD_S, atol=0.01)
    assert np.abs(poles.imag).max() < 0.01  # zeta = 1: critically damped


def test_decentralized_pd_poles_spread_with_the_arms_coupling(ur5):
    """The per-joint design targets -40 rad/s, but the shoulder/elbow coupling (that CTC
    cancels) moves the real poles from about -22 to about -280 rad/s at q = 0 (with the
    estimated armature 0.4/0.4/0.2/0.04 kg m^2; -830 with 0.1 on every joint, where the
    links' coupling weighs more); the fastest bounds the control period (explicit-Euler-
    like bound T < 2 / 280 s ~ 7 ms)."""
    poles = _closed_loop_poles(ur5, "pd_gravity", np.zeros(6))
    assert poles.real.min() < -5 * DEFAULT_OMEGA_N_RAD_S
    assert poles.real.max() > -0.6 * DEFAULT_OMEGA_N_RAD_S
    assert (poles.real < 0).all()


# --- per-step arithmetic: the buffered laws are their plain formulas, bit for bit --------


def _plain_pid(g, state, e_int, dt):
    """control_toolbox::Pid as the plain expressions (the law before its buffers)."""
    q, qd, q_ref, qd_ref, _ = state
    e = q_ref - q
    e_int += g["ki"] * dt * e
    if g["antiwindup"]:
        np.minimum(e_int, g["i_clamp_max"], out=e_int)
        np.maximum(e_int, g["i_clamp_min"], out=e_int)
        i_out = e_int
    else:
        i_out = np.maximum(np.minimum(e_int, g["i_clamp_max"]), g["i_clamp_min"])
    tau = g["kp"] * e + g["kd"] * (qd_ref - qd) + i_out
    return tau + g["ff_velocity_scale"] * qd_ref if g["ff_velocity_scale"].any() else tau


def _plain_ctc(spec, g, state, z, dt, *, integral):
    """Eq. 18 (with ctc_pid's clamped integral) as the plain expressions, on Pinocchio."""
    import pinocchio as pin

    from pipeline.control.controller import friction_feedforward
    from pipeline.robots.urdf import build_pinocchio_model

    q, qd, q_ref, qd_ref, qdd_ref = state
    model = build_pinocchio_model(spec)
    if integral:
        e = q_ref - q
        z += e * dt
        np.clip(z, -g["i_clamp"], g["i_clamp"], out=z)
        a = qdd_ref + g["kd"] * (qd_ref - qd) + g["kp"] * e + g["ki"] * z
    else:
        a = qdd_ref + g["kd"] * (qd_ref - qd) + g["kp"] * (q_ref - q)
    tau = pin.rnea(model, model.createData(), q, qd, a).copy()
    friction = friction_feedforward(g, qd_ref) if g.get("friction_ff") else None
    return tau if friction is None else tau + friction


@pytest.mark.parametrize(
    ("name", "gains"),
    [
        ("pid", None),
        ("pid", {"antiwindup": False, "ff_velocity_scale": 0.3, "i_clamp_max": 0.5}),
        ("ctc", None),
        ("ctc", {"kp": 900.0, "kd": 60.0, "friction_ff": True, "friction_coulomb_nm": 2.0}),
        ("ctc_pid", None),
        ("ctc_pid", {"omega_n_rad_s": 30.0, "friction_ff": True, "friction_viscous_nm_s_rad": 1.0}),
    ],
)
def test_each_law_is_its_plain_formula_bit_for_bit_step_after_step(ur5, name, gains):
    # the laws write into preallocated buffers (the hot loop): the same operations in the
    # same order as the plain expressions, so every recording keeps its bytes
    ctl = make_controller(name, ur5, gains)
    g = {k: np.asarray(v) if isinstance(v, list) else v for k, v in ctl.gains_in_effect().items()}
    rng = np.random.default_rng(7)
    z = np.zeros(6)
    for _ in range(50):
        state = tuple(rng.normal(0.0, s, 6) for s in (0.5, 1.0, 0.5, 1.0, 5.0))
        tau = ctl.compute(*state, DT_S).copy()
        if name == "pid":
            expected = _plain_pid(g, state, z, DT_S)
        else:
            expected = _plain_ctc(ur5, g, state, z, DT_S, integral=name == "ctc_pid")
        np.testing.assert_array_equal(tau, expected)
