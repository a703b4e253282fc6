"""Motion planning: OMPL RRTConnect in joint space, MuJoCo collision checking, timing."""

from __future__ import annotations

from pipeline.planning.collision import (
    CollisionChecker,
    default_padding_m,
    motion_check_step_rad,
    reach_bound_m,
)
from pipeline.planning.planner import PLANNER_NAME, PlannedPath, plan_path, quiet_ompl, seed_ompl
from pipeline.planning.timing import (
    DEFAULT_SMOOTHING_WINDOW_S,
    StateChecker,
    TimedTrajectory,
    time_parameterize,
)

__all__ = [
    "DEFAULT_SMOOTHING_WINDOW_S",
    "PLANNER_NAME",
    "CollisionChecker",
    "PlannedPath",
    "StateChecker",
    "TimedTrajectory",
    "default_padding_m",
    "motion_check_step_rad",
    "plan_path",
    "quiet_ompl",
    "reach_bound_m",
    "seed_ompl",
    "time_parameterize",
]
