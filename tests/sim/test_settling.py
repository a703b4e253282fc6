"""The settling criterion (pre-roll and hold) on both sides, and the pre-roll it ends."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.control import make_controller
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode
from pipeline.sim.settling import SETTLING, integral_state, settled

ROWS, DOF = 100, 6


def _quiet(error_rad: float = 0.0, velocity_rad_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    return np.full((ROWS, DOF), error_rad), np.full((ROWS, DOF), velocity_rad_s)


def test_a_window_inside_every_threshold_is_settled():
    # a steady offset (a law without integral action on a mismatched plant) is settled
    e, v = _quiet(0.05, -0.9 * SETTLING.velocity_rad_s)
    e[-1] += 0.9 * SETTLING.error_change_rad
    i0 = np.full(DOF, 3.0)
    assert settled(e, v)
    assert settled(e, v, integral_before=i0, integral_after=i0 + 0.9 * SETTLING.integral_rad)


@pytest.mark.parametrize("what", ["error", "velocity", "integral", "nan", "empty"])
def test_one_threshold_crossed_on_one_joint_in_one_row_is_not_settled(what):
    e, v = _quiet()
    i0 = np.zeros(DOF)
    i1 = i0.copy()
    if what == "error":
        e[57, 2] = -1.1 * SETTLING.error_change_rad  # the error still moves
    elif what == "velocity":
        v[99, 5] = 1.1 * SETTLING.velocity_rad_s
    elif what == "integral":
        i1[4] = 1.1 * SETTLING.integral_rad  # the integral still moves
    elif what == "nan":
        e[0, 0] = np.nan
    else:
        e, v = e[:0], v[:0]
    assert not settled(e, v, integral_before=i0, integral_after=i1)


def test_integral_state_is_read_only_where_a_controller_has_an_integrator(ur5):
    assert integral_state(make_controller("ctc", ur5)) is None
    for name in ("pid", "ctc_pid", "pid_humble"):
        state = integral_state(make_controller(name, ur5))
        assert state is not None and state.shape == (ur5.dof,)


def _episode(ur5, name, gains=None, *, preroll_s=2.0, seed=0, hold_max_s=None, **more):
    return run_episode(
        ur5,
        reference=QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=0.5),
        controller=make_controller(name, ur5, gains),
        hold_s=0.2,
        preroll_s=preroll_s,
        hold_max_s=hold_max_s,
        seed=seed,
        position_noise_std_rad=1e-5,
        **more,
    )


def test_a_controller_too_soft_to_hold_the_arm_is_flagged_not_measured_as_settled(ur5):
    # a 2 rad/s PID cannot hold the UR5 against gravity within a 1 s pre-roll
    result = _episode(ur5, "pid", {"omega_n_rad_s": 2.0}, preroll_s=1.0)
    k0 = result.motion_start_row
    assert result.preroll_settled is False
    assert result.motion_start_s == pytest.approx(1.0)  # ran to the cap
    assert np.abs(result.q_ref[k0] - result.q_true[k0]).max() > 1e-2  # sagging
    # the same law at the default bandwidth settles, and starts the motion earlier
    stiff = _episode(ur5, "pid", preroll_s=2.0)
    assert stiff.preroll_settled is True
    assert stiff.motion_start_s < 2.0


def test_a_settled_pre_roll_ends_on_a_window_holding_the_start_pose(ur5):
    result = _episode(ur5, "ctc")
    k0 = result.motion_start_row
    window = round(SETTLING.window_s / result.control_period_s)
    assert result.preroll_settled is True
    assert k0 > 0 and k0 % window == 0
    assert np.ptp(result.q_ref[: k0 + 1], axis=0).max() == 0.0
    assert np.abs(result.qd_ref[:k0]).max() == 0.0
    # the last pre-roll window meets the criterion, as the runner decided
    rows = slice(k0 - window, k0)
    assert settled(result.q_ref[rows] - result.q_true[rows], result.qd_true[rows])
    # the episode is the pre-roll used, the motion and the hold: nothing after
    assert result.rows_planned == len(result.stamp_ns)


def test_the_settled_pre_roll_is_reproducible_bit_for_bit(ur5):
    a, b = _episode(ur5, "pid", seed=3), _episode(ur5, "pid", seed=3)
    facts = ("motion_start_row", "motion_start_s", "preroll_settled", "hold_settled")
    assert [getattr(a, f) for f in facts] == [getattr(b, f) for f in facts]
    for field in ("q", "q_true", "tau_cmd_nm", "stamp_ns"):
        assert np.array_equal(getattr(a, field), getattr(b, field))


def test_the_hold_goes_on_until_settled_by_the_same_criterion_up_to_its_cap(ur5):
    # PID's integral is still pulling the error in 0.2 s after the motion
    short = _episode(ur5, "pid", preroll_s=0.0)
    assert short.hold_settled is False
    longer = _episode(ur5, "pid", preroll_s=0.0, hold_max_s=3.0)
    assert longer.hold_settled is True
    extra_s = (len(longer.stamp_ns) - len(short.stamp_ns)) * longer.control_period_s
    assert 0 < extra_s < 2.8
    # the last window meets the criterion the pre-roll ends on
    window = round(SETTLING.window_s / longer.control_period_s)
    rows = slice(-window - 1, -1)
    assert settled(longer.q_ref[rows] - longer.q_true[rows], longer.qd_true[rows])
    # the same rows up to the shorter hold's end: the extension only appends
    n = len(short.stamp_ns) - 1
    assert np.array_equal(short.q_true[:n], longer.q_true[:n])
    # a cap it cannot meet: held to the cap, and said so
    capped = _episode(ur5, "pid", {"omega_n_rad_s": 5.0}, preroll_s=0.0, hold_max_s=0.4)
    assert capped.hold_settled is False
    assert len(capped.stamp_ns) == len(short.stamp_ns) + round(0.2 / 0.001)


def test_the_motion_meets_the_same_noise_however_long_the_pre_roll_held(ur5):
    # the sensor's and the torque sensor's draws along the motion do not depend on where
    # the pre-roll ended: a settled episode meets the noise the full pre-roll's would, so
    # two laws (or a fixed and a settled pre-roll) are compared on the same noise
    def episode(settle):
        return _episode(
            ur5, "ctc", preroll_s=1.0, seed=7, settle=settle,
            velocity_noise_std_rad_s=1e-4, effort_noise_std_nm=0.05,
        )  # fmt: skip

    settled_, fixed = episode(True), episode(False)
    k0, k1 = settled_.motion_start_row, fixed.motion_start_row
    assert 0 < k0 < k1 == 1000
    n = len(fixed.stamp_ns) - k1
    assert len(settled_.stamp_ns) - k0 == n
    for measured, true in (("q", "q_true"), ("qd", "qd_true"), ("tau_nm", "tau_cmd_nm")):
        a = getattr(settled_, measured)[k0:] - getattr(settled_, true)[k0:]
        b = getattr(fixed, measured)[k1:] - getattr(fixed, true)[k1:]
        np.testing.assert_allclose(a, b, atol=1e-12, err_msg=measured)
        # and the pre-roll's own rows keep the draws they met
        c = getattr(settled_, measured)[:k0] - getattr(settled_, true)[:k0]
        d = getattr(fixed, measured)[:k0] - getattr(fixed, true)[:k0]
        np.testing.assert_allclose(c, d, atol=1e-12, err_msg=measured)


def test_settle_false_holds_the_whole_pre_roll_and_still_reports_the_last_window(ur5):
    fixed = run_episode(
        ur5,
        reference=QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=0.5),
        controller=make_controller("ctc", ur5),
        hold_s=0.2,
        preroll_s=0.5,
        settle=False,
        seed=0,
    )
    assert fixed.motion_start_s == pytest.approx(0.5)
    assert fixed.preroll_settled is True  # a perfect-model CTC rests at once
