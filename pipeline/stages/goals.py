"""Start and goal of a scenario as joint vectors: checked against the limits, IK for a pose."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.errors import ParamsError, PipelineError
from pipeline.params import ScenarioParams
from pipeline.robots.spec import RobotSpec


def _field(source: str, path: str, msg: str) -> ParamsError:
    return ParamsError(f"{source}: {path}: {msg}")


def _joint_vector(
    values: Sequence[float], spec: RobotSpec, *, source: str, path: str
) -> np.ndarray:
    if len(values) != spec.dof:
        raise _field(source, path, f"expected {spec.dof} values for {spec.name}, got {len(values)}")
    q = np.asarray(values, dtype=float)
    for i, (v, j) in enumerate(zip(q, spec.joints, strict=True)):
        if not j.limits.lower <= v <= j.limits.upper:
            raise _field(
                source,
                f"{path}[{i}]",
                f"{v} rad is outside {j.name}'s limits "
                f"[{j.limits.lower:.4g}, {j.limits.upper:.4g}]",
            )
    return q


def resolve_goal(
    spec: RobotSpec, scenario: ScenarioParams, *, name: str, source: str
) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal joint vectors; a Cartesian goal is solved by IK, nearest the start."""
    start = _joint_vector(scenario.start, spec, source=source, path=f"scenarios.{name}.start")
    if scenario.goal.joints is not None:
        goal = _joint_vector(
            scenario.goal.joints, spec, source=source, path=f"scenarios.{name}.goal.joints"
        )
        return start, goal
    from pipeline.kinematics import solve_pose_nearest

    pose = scenario.goal.pose
    assert pose is not None
    try:
        goal = solve_pose_nearest(
            spec,
            position=pose.position,
            quaternion_wxyz=pose.quaternion_wxyz,
            rpy=pose.rpy,
            solver=pose.solver,
            near=start,
        )
    except PipelineError as err:
        raise _field(source, f"scenarios.{name}.goal.pose", str(err)) from err
    return start, goal
