"""The episode runner: closed-loop physics, divergence, saturation, noise, settings."""

from __future__ import annotations

import dataclasses
import json

import mujoco
import numpy as np
import pytest

from pipeline.control import make_controller
from pipeline.errors import SimulationError, SpecError
from pipeline.model.mjcf import PlantOptions, build_mujoco_model
from pipeline.robots import load_spec
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode

MOTION_S = 2.0
HOLD_S = 1.0


@pytest.fixture(scope="module")
def reference():
    return QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=MOTION_S)


def _run(spec, reference, name="ctc", gains=None, **kwargs):
    kwargs.setdefault("seed", 0)
    kwargs.setdefault("hold_s", HOLD_S)
    return run_episode(
        spec, reference=reference, controller=make_controller(name, spec, gains), **kwargs
    )


def _ideal_double_integrators(result, kp, kd, dt_s, nstep):
    """Eq. 15 in discrete time: qdd = u, integrated as MuJoCo's semi-implicit Euler does."""
    q = result.q_ref[0].copy()
    v = np.zeros_like(q)
    out = np.empty_like(result.q_true)
    for k in range(len(out)):
        out[k] = q
        a = result.qdd_ref[k] + kd * (result.qd_ref[k] - v) + kp * (result.q_ref[k] - q)
        for _ in range(nstep):
            v = v + dt_s * a
            q = q + dt_s * v
    return out


# --- physics sanity ---------------------------------------------------------------


def test_ctc_with_a_perfect_model_is_exactly_a_bank_of_double_integrators(dynamic_robot):
    """Perfect nominal model, no friction, no noise: the nonlinear arm behaves as
    qdd = qdd_r + Kd e' + Kp e (eq. 15-17), to rounding, over the whole episode
    (on semi-implicit Euler, which evaluates the dynamics once per step, where the
    controller did)."""
    spec = dynamic_robot
    reference = QuinticReference.between(
        np.zeros(spec.dof), PAPER_GOAL_RAD[: spec.dof], duration_s=MOTION_S
    )
    result = _run(spec, reference, integrator="Euler")
    assert result.ok, result.reason
    kp = np.array(result.gains_in_effect["kp"])
    kd = np.array(result.gains_in_effect["kd"])
    ideal = _ideal_double_integrators(result, kp, kd, 0.001, 1)
    assert np.abs(result.q_true - ideal).max() < 1e-12


def test_euler_ctc_tracking_error_is_only_the_first_order_integration_error(ur5, reference):
    """On semi-implicit Euler what is left is its position update running dt/2 * qdd
    ahead of the sampled velocity: e ~ zeta dt |qdd_r| / omega_n, halving with dt, ~1e-6
    rad at 10 kHz. Not a model error (previous test)."""
    omega_n, zeta = 40.0, 1.0
    errors = {}
    for dt_s in (0.001, 0.0005, 0.0001):
        result = _run(ur5, reference, physics_dt_s=dt_s, integrator="Euler")
        errors[dt_s] = np.abs(result.q_ref - result.q_true).max()
        predicted = zeta * dt_s * np.abs(result.qdd_ref).max() / omega_n
        assert errors[dt_s] == pytest.approx(predicted, rel=0.05)
    assert errors[0.001] / errors[0.0005] == pytest.approx(2.0, rel=0.05)
    assert errors[0.0001] < 5e-6


def test_rk4_plant_leaves_ctc_only_the_sampling_error(ur5, reference):
    """The default plant (RK4) under a 1 kHz zero-order-hold controller: CTC's residual
    is the sampling's (the torque held while the arm moves), not the integrator's. It
    does not move when the physics step halves or quarters at the same control rate,
    and is over 10x below semi-implicit Euler's at the control period."""
    errors = {}
    for steps in (1, 2, 4):
        result = _run(ur5, reference, physics_dt_s=0.001 / steps, control_period_steps=steps)
        assert result.integrator == "RK4"
        errors[steps] = np.abs(result.q_ref - result.q_true).max()
    assert errors[2] == pytest.approx(errors[4], rel=1e-3)
    assert errors[1] == pytest.approx(errors[4], rel=1e-3)
    euler = _run(ur5, reference, integrator="Euler")
    assert np.abs(euler.q_ref - euler.q_true).max() > 10 * errors[4]


