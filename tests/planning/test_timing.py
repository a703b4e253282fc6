"""Time parameterization: limits, continuity, rest at both ends, collision-free, exactness."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import PlanningError
from pipeline.planning import (
    DEFAULT_SMOOTHING_WINDOW_S,
    CollisionChecker,
    TimedTrajectory,
    time_parameterize,
)
from pipeline.trajectory import Reference
from tests.planning.scenarios import PAPER_GOAL, START, blocking_box

DT_S = 1e-3
REL_TOL = 1e-6


def _analytic_rest_to_rest_s(delta: np.ndarray, vlim: np.ndarray, alim: np.ndarray) -> float:
    """Time-optimal straight-line motion under per-joint v/a limits (trapezoid or triangle)."""
    moving = np.abs(delta) > 0
    v = np.min(vlim[moving] / np.abs(delta[moving]))  # path-fraction velocity limit [1/s]
    a = np.min(alim[moving] / np.abs(delta[moving]))  # [1/s^2]
    if v * v / a >= 1.0:
        return float(2.0 * np.sqrt(1.0 / a))
    return float(1.0 / v + v / a)


class _Corner:
    """Joint-space fence around an L-shaped path: q0 <= 1 + slack and q4 >= -slack."""

    def __init__(self, slack: float) -> None:
        self.slack = slack

    def is_valid(self, q) -> bool:
        return bool(q[0] <= 1.0 + self.slack and q[4] >= -self.slack)


L_PATH = np.array([[0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0], [1, 0, 0, 0, 1, 0]], dtype=float)


@pytest.fixture(scope="module")
def trajectories(ur5, direct_plan, detour_plan) -> dict[str, TimedTrajectory]:
    return {
        "direct": time_parameterize(ur5, direct_plan),
        "direct_scaled": time_parameterize(
            ur5, direct_plan, velocity_scaling=0.3, acceleration_scaling=0.5
        ),
        "detour": time_parameterize(ur5, detour_plan),
        "detour_scaled": time_parameterize(
            ur5, detour_plan, velocity_scaling=0.5, acceleration_scaling=0.25
        ),
        "stop_and_go": time_parameterize(ur5, L_PATH, checker=_Corner(0.0)),
    }


ALL = ["direct", "direct_scaled", "detour", "detour_scaled", "stop_and_go"]


def test_trajectory_is_a_simulation_reference(trajectories):
    ref: Reference = trajectories["direct"]
    assert ref.duration_s > 0


def test_straight_line_duration_is_the_analytic_time_optimum_plus_the_window(ur5, trajectories):
    for key, vs, acs in (("direct", 1.0, 1.0), ("direct_scaled", 0.3, 0.5)):
        expected = _analytic_rest_to_rest_s(
            PAPER_GOAL - START, ur5.velocity_limits * vs, ur5.acceleration_limits * acs
        )
        traj = trajectories[key]
        # TOPP-RA's grid places the switch points; 1e-4 is ~0.1 ms on this motion
        assert traj.duration_s == pytest.approx(expected + DEFAULT_SMOOTHING_WINDOW_S, rel=1e-4)
        assert traj.interpolation == "spline"


def test_paper_motion_peaks_like_the_papers_ctc_run(trajectories):
    """The paper's CTC run peaked at -2.30 rad/s on joint 4 (seeds/000): a time-optimal
    profile at 5 rad/s^2 gives about the same peak (sqrt(1.15 * 5) = 2.40 before smoothing)."""
    qd = trajectories["direct"].samples(DT_S).velocities
    peak = qd[np.argmax(np.abs(qd[:, 3])), 3]
    assert -2.45 < peak < -2.2


@pytest.mark.parametrize("key", ALL)
def test_limits_are_respected(trajectories, key):
    traj = trajectories[key]
    s = traj.samples(DT_S / 2)
    assert np.all(np.abs(s.velocities) <= traj.velocity_limits * (1 + REL_TOL))
    assert np.all(np.abs(s.accelerations) <= traj.acceleration_limits * (1 + REL_TOL))
    assert np.all(s.positions >= traj.waypoints.min(axis=0) - 0.1)  # no wild excursions
    assert np.all(s.positions <= traj.waypoints.max(axis=0) + 0.1)


def test_scaling_factors_scale_the_limits(ur5, trajectories):
    traj = trajectories["detour_scaled"]
    np.testing.assert_allclose(traj.velocity_limits, ur5.velocity_limits * 0.5)
    np.testing.assert_allclose(traj.acceleration_limits, ur5.acceleration_limits * 0.25)
    assert traj.duration_s > trajectories["detour"].duration_s


@pytest.mark.parametrize("key", ALL)
def test_position_velocity_acceleration_are_continuous(trajectories, key):
    """Jumps between consecutive samples shrink with the sample spacing (no steps), and
    stay within what the velocity, acceleration and jerk bounds allow."""
    traj = trajectories[key]
    jumps = {}
    for dt in (DT_S, DT_S / 10):
        s = traj.samples(dt)
        dq = np.abs(np.diff(s.positions, axis=0)).max(axis=0)
        dqd = np.abs(np.diff(s.velocities, axis=0)).max(axis=0)
        dqdd = np.abs(np.diff(s.accelerations, axis=0)).max(axis=0)
        assert np.all(dq <= traj.velocity_limits * dt * (1 + REL_TOL))
        assert np.all(dqd <= traj.acceleration_limits * dt * (1 + REL_TOL))
        jumps[dt] = dqdd.max()
    # acceleration: tenfold finer sampling => tenfold smaller jumps (a step would not shrink)
    assert jumps[DT_S / 10] <= 0.15 * jumps[DT_S]
    if key.startswith("direct") or key == "stop_and_go":
        # straight pieces: the moving average bounds jerk by 2 a_max / w exactly
        jerk_bound = 2 * traj.acceleration_limits.max() / traj.smoothing_window_s
        assert jumps[DT_S] <= jerk_bound * DT_S * (1 + 1e-6)


@pytest.mark.parametrize("key", ALL)
def test_reported_derivatives_are_the_derivatives_of_the_position(trajectories, key):
    traj = trajectories[key]
    h = 1e-6
    t = np.linspace(0.0, traj.duration_s, 997)[1:-1]
    q_p, qd_p, _ = traj.sample_many(t + h)
    q_m, qd_m, _ = traj.sample_many(t - h)
    _, qd, qdd = traj.sample_many(t)
    scale_v = traj.velocity_limits.max()
    scale_a = traj.acceleration_limits.max()
    assert np.abs((q_p - q_m) / (2 * h) - qd).max() <= 1e-6 * scale_v
    assert np.abs((qd_p - qd_m) / (2 * h) - qdd).max() <= 1e-3 * scale_a


@pytest.mark.parametrize("key", ALL)
def test_starts_and_ends_at_rest_and_holds_outside(trajectories, key):
    traj = trajectories[key]
    zero = np.zeros(6)
    for t in (-1.0, 0.0):
        q, qd, qdd = traj.sample(t)
        np.testing.assert_array_equal(q, traj.waypoints[0])
        np.testing.assert_array_equal(qd, zero)
        np.testing.assert_array_equal(qdd, zero)
    for t in (traj.duration_s, traj.duration_s + 5.0):
        q, qd, qdd = traj.sample(t)
        np.testing.assert_array_equal(q, traj.waypoints[-1])
        np.testing.assert_array_equal(qd, zero)
        np.testing.assert_array_equal(qdd, zero)
    # and it approaches rest continuously from inside
    eps = 1e-7
    for t, q_end in ((eps, traj.waypoints[0]), (traj.duration_s - eps, traj.waypoints[-1])):
        q, qd, qdd = traj.sample(t)
        assert np.abs(q - q_end).max() < 1e-9
        assert np.abs(qd).max() < 1e-5
        assert np.abs(qdd).max() < 1e-3


@pytest.mark.parametrize("key", ALL)
def test_sample_equals_sample_many(trajectories, key):
    traj = trajectories[key]
    times = np.concatenate([np.linspace(-0.1, traj.duration_s + 0.1, 301), traj.time_breaks_s[::7]])
    q_all, qd_all, qdd_all = traj.sample_many(times)
    for k, t in enumerate(times):
        q, qd, qdd = traj.sample(float(t))
        np.testing.assert_allclose(q, q_all[k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(qd, qd_all[k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(qdd, qdd_all[k], rtol=0, atol=1e-12)


def test_samples_cover_the_whole_motion(trajectories):
    traj = trajectories["detour"]
    s = traj.samples(DT_S)
    assert s.times_s[0] == 0.0
    assert s.times_s[-1] >= traj.duration_s > s.times_s[-2]
    np.testing.assert_allclose(np.diff(s.times_s), DT_S)
    np.testing.assert_array_equal(s.positions[-1], traj.waypoints[-1])
    assert s.positions.shape == s.velocities.shape == s.accelerations.shape == (len(s.times_s), 6)


@pytest.mark.parametrize("key", ["detour", "detour_scaled"])
def test_timed_detour_is_collision_free_when_densely_rechecked(ur5, trajectories, key):
    traj = trajectories[key]
    exact = CollisionChecker(ur5, obstacles=[blocking_box(ur5)])
    s = traj.samples(DT_S / 4)
    assert np.linalg.norm(np.diff(s.positions, axis=0), axis=1).max() < 2e-3
    assert all(exact.is_valid(q) for q in s.positions)


def test_same_path_gives_bit_identical_trajectories(ur5, detour_plan, trajectories):
    again = time_parameterize(ur5, detour_plan)
    np.testing.assert_array_equal(again.time_breaks_s, trajectories["detour"].time_breaks_s)
    np.testing.assert_array_equal(again.s_coeffs, trajectories["detour"].s_coeffs)
    np.testing.assert_array_equal(again.path_coeffs, trajectories["detour"].path_coeffs)


def test_spline_leaving_the_free_space_is_densified_until_it_fits(ur5):
    # a natural spline through the L's corner overshoots it by ~0.1 rad, 4x densified by ~0.02
    traj = time_parameterize(ur5, L_PATH, checker=_Corner(0.03))
    assert traj.interpolation == "spline"
    assert len(traj.waypoints) > len(L_PATH)
    q = traj.samples(DT_S).positions
    assert q[:, 0].max() > 1.0  # it does round the corner ...
    assert q[:, 0].max() <= 1.03 and q[:, 4].min() >= -0.03  # ... inside the fence


def test_no_spline_fits_so_the_polyline_is_followed_with_a_stop_at_the_corner(trajectories):
    traj = trajectories["stop_and_go"]
    assert traj.interpolation == "stop_and_go"
    s = traj.samples(DT_S / 10)
    assert s.positions[:, 0].max() <= 1.0 + 1e-12
    assert s.positions[:, 4].min() >= -1e-12
    at_corner = np.argmin(np.linalg.norm(s.positions - L_PATH[1], axis=1))
    assert np.linalg.norm(s.positions[at_corner] - L_PATH[1]) < 1e-6
    assert np.abs(s.velocities[at_corner]).max() < 1e-3


def test_path_in_collision_even_as_a_polyline_is_refused(ur5):
    with pytest.raises(PlanningError, match=r"^path_waypoints: the path is in collision"):
        time_parameterize(ur5, L_PATH, checker=_Corner(-0.5))


def test_path_through_the_floor_is_refused_by_the_default_checker(ur5):
    folded = np.array([0.0, np.pi / 2, 0.0, 0.0, 0.0, 0.0])  # upper arm down, under the floor
    path = np.stack([START, folded, PAPER_GOAL])
    with pytest.raises(PlanningError, match=r"in collision"):
        time_parameterize(ur5, path)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"velocity_scaling": 0.0}, r"^velocity_scaling: expected a factor in \(0, 1\]"),
        ({"velocity_scaling": 1.5}, r"^velocity_scaling: expected a factor in \(0, 1\]"),
        ({"acceleration_scaling": -0.1}, r"^acceleration_scaling: expected a factor"),
        ({"smoothing_window_s": 0.0}, r"^smoothing_window_s: expected a positive"),
    ],
)
def test_bad_arguments_are_refused(ur5, direct_plan, kwargs, message):
    with pytest.raises(PlanningError, match=message):
        time_parameterize(ur5, direct_plan, **kwargs)


def test_wrong_shape_is_refused(ur5):
    with pytest.raises(PlanningError, match=r"^path_waypoints: expected shape \(K, 6\)"):
        time_parameterize(ur5, np.zeros((3, 5)))


def test_zero_length_path_holds_the_state(ur5):
    q = np.full(6, 0.1)
    traj = time_parameterize(ur5, np.stack([q, q]))
    assert traj.duration_s == 0.0
    got, qd, qdd = traj.sample(0.5)
    np.testing.assert_array_equal(got, q)
    assert not qd.any() and not qdd.any()
    assert len(traj.samples(DT_S).times_s) == 1
