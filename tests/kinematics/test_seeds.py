"""The IK seed table: reproducible, searched correctly, and what numeric IK restarts from."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.kinematics import IKOptions, flange_pose, make_solver
from pipeline.kinematics.numeric import TABLE_STARTS, NumericLMSolver
from pipeline.kinematics.seeds import ROTATION_LENGTH_M, seed_table
from pipeline.robots import load_spec


@pytest.fixture(scope="module")
def panda():
    return load_spec("panda_dh")


def _targets(spec, count, seed):
    qs = np.random.default_rng(seed).uniform(spec.lower, spec.upper, (count, spec.dof))
    return [flange_pose(spec, q) for q in qs]


def test_the_table_is_rebuilt_identically_and_stays_within_one_turn_inside_the_limits():
    for name in ("panda_dh", "ur5", "arm3_example"):
        spec = load_spec(name)
        table = seed_table(spec)
        seed_table.cache_clear()
        again = seed_table(spec)
        assert again is not table and np.array_equal(again.joints, table.joints)
        assert np.all(table.joints >= spec.lower) and np.all(table.joints <= spec.upper)
        # +-2 pi joints (ur5) are drawn over one turn: every angle once
        assert np.all(np.ptp(table.joints, axis=0) <= 2 * math.pi)


def test_nearest_matches_a_brute_force_search_over_the_table_poses(panda):
    table = seed_table(panda)
    rows = range(0, table.joints.shape[0], 97)  # a sample of the table, by independent FK
    poses = np.array([flange_pose(panda, table.joints[i]) for i in rows])
    weight = ROTATION_LENGTH_M / math.sqrt(2.0)
    for target in _targets(panda, 5, seed=31):
        d2 = ((poses[:, :3, 3] - target[:3, 3]) ** 2).sum(axis=1) + weight**2 * (
            (poses[:, :3, :3] - target[:3, :3]) ** 2
        ).sum(axis=(1, 2))
        best = min(d2)
        nearest = table.nearest(target, 1)[0]
        mine = flange_pose(panda, nearest)
        d2_mine = float(((mine[:3, 3] - target[:3, 3]) ** 2).sum()) + weight**2 * float(
            ((mine[:3, :3] - target[:3, :3]) ** 2).sum()
        )
        assert d2_mine <= best + 1e-12  # the whole table's nearest beats a sample's


def test_a_position_only_robot_is_searched_on_position():
    arm3 = load_spec("arm3_example")
    table = seed_table(arm3)
    assert table.position_only
    target = flange_pose(arm3, table.joints[5])
    target[:3, :3] = np.eye(3)  # the rotation plays no part
    assert np.array_equal(table.nearest(target, 1)[0], table.joints[5])


def test_restarts_start_from_the_table_poses_nearest_the_target(panda, monkeypatch):
    starts: list[np.ndarray] = []
    attempt = NumericLMSolver._attempt

    def recording(self, q0, goal):
        starts.append(q0.copy())
        return attempt(self, q0, goal)

    monkeypatch.setattr(NumericLMSolver, "_attempt", recording)
    solver = make_solver("numeric", panda, options=IKOptions(null_space_iterations=0))
    restarted = 0
    for target in _targets(panda, 60, seed=32):
        starts.clear()
        result = solver.solve(target)
        assert result.ok
        if result.restarts:
            restarted += 1
            near = seed_table(panda).nearest(target, TABLE_STARTS)
            used = min(result.restarts, TABLE_STARTS)
            assert np.array_equal(np.array(starts[1 : 1 + used]), near[:used])
    assert restarted > 0


def test_few_panda_targets_need_four_attempts_or_more(panda):
    # 2,000 random targets: 4.2 % took 4 or more attempts with uniform restarts, 1.4 %
    # with restarts from the table
    solver = make_solver("numeric", panda, options=IKOptions(null_space_iterations=0))
    restarts = np.array([solver.solve(t).restarts for t in _targets(panda, 400, seed=33)])
    assert (restarts >= 3).mean() <= 0.03
