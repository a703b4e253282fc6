"""Loop realism: actuation delay and jitter, encoder quantisation, encoder velocity."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from pipeline.control import make_controller
from pipeline.errors import SimulationError
from pipeline.settings import LoopSettings
from pipeline.sim.loop import Actuator, Sensor
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode

ARRAYS = ("q", "qd", "q_true", "qd_true", "tau_cmd_nm", "tau_nm", "saturated")


@pytest.fixture(scope="module")
def paper_motion():
    return QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=1.0)


@pytest.fixture(scope="module")
def quick_move():
    """0.02 rad on every joint in 0.1 s: fast enough to excite the PID's fast modes."""
    start = np.asarray(PAPER_START_RAD, dtype=float)
    return QuinticReference.between(start, start + 0.02, duration_s=0.1)


def _run(spec, reference, loop=None, *, name="pid", **kwargs):
    kwargs.setdefault("seed", 3)
    kwargs.setdefault("hold_s", 0.2)
    kwargs.setdefault("preroll_s", 0.5)
    return run_episode(
        spec,
        reference=reference,
        controller=make_controller(name, spec, None),
        loop=loop,
        **kwargs,
    )


def _same(a, b) -> bool:
    return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ARRAYS)


NOISE = {"position_noise_std_rad": 1e-5, "velocity_noise_std_rad_s": 1e-3}


def test_a_zero_delay_loop_is_the_ideal_loop_byte_for_byte(ur5, paper_motion, monkeypatch):
    ideal = _run(ur5, paper_motion, **NOISE)
    assert _same(ideal, _run(ur5, paper_motion, LoopSettings(delay_s=0.0), **NOISE))
    # and the Sensor/Actuator path itself, at zero delay and no quantisation, is too
    monkeypatch.setattr(LoopSettings, "ideal", property(lambda self: False))
    assert _same(ideal, _run(ur5, paper_motion, LoopSettings(), **NOISE))


def test_a_1ms_delay_applies_each_command_one_period_late(ur5, paper_motion):
    result = _run(ur5, paper_motion, LoopSettings(delay_s=0.001))
    assert result.ok, result.reason
    effort = ur5.effort_limits
    assert np.array_equal(result.tau_nm[0], np.zeros(ur5.dof))  # nothing arrived yet
    assert np.array_equal(result.tau_nm[1:], np.clip(result.tau_cmd_nm[:-1], -effort, effort))
    assert result.loop.delay_s == 0.001


def test_a_1ms_delay_measurably_changes_the_pids_error(ur5, quick_move):
    """On a quick move, 1 ms of delay (one control period at 1 kHz) raises the PID's
    max tracking error on every joint (measured 2-3 %) and moves its error trace by
    4-6 % of the error; the runs are deterministic, so this is not noise."""
    runs = [_run(ur5, quick_move, LoopSettings(delay_s=d)) for d in (0.0, 0.001)]
    assert all(r.ok for r in runs)
    k0 = runs[0].motion_start_row
    e0, e1 = ((r.q_ref - r.q_true)[k0:] for r in runs)
    peak0 = np.abs(e0).max(axis=0)
    assert (np.abs(e1).max(axis=0) > 1.01 * peak0).all()
    assert (np.abs(e1 - e0).max(axis=0) > 0.03 * peak0).all()


def test_a_delay_inside_a_control_period_switches_the_torque_at_the_physics_step():
    act = Actuator(LoopSettings(delay_s=0.001), rows=4, nstep=2, physics_dt_s=0.001, seed=0)
    assert act.in_effect.tolist() == [-1, 0, 0, 1, 1, 2, 2, 3]
    tau = np.arange(4.0)[:, None] * np.ones((1, 2))
    seen: list[tuple[int, float]] = []
    ctrl = np.zeros(2)
    act.advance(1, tau, ctrl, lambda n: seen.append((n, float(ctrl[0]))))
    assert seen == [(1, 0.0), (1, 1.0)]
    # the recorded torque of a row: the one in effect at its first physics step
    assert act.applied(tau, 4)[:, 0].tolist() == [0.0, 0.0, 1.0, 2.0]


def test_a_sub_period_delay_runs_in_an_episode(ur5, paper_motion):
    result = _run(
        ur5, paper_motion, LoopSettings(delay_s=0.0005), physics_dt_s=0.0005, control_period_steps=2
    )
    assert result.ok, result.reason
    ideal = _run(ur5, paper_motion, physics_dt_s=0.0005, control_period_steps=2)
    assert not np.array_equal(result.q_true, ideal.q_true)


def test_quantised_positions_sit_on_the_count_grid(ur5, paper_motion):
    counts = 2**14
    step_rad = 2 * math.pi / counts
    result = _run(
        ur5,
        paper_motion,
        LoopSettings(encoder_counts_per_rev=counts),
        position_noise_std_rad=1e-5,
    )
    ticks = result.q / step_rad
    assert np.abs(ticks - np.round(ticks)).max() < 1e-6
    # the nearest count to the noisy position: within half a count plus the noise
    assert np.abs(result.q - result.q_true).max() <= step_rad / 2 + 6e-5
    np.testing.assert_array_equal(result.qd, result.qd_true)  # velocity: plant, no noise


