"""Planning: one collision-free path and its timing per distinct plan input.

``plan_path`` re-seeds OMPL and builds fresh objects, so a path depends on its plan
input (robot, start, goal, obstacles, planner and timing settings) alone; every
episode with that input tracks the same reference.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pipeline.errors import PipelineError
from pipeline.experiment.goals import resolve_goal
from pipeline.params import Episode, Params, ScenarioParams
from pipeline.planning import PlannedPath, TimedTrajectory
from pipeline.robots.loaders import load_spec

if TYPE_CHECKING:
    from pipeline.model.scene import Box


@dataclass(frozen=True)
class ScenarioPlan:
    """A scenario's planned path and its timing (shared by every controller), or the error."""

    scenario: str
    path: PlannedPath | None
    trajectory: TimedTrajectory | None = None
    error: str = ""


def obstacle_boxes(scenario: ScenarioParams) -> list[Box]:
    """The scenario's obstacles as scene boxes."""
    from pipeline.model.scene import Box

    return [Box(b.name, b.center, b.half_size) for b in scenario.obstacles]


def plan_key(scenario: ScenarioParams) -> str:
    """What a plan depends on: robot, start, goal, obstacles, planner and timing settings.

    Episodes with equal keys share one plan (planned once per campaign run).
    """
    data = scenario.model_dump(include={"robot", "start", "goal", "obstacles", "planner", "timing"})
    return json.dumps(data, sort_keys=True, separators=(",", ":"))


def plan_scenario(name: str, scenario: ScenarioParams, source: str) -> ScenarioPlan:
    """Plan and time one scenario; a failure is returned, not raised (it fails its episodes)."""
    from pipeline.planning import plan_path, time_parameterize

    try:
        spec = load_spec(scenario.robot)
        start, goal = resolve_goal(spec, scenario, name=name, source=source)
        path = plan_path(
            spec,
            start=start,
            goal=goal,
            obstacles=obstacle_boxes(scenario),
            time_limit_s=scenario.planner.time_limit_s,
            simplify=scenario.planner.simplify,
            seed=scenario.planner.seed,
        )
        trajectory = time_parameterize(
            spec,
            path,
            velocity_scaling=scenario.timing.velocity_scaling,
            acceleration_scaling=scenario.timing.acceleration_scaling,
        )
    except PipelineError as err:
        return ScenarioPlan(name, None, error=str(err))
    return ScenarioPlan(name, path, trajectory)


def plan_all(
    params: Params, episodes: Sequence[Episode], *, emit: Callable[[str, str, float], None]
) -> tuple[dict[str, ScenarioPlan], dict[str, str]]:
    """Plan once per distinct plan input (robot, start, goal, obstacles, planner, timing).

    Returns:
        The plans by plan key, and each episode's plan key by episode name.
    """
    plan_of: dict[str, str] = {}
    named: dict[str, str] = {}  # plan key -> a scenario name for messages
    by_scenario: dict[int, str] = {}  # campaign episodes share scenario objects
    for e in episodes:
        key = by_scenario.get(id(e.scenario))
        if key is None:
            key = by_scenario[id(e.scenario)] = plan_key(e.scenario)
        plan_of[e.name] = key
        named.setdefault(key, e.scenario_name)
    plans: dict[str, ScenarioPlan] = {}
    scenarios = {plan_of[e.name]: e.scenario for e in episodes}
    for key in sorted(named, key=lambda k: (named[k], k)):
        plans[key] = plan_scenario(named[key], scenarios[key], params.source)
        emit("plan", named[key], 1.0)
    return plans, plan_of