@pytest.mark.parametrize("name", ["ctc", "pid", "pd_gravity"])
def test_every_controller_reaches_the_goal_after_the_hold(ur5, reference, name):
    result = _run(ur5, reference, name)
    assert result.ok, result.reason
    assert np.abs(result.q_true[-1] - np.array(PAPER_GOAL_RAD)).max() < 1e-4
    assert np.abs(result.qd_true[-1]).max() < 1e-3
    assert not result.saturated.any()


def test_ctc_beats_pid_on_max_tracking_error_at_fair_default_gains(ur5, reference):
    results = {name: _run(ur5, reference, name) for name in ("ctc", "pid")}
    errors = {name: np.abs(r.q_ref - r.q).max(axis=0) for name, r in results.items()}
    assert (errors["ctc"] < errors["pid"]).all(), errors
    # joint 1 is the paper's headline comparison (its Fig. 5 and the 45.9 % figure)
    assert errors["ctc"][0] < 0.5 * errors["pid"][0]


def test_ctc_with_payload_and_damping_settles_where_its_stiffness_predicts(ur5, reference):
    """No integral action in eq. 18: at rest, M_n Kp e = g_plant - g_nominal.

    Viscous damping is sized per joint like the drives (the 28 N m wrist joints get
    less): a 1 N m s/rad damper on wrist 3, whose nominal inertia is 1.3e-4 kg m^2,
    would make it creep for seconds, which is physics but not this test's point.
    """
    plant = PlantOptions(damping=(2.0, 2.0, 1.0, 0.1, 0.1, 0.01), payload_kg=2.0)
    result = _run(ur5, reference, plant=plant)
    assert result.ok, result.reason
    q = result.q_true[-1]
    assert np.abs(result.qd_true[-1]).max() < 1e-5

    def mass_and_gravity(model):
        data = mujoco.MjData(model)
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        mass = np.zeros((model.nv, model.nv))
        mujoco.mj_fullM(model, data, mass)
        return mass, data.qfrc_bias.copy()

    mass_n, gravity_n = mass_and_gravity(build_mujoco_model(ur5))
    _, gravity_p = mass_and_gravity(build_mujoco_model(ur5, plant=plant))
    kp = np.array(result.gains_in_effect["kp"])
    predicted = np.linalg.solve(mass_n, gravity_p - gravity_n) / kp
    error = result.q_ref[-1] - q
    np.testing.assert_allclose(error, predicted, atol=1e-6)
    # the heavy joints reach the goal; the light wrist yields to the payload's torque
    assert np.abs(error[:3]).max() < 5e-3


# --- divergence, saturation ---------------------------------------------------------


def test_absurd_gain_is_reported_as_diverged_not_raised(ur5, reference):
    # without rotor armature the wrist's tiny inertia lets saturated torque spin it away
    bare = dataclasses.replace(
        ur5, joints=tuple(dataclasses.replace(j, armature=0.0) for j in ur5.joints)
    )
    result = _run(bare, reference, gains={"kp": 1e9})
    assert result.status == "diverged" and not result.ok
    assert "t=" in result.reason and "velocity limit" in result.reason
    assert any(name in result.reason for name in ur5.joint_names)
    rows = len(result.stamp_ns)
    assert 0 < rows < result.rows_planned
    for arr in (result.q, result.q_true, result.tau_cmd_nm, result.tau_nm, result.saturated):
        assert len(arr) == rows
    assert np.isfinite(result.q_true).all()