def test_encoder_velocity_of_a_constant_velocity_motion_is_that_velocity_after_settling():
    """The filter's step response, exactly: after one time constant 1 - 1/e of the
    velocity, after 20 the velocity itself."""
    dt_s, tau_s = 0.001, 0.01
    cutoff_hz = 1 / (2 * math.pi * tau_s)
    v = np.array([0.5, -1.2, 3.0])
    sensor = Sensor(
        LoopSettings(velocity="encoder", velocity_cutoff_hz=cutoff_hz), control_dt_s=dt_s
    )
    q0 = np.array([0.1, 0.2, -0.3])
    measured = []
    for k in range(201):
        q_out, v_out = np.empty(3), np.empty(3)
        sensor.measure(k, q0 + v * k * dt_s, np.zeros(3), q_out, v_out)
        measured.append(v_out)
    m = np.array(measured)
    assert np.array_equal(m[0], np.zeros(3))  # starts from rest
    np.testing.assert_allclose(m[10], v * (1 - math.exp(-1)), rtol=1e-9)
    np.testing.assert_allclose(m[200], v, rtol=1e-8)


def test_encoder_velocity_in_an_episode_is_the_filtered_difference(ur5, paper_motion):
    """Cross-check against scipy's filter of the differenced measured positions."""
    loop = LoopSettings(encoder_counts_per_rev=2**16, velocity="encoder", velocity_cutoff_hz=200.0)
    result = _run(ur5, paper_motion, loop, position_noise_std_rad=1e-5)
    assert result.ok, result.reason
    dt_s = 0.001
    alpha = 1 - math.exp(-2 * math.pi * 200.0 * dt_s)
    raw = np.vstack([np.zeros((1, ur5.dof)), np.diff(result.q, axis=0) / dt_s])
    expected = signal.lfilter([alpha], [1, alpha - 1], raw, axis=0)
    np.testing.assert_allclose(result.qd, expected, rtol=1e-9, atol=1e-9)
    # not the plant's velocity plus noise: the filter lags it, bounded
    assert 0 < np.abs(result.qd - result.qd_true).max() < 0.1


def test_jitter_is_deterministic_per_seed_and_leaves_the_noise_draws_alone(ur5, paper_motion):
    loop = LoopSettings(delay_s=0.001, jitter_s=0.002)
    a, b = (_run(ur5, paper_motion, loop, seed=5, **NOISE) for _ in range(2))
    assert _same(a, b)
    other = _run(ur5, paper_motion, loop, seed=6, **NOISE)
    assert not np.array_equal(a.tau_nm, other.tau_nm)
    # the position noise of seed 5 is the same with and without jitter
    plain = _run(ur5, paper_motion, seed=5, **NOISE)
    np.testing.assert_allclose(a.q - a.q_true, plain.q - plain.q_true, atol=1e-15)


def test_jitter_delays_each_command_within_its_bounds():
    act = Actuator(
        LoopSettings(delay_s=0.001, jitter_s=0.002), rows=500, nstep=1, physics_dt_s=0.001, seed=9
    )
    k = np.arange(500)
    j = act.in_effect
    arrived = j >= 0
    assert (k[arrived] - j[arrived] >= 1).all() and (k[arrived] - j[arrived] <= 3).all()
    assert set((k - j)[arrived].tolist()) == {1, 2, 3}  # every delay in range occurs
    assert (np.diff(j) >= 0).all()  # a stale command never replaces a newer one
    again = Actuator(
        LoopSettings(delay_s=0.001, jitter_s=0.002), rows=500, nstep=1, physics_dt_s=0.001, seed=9
    )
    assert np.array_equal(j, again.in_effect)


def test_jitter_aligned_to_the_motion_gives_its_commands_the_full_pre_rolls_delays():
    loop = LoopSettings(delay_s=0.001, jitter_s=0.002)
    full = Actuator(loop, rows=400, nstep=2, physics_dt_s=0.001, seed=4)
    early = Actuator(loop, rows=400, nstep=2, physics_dt_s=0.001, seed=4)
    before = early.in_effect.copy()
    early.align_to_motion(start_row=100, cap_rows=250)
    # the pre-roll's periods, already run, keep their schedule
    assert np.array_equal(early.in_effect[:200], before[:200])
    # once the pre-roll's last commands are through (delay + jitter <= 3 steps), motion
    # command start + m arrives as command cap + m of the full pre-roll did
    steps = np.arange(200 + 3, 2 * (400 - 150))
    assert np.array_equal(early.in_effect[steps] - 100, full.in_effect[steps + 300] - 250)
    assert not np.array_equal(before[steps] - 100, full.in_effect[steps + 300] - 250)
    # a pre-roll that ran to its cap changes nothing
    capped = Actuator(loop, rows=400, nstep=2, physics_dt_s=0.001, seed=4)
    capped.align_to_motion(start_row=250, cap_rows=250)
    assert np.array_equal(capped.in_effect, full.in_effect)


@pytest.mark.parametrize(
    ("loop", "kwargs", "message"),
    [
        (
            LoopSettings(delay_s=0.0015),
            {},
            r"^loop\.delay_s: 0\.0015 s is not a whole number of physics steps of 0\.001 s",
        ),
        (
            LoopSettings(jitter_s=0.0001),
            {},
            r"^loop\.jitter_s: 0\.0001 s is not a whole number of physics steps",
        ),
        (
            LoopSettings(velocity="encoder"),
            {"velocity_noise_std_rad_s": 1e-3},
            r"^loop\.velocity: 'encoder' differentiates the measured position",
        ),
    ],
)
def test_loop_settings_the_runner_cannot_honour_are_refused(
    ur5, paper_motion, loop, kwargs, message
):
    with pytest.raises(SimulationError, match=message):
        _run(ur5, paper_motion, loop, **kwargs)
