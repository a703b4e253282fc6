"""Rope shortcutting that checks only motions that gain, and the plans it shortens."""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest

from pipeline.errors import PlanningError
from pipeline.planning import CollisionChecker, plan_path
from pipeline.planning.batch import BatchChecker
from pipeline.planning.shortcut import densify, rope_shortcut
from tests.planning.scenarios import PAPER_GOAL, START, blocking_box


def _balls(rng, dim, n=6):
    """Joint-space obstacles: (centres, radii)."""
    return rng.uniform(-1.0, 1.0, size=(n, dim)), rng.uniform(0.15, 0.35, size=n)


def _segment_clear(a, b, centres, radii):
    """The exact answer: does the segment a-b stay outside every ball?"""
    d = b - a
    t = np.clip(((centres - a) @ d) / max(float(d @ d), 1e-300), 0.0, 1.0)
    nearest = a + t[:, None] * d
    return bool(np.all(np.linalg.norm(centres - nearest, axis=1) > radii))


def _valid_path(rng, dim, centres, radii, n=8):
    """A wandering path whose segments are all clear, from a free start."""
    start = rng.uniform(-1.5, 1.5, dim)
    while not _segment_clear(start, start, centres, radii):
        start = rng.uniform(-1.5, 1.5, dim)
    pts = [start]
    while len(pts) < n:
        q = pts[-1] + rng.normal(scale=0.6, size=dim)
        if _segment_clear(pts[-1], q, centres, radii):
            pts.append(q)
    return np.array(pts)


def _rope_checking_every_motion(waypoints, *, delta, tolerance, motion_clear):
    """RRT-Rope as OMPL states it: every candidate from the path's end back to the
    first valid one is checked; a valid one that gains too little ends the search."""
    states = densify(waypoints, delta)

    def along(i, j):
        return sum(math.dist(p, q) for p, q in pairwise(states[i : j + 1]))

    i = 0
    while i < len(states) - 2:
        restart = False
        for j in range(len(states) - 1, i + 1, -1):
            if not motion_clear(states[i], states[j]):
                continue
            short = math.dist(states[i], states[j])
            if along(i, j) - short < tolerance * delta:
                break
            m = math.floor(short / delta) if short > delta else 0
            a, b = states[i], states[j]
            states[i + 1 : j] = [a + (b - a) * ((k + 1) / (m + 1)) for k in range(m)]
            restart = True
            break
        i = 0 if restart else i + 1
    return np.array(states)


@pytest.mark.parametrize("dim", [2, 6])
def test_rope_checks_only_gaining_motions_and_shortens_like_checking_them_all(dim):
    rng = np.random.default_rng(dim)
    fewer = 0
    for _ in range(15):
        centres, radii = _balls(rng, dim)
        path = _valid_path(rng, dim, centres, radii)
        calls = {"lazy": 0, "all": 0}

        def counted(key, calls=calls, centres=centres, radii=radii):
            def check(qa, qb):
                calls[key] += 1
                return _segment_clear(qa, qb, centres, radii)

            return check

        lazy = rope_shortcut(path, delta=0.2, tolerance=0.1, motion_clear=counted("lazy"))
        full = _rope_checking_every_motion(
            path, delta=0.2, tolerance=0.1, motion_clear=counted("all")
        )
        np.testing.assert_allclose(lazy, full, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(lazy[[0, -1]], path[[0, -1]])
        for a, b in pairwise(lazy):
            assert _segment_clear(a, b, centres, radii)
        assert calls["lazy"] <= calls["all"]
        fewer += calls["lazy"] < calls["all"]
        length = np.linalg.norm(np.diff(lazy, axis=0), axis=1).sum()
        assert length <= np.linalg.norm(np.diff(path, axis=0), axis=1).sum() + 1e-9
    assert fewer >= 10  # most paths: the checks that cannot gain are skipped


def test_densify_spaces_states_at_most_delta_apart_and_keeps_the_vertices():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.05], [1.0, 0.75]])
    states = np.array(densify(path, 0.2))
    assert np.all(np.linalg.norm(np.diff(states, axis=0), axis=1) <= 0.2 + 1e-12)
    for vertex in path:
        assert np.any(np.all(states == vertex, axis=1))
    # floor(length / delta) states between a segment's ends, as in OMPL's rope
    assert len(states) == len(path) + 5 + 0 + 3


@pytest.mark.parametrize("seed", range(6))
def test_every_interpolated_state_of_a_plan_is_clear_by_the_scalar_checker(ur5, seed):
    box = blocking_box(ur5)
    plan = plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=seed)
    assert not plan.direct and plan.simplified
    checker = CollisionChecker(ur5, obstacles=[box], padding_m=plan.padding_m)
    for qa, qb in pairwise(plan.waypoints):
        n = max(1, math.ceil(float(np.linalg.norm(qb - qa)) / plan.check_step_rad))
        for k in range(n + 1):
            q = qa + (k / n) * (qb - qa)
            assert checker.within_limits(q)
            assert checker.is_clear(q), (seed, k, checker.clearance_m(q))


def test_rope_plans_are_as_short_as_ompls_rope(ur5):
    box = blocking_box(ur5)
    ours, ompls = [], []
    for seed in range(8):
        kw = {"start": START, "goal": PAPER_GOAL, "obstacles": [box], "seed": seed}
        ours.append(plan_path(ur5, **kw).path_length_rad)
        ompls.append(plan_path(ur5, recipe="ompl_rope", **kw).path_length_rad)
    assert np.median(ours) <= 1.01 * np.median(ompls)
    assert max(ours) <= 1.05 * max(ompls)


def test_unknown_recipe_is_refused(ur5):
    with pytest.raises(PlanningError, match=r"^recipe: expected one of rope, ompl_rope, legacy"):
        plan_path(ur5, start=START, goal=PAPER_GOAL, seed=0, recipe="fast")


def test_batched_recheck_finds_the_same_first_invalid_state(ur5):
    box = blocking_box(ur5)
    plans = [
        plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[box], seed=seed) for seed in (0, 1)
    ]
    checker = CollisionChecker(ur5, obstacles=[box], padding_m=plans[0].padding_m)
    batch = BatchChecker(checker)
    step = plans[0].check_step_rad
    rng = np.random.default_rng(9)
    paths = [plan.waypoints for plan in plans]
    for _ in range(20):
        path = np.concatenate([[START], rng.uniform(-0.9, 0.9, size=(3, 6)), [PAPER_GOAL]])
        if rng.random() < 0.3:
            path[rng.integers(1, 4), rng.integers(6)] = 7.0  # out of limits too
        paths.append(path)
    outcomes = set()
    for path in paths:
        want = checker.first_invalid(path, step_rad=step)
        got = batch.first_invalid(path, step_rad=step)
        outcomes.add(want is None)
        if want is None:
            assert got is None
        else:
            np.testing.assert_array_equal(got, want)
    assert outcomes == {True, False}