@pytest.mark.parametrize("elbow_limit_scale", [1.0, 50.0])
def test_divergence_is_declared_at_the_first_row_a_joint_exceeds_the_speed_factor(
    ur5, reference, elbow_limit_scale
):
    # the loop's cheap speed pre-test (|qd| against the slowest joint's limit) must never
    # hide a joint over its own limit, also when the limits differ by far
    joints = tuple(
        dataclasses.replace(
            j, limits=dataclasses.replace(j.limits, velocity=j.limits.velocity * elbow_limit_scale)
        )
        if j.name == "elbow_joint"
        else j
        for j in ur5.joints
    )
    spec = dataclasses.replace(ur5, joints=joints)
    free = _run(spec, reference, divergence_speed_factor=1e6)
    ratio = np.abs(free.qd_true) / spec.velocity_limits
    factor = 0.5 * float(ratio.max())
    k = int(np.argmax((ratio > factor).any(axis=1)))
    result = _run(spec, reference, divergence_speed_factor=factor)
    assert result.status == "diverged"
    assert len(result.stamp_ns) == k
    assert spec.joint_names[int(np.argmax(ratio[k]))] in result.reason
    np.testing.assert_array_equal(result.q_true, free.q_true[:k])


class _NanAfter:
    """A controller that breaks: NaN torque on one joint from ``t_s`` on."""

    name = "nan_after"

    def __init__(self, spec, t_s, joint):
        self._inner = make_controller("ctc", spec)
        self._t_s, self._joint, self._now = t_s, joint, 0.0

    def gains_in_effect(self):
        return {}

    def reset(self):
        self._now = 0.0

    def compute(self, q, qd, q_ref, qd_ref, qdd_ref, dt_s):
        tau = self._inner.compute(q, qd, q_ref, qd_ref, qdd_ref, dt_s)
        if self._now >= self._t_s - 1e-9:
            tau[self._joint] = np.nan
        self._now += dt_s
        return tau


def test_non_finite_torque_is_reported_as_diverged_with_the_joint(ur5, reference):
    result = run_episode(ur5, reference=reference, controller=_NanAfter(ur5, 0.5, 2), seed=0)
    assert result.status == "diverged"
    assert "t=0.5000 s" in result.reason
    assert "non-finite torque for elbow_joint" in result.reason
    assert len(result.stamp_ns) == 500
    assert np.isfinite(result.tau_cmd_nm).all()


def test_mujoco_warning_ends_the_episode_with_its_name(ur5):
    absurd = QuinticReference.between([1e11, 0, 0, 0, 0, 0], PAPER_GOAL_RAD, duration_s=1.0)
    result = _run(ur5, absurd)
    assert result.status == "diverged"
    assert "mjWARN_BADQPOS" in result.reason and "shoulder_pan_joint" in result.reason
    assert result.mujoco_warnings.get("mjWARN_BADQPOS", 0) >= 1


def test_runner_restores_the_mujoco_warning_handler(ur5):
    def mine(text):
        pass

    mujoco.set_mju_user_warning(mine)
    try:
        absurd = QuinticReference.between([1e11, 0, 0, 0, 0, 0], PAPER_GOAL_RAD, duration_s=1.0)
        _run(ur5, absurd)
        assert mujoco.get_mju_user_warning() is mine
    finally:
        mujoco.set_mju_user_warning(None)


def test_saturation_is_counted_per_joint_and_the_applied_torque_is_clipped(ur5):
    # 0.15 s for the Table 2 motion needs ~3.4x the shoulder's 150 N m
    fast = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=0.15)
    result = _run(ur5, fast)
    effort = ur5.effort_limits
    assert result.saturated.any()
    np.testing.assert_array_equal(result.saturated, np.abs(result.tau_cmd_nm) > effort)
    np.testing.assert_array_equal(result.tau_nm, np.clip(result.tau_cmd_nm, -effort, effort))
    assert result.saturation_counts == result.saturated.sum(axis=0).tolist()
    assert result.saturation_counts[1] > 10


# --- noise, control period ------------------------------------------------------------


