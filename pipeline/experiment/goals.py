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


def _named(spec: RobotSpec, name: str, *, source: str, path: str) -> list[float]:
    """An SRDF named state's joint positions [rad]; one line listing the defined ones."""
    states = dict(spec.named_states)
    if name not in states:
        known = ", ".join(sorted(states)) or "none"
        pairs = spec.collision_pairs_source
        srdf = pairs if pairs.startswith("SRDF ") else "no SRDF"
        raise _field(
            source, path, f"robot {spec.name} ({srdf}) defines no state {name!r}; defined: {known}"
        )
    return list(states[name])


def resolve_start(
    spec: RobotSpec, scenario: ScenarioParams, *, name: str, source: str
) -> np.ndarray:
    """The start joint vector [rad]: the listed joints, or the SRDF named state it names."""
    start_path = f"scenarios.{name}.start"
    start_q = (
        _named(spec, scenario.start, source=source, path=start_path)
        if isinstance(scenario.start, str)
        else scenario.start
    )
    return _joint_vector(start_q, spec, source=source, path=start_path)


def resolve_goal(
    spec: RobotSpec, scenario: ScenarioParams, *, name: str, source: str
) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal joint vectors; a named state (``start: ready``) comes from the robot's
    SRDF, a Cartesian goal is solved by IK, nearest the start."""
    start = resolve_start(spec, scenario, name=name, source=source)
    if scenario.goal.state is not None:
        goal_path = f"scenarios.{name}.goal"
        goal_q = _named(spec, scenario.goal.state, source=source, path=goal_path)
        return start, _joint_vector(goal_q, spec, source=source, path=goal_path)
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
