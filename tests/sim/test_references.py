"""The quintic (minimum-jerk) test reference."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sim.references import (
    PAPER_GOAL_RAD,
    PAPER_START_RAD,
    BatchReference,
    QuinticReference,
)

T_S = 2.0


@pytest.fixture(scope="module")
def ref():
    return QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=T_S)


def test_rests_at_start_and_goal_and_holds_outside_the_motion(ref):
    for t, pose in ((-1.0, PAPER_START_RAD), (0.0, PAPER_START_RAD), (T_S, PAPER_GOAL_RAD)):
        q, qd, qdd = ref.sample(t)
        np.testing.assert_allclose(q, pose, atol=1e-15)
        assert not qd.any() and not qdd.any()
    q, qd, qdd = ref.sample(T_S + 5.0)
    np.testing.assert_array_equal(q, np.array(PAPER_GOAL_RAD))
    assert not qd.any() and not qdd.any()


def test_velocity_and_acceleration_are_the_derivatives_of_position(ref):
    t = np.linspace(0.01, T_S - 0.01, 400)
    h = 1e-5
    q_plus, qd_plus, _ = ref.sample_many(t + h)
    q_minus, qd_minus, _ = ref.sample_many(t - h)
    _, qd, qdd = ref.sample_many(t)
    np.testing.assert_allclose((q_plus - q_minus) / (2 * h), qd, atol=1e-8)
    np.testing.assert_allclose((qd_plus - qd_minus) / (2 * h), qdd, atol=1e-7)


def test_peaks_are_the_minimum_jerk_textbook_values(ref):
    t = np.linspace(0.0, T_S, 20001)
    _, qd, qdd = ref.sample_many(t)
    delta = np.abs(np.array(PAPER_GOAL_RAD) - np.array(PAPER_START_RAD))
    np.testing.assert_allclose(np.abs(qd).max(axis=0), 15 / 8 * delta / T_S, rtol=1e-6)
    np.testing.assert_allclose(np.abs(qdd).max(axis=0), 10 / np.sqrt(3) * delta / T_S**2, rtol=1e-4)


def test_single_samples_equal_the_vectorized_ones(ref):
    t = np.array([0.0, 0.3, 1.0, 1.7, 2.5])
    many = ref.sample_many(t)
    for k, tk in enumerate(t):
        for single, batch in zip(ref.sample(float(tk)), many, strict=True):
            np.testing.assert_array_equal(single, batch[k])


def test_is_a_batch_reference(ref):
    assert isinstance(ref, BatchReference)


@pytest.mark.parametrize(
    ("start", "goal", "duration_s", "match"),
    [
        ([0.0, 0.0], [1.0], 1.0, "start has 2 joints, goal 1"),
        ([0.0], [float("nan")], 1.0, "finite"),
        ([0.0], [1.0], 0.0, "duration_s must be > 0"),
    ],
)
def test_between_refuses_inconsistent_input(start, goal, duration_s, match):
    with pytest.raises(ValueError, match=match):
        QuinticReference.between(start, goal, duration_s=duration_s)