def test_sensor_noise_is_reproducible_with_the_seed_and_changes_with_another(ur5, reference):
    noise = {"position_noise_std_rad": 1e-4, "velocity_noise_std_rad_s": 1e-3}
    a = _run(ur5, reference, "pid", seed=1, **noise)
    b = _run(ur5, reference, "pid", seed=1, **noise)
    c = _run(ur5, reference, "pid", seed=2, **noise)
    for field in ("q", "qd", "q_true", "tau_cmd_nm"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
        assert not np.array_equal(getattr(a, field), getattr(c, field))
    pos_noise = a.q - a.q_true
    vel_noise = a.qd - a.qd_true
    assert pos_noise.std() == pytest.approx(1e-4, rel=0.05)
    assert vel_noise.std() == pytest.approx(1e-3, rel=0.05)
    assert abs(pos_noise.mean()) < 1e-5
    assert a.seed == 1


def test_noise_free_measurement_is_the_true_state(ur5, reference):
    result = _run(ur5, reference)
    np.testing.assert_array_equal(result.q, result.q_true)
    np.testing.assert_array_equal(result.qd, result.qd_true)


@pytest.mark.parametrize("steps", [2, 5])
def test_slower_control_period_holds_the_torque_and_still_tracks(ur5, reference, steps):
    result = _run(ur5, reference, control_period_steps=steps)
    assert result.ok, result.reason
    assert np.diff(result.stamp_ns).tolist() == [steps * 1_000_000] * (len(result.stamp_ns) - 1)
    assert len(result.stamp_ns) == round((MOTION_S + HOLD_S) / (steps * 0.001)) + 1
    # a held torque is no longer a held acceleration (M and h change within the
    # period): small extra error, still ~1e-4 rad, and the goal is reached
    assert np.abs(result.q_ref - result.q_true).max() < 2e-4
    assert np.abs(result.q_true[-1] - np.array(PAPER_GOAL_RAD)).max() < 1e-6


def test_pid_runs_at_a_2_step_control_period(ur5, reference):
    result = _run(ur5, reference, "pid", control_period_steps=2)
    assert result.ok, result.reason
    assert np.abs(result.q_true[-1] - np.array(PAPER_GOAL_RAD)).max() < 1e-4


# --- the result's layout ---------------------------------------------------------------


def test_result_rows_are_control_instants_from_rest_at_the_reference_start(ur5, reference):
    result = _run(ur5, reference)
    n = round((MOTION_S + HOLD_S) / 0.001) + 1
    assert result.joint_names == ur5.joint_names
    assert result.stamp_ns.dtype == np.int64
    np.testing.assert_array_equal(result.stamp_ns, np.arange(n) * 1_000_000)
    for field in ("q", "qd", "q_true", "qd_true", "q_ref", "qd_ref", "qdd_ref", "tau_nm"):
        assert getattr(result, field).shape == (n, 6)
    np.testing.assert_array_equal(result.q_true[0], reference.sample(0.0)[0])
    np.testing.assert_array_equal(result.qd_true[0], np.zeros(6))
    q_ref, qd_ref, _ = reference.sample(1.234)
    np.testing.assert_allclose(result.q_ref[1234], q_ref, atol=1e-15)
    np.testing.assert_allclose(result.qd_ref[1234], qd_ref, atol=1e-15)
    assert result.status == "ok" and result.reason == "" and result.mujoco_warnings == {}
    with pytest.raises(ValueError, match="read-only"):
        result.q[0, 0] = 1.0
    assert result.controller == "ctc"
    assert json.loads(json.dumps(result.gains_in_effect))["kp"] == [1600.0] * 6
    assert result.physics_dt_s == 0.001 and result.control_period_steps == 1
    assert result.saturation_counts == [0] * 6


def test_progress_rises_to_one_in_about_a_hundred_calls(ur5, reference):
    fractions = []
    _run(ur5, reference, progress=fractions.append)
    assert 90 <= len(fractions) <= 110
    assert fractions == sorted(fractions)
    assert fractions[-1] == 1.0 and 0.0 < fractions[0] < 0.05


class _SampleOnly:
    """A reference with only the protocol's ``sample`` (no vectorized path)."""

    def __init__(self, inner):
        self._inner = inner

    @property
    def duration_s(self):
        return self._inner.duration_s

    def sample(self, t_s):
        return self._inner.sample(t_s)


def test_reference_without_sample_many_gives_the_same_episode(ur5, reference):
    a = _run(ur5, reference, "pid")
    b = _run(ur5, _SampleOnly(reference), "pid")
    np.testing.assert_array_equal(a.q_ref, b.q_ref)
    np.testing.assert_array_equal(a.q_true, b.q_true)


# --- refusals ----------------------------------------------------------------------------


class _Zero:
    name = "zero"

    def gains_in_effect(self):
        return {}

    def reset(self):
        pass

    def compute(self, q, qd, q_ref, qd_ref, qdd_ref, dt_s):
        return np.zeros(len(q))


def test_kinematics_only_robot_is_refused_with_a_clear_error():
    mdh = load_spec("mdh_example")
    reference = QuinticReference.between(np.zeros(6), np.full(6, 0.1), duration_s=1.0)
    with pytest.raises(SpecError, match=r"kinematics-only .* simulation needs link dynamics"):
        run_episode(mdh, reference=reference, controller=_Zero(), seed=0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"control_period_steps": 0}, "control_period_steps: expected an integer >= 1"),
        ({"control_period_steps": 2.5}, "control_period_steps"),
        ({"physics_dt_s": 0.0}, "physics_dt_s: expected a positive time step"),
        ({"hold_s": -1.0}, "hold_s: expected a finite number >= 0"),
        ({"position_noise_std_rad": -1e-3}, "position_noise_std_rad"),
        ({"velocity_noise_std_rad_s": float("nan")}, "velocity_noise_std_rad_s"),
        ({"seed": -1}, "seed: expected a non-negative integer"),
        ({"divergence_speed_factor": 0.0}, "divergence_speed_factor"),
    ],
)
def test_bad_settings_are_refused_in_one_line(ur5, reference, kwargs, match):
    kwargs = {"seed": 0, **kwargs}
    with pytest.raises(SimulationError, match=match) as err:
        run_episode(ur5, reference=reference, controller=_Zero(), **kwargs)
    assert "\n" not in str(err.value)


