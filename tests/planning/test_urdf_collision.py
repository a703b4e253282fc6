"""Collision checking on a URDF robot's own geometry (convex meshes), skipping its SRDF's
disabled pairs: the arm at rest is not in collision with itself."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from pipeline.model.scene import Box
from pipeline.planning.collision import CollisionChecker
from pipeline.robots import load_spec
from pipeline.robots.packages import package_search_path

pytestmark = pytest.mark.skipif(
    not any((p / "example-robot-data").is_dir() for p in package_search_path()),
    reason="example-robot-data is not installed",
)


def test_panda_at_rest_is_not_in_self_collision():
    panda = load_spec("panda")
    assert panda.disabled_pairs  # from its SRDF
    assert "SRDF" in dict(panda.settings_sources)["collision_pairs"]
    checker = CollisionChecker(panda)
    assert all(j.shapes for j in panda.joints)  # its meshes, not capsules
    for _, q in panda.named_states:
        assert checker.is_valid(np.array(q))
    assert checker.is_valid(0.5 * (panda.lower + panda.upper))


def _panda_around_a_box():
    """The Panda, a start and goal, and a box on the straight path between them."""
    panda = load_spec("panda")
    start = panda.named_state("default")
    goal = np.array([1.3, -0.5, 0.0, -2.0, 0.0, 1.5, 0.785398])
    box = Box(name="box", center=(0.28, 0.21, 0.26), half_size=(0.05, 0.05, 0.26))
    return panda, start, goal, box


def test_panda_meets_a_box_placed_on_its_path():
    panda, start, goal, box = _panda_around_a_box()
    checker = CollisionChecker(panda, obstacles=[box])
    assert checker.is_valid(start) and checker.is_valid(goal)
    assert not checker.is_valid(0.5 * (start + goal))


def test_panda_plans_around_the_box_on_its_meshes_with_mujoco_alone():
    from pipeline.errors import PlanningError
    from pipeline.planning import plan_path
    from pipeline.planning.batch import BatchChecker

    panda, start, goal, box = _panda_around_a_box()
    checker = CollisionChecker(panda, obstacles=[box])
    with pytest.raises(PlanningError, match="batched checks need capsules or spheres"):
        BatchChecker(checker)  # so plan_path checks and re-checks in MuJoCo
    plan = plan_path(panda, start=start, goal=goal, obstacles=[box], seed=1)
    assert not plan.direct and plan.simplified
    checker.padding_m = plan.padding_m
    assert checker.first_invalid(plan.waypoints, step_rad=plan.check_step_rad) is None


def test_the_motion_check_step_bounds_how_far_the_meshes_move():
    from pipeline.planning.collision import reach_bound_m, shape_extent_m

    panda = load_spec("panda")
    assert shape_extent_m(panda) > max(j.collision_radius for j in panda.joints)
    checker = CollisionChecker(panda)
    model, data = checker.model, checker.data
    rng = np.random.default_rng(4)
    bound = reach_bound_m(panda)
    for _ in range(20):
        q = rng.uniform(panda.lower, panda.upper)
        dq = rng.normal(0.0, 1e-3, panda.dof)
        points = []
        for qq in (q, q + dq):
            data.qpos[:] = qq
            mujoco.mj_forward(model, data)
            points.append(data.geom_xpos.copy())
        # geom centres: every point of the arm moves no more than the bound allows
        moved = float(np.linalg.norm(points[1] - points[0], axis=1).max())
        assert moved <= bound * float(np.linalg.norm(dq)) * (1 + 1e-9)