def test_reference_with_the_wrong_joint_count_is_refused(ur5):
    five = QuinticReference.between(np.zeros(5), np.ones(5), duration_s=1.0)
    with pytest.raises(
        SimulationError, match=r"reference: position samples have shape \(2001, 5\)"
    ):
        run_episode(ur5, reference=five, controller=_Zero(), seed=0)


def test_non_finite_reference_is_refused_with_the_joint_and_time(ur5, reference):
    class Broken(_SampleOnly):
        def sample(self, t_s):
            q, qd, qdd = self._inner.sample(t_s)
            if t_s > 1.0:
                qd = qd.copy()
                qd[3] = np.inf
            return q, qd, qdd

    with pytest.raises(SimulationError, match=r"velocity of wrist_1_joint is inf at t=1\.0010"):
        run_episode(ur5, reference=Broken(reference), controller=_Zero(), seed=0)


@pytest.mark.parametrize("torque", [np.zeros(5), np.zeros(1), 0.0])
def test_controller_returning_the_wrong_size_is_a_clear_error(ur5, reference, torque):
    class Wrong(_Zero):
        def compute(self, q, qd, q_ref, qd_ref, qdd_ref, dt_s):
            return torque

    with pytest.raises(SimulationError, match=r"controller 'zero' failed at t=0\.0000 s"):
        run_episode(ur5, reference=reference, controller=Wrong(), seed=0)


def test_recorded_applied_torque_is_what_the_plant_felt_even_when_saturated(ur5):
    """Replaying tau_nm open loop on a fresh plant reproduces the recorded states exactly."""
    import mujoco

    from pipeline.model.mjcf import build_mujoco_model

    fast = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=0.15)
    result = _run(ur5, fast)
    assert result.saturated.any()
    model = build_mujoco_model(ur5)
    data = mujoco.MjData(model)
    data.qpos[:] = result.q_true[0]
    for k in range(len(result.stamp_ns) - 1):
        np.testing.assert_array_equal(data.qpos, result.q_true[k])
        data.ctrl[:] = result.tau_nm[k]
        mujoco.mj_step(model, data)
