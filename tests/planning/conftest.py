from __future__ import annotations

import pytest

from pipeline.planning import PlannedPath, plan_path
from pipeline.robots import RobotSpec
from tests.planning.scenarios import PAPER_GOAL, START, blocking_box


@pytest.fixture(scope="session")
def direct_plan(ur5: RobotSpec) -> PlannedPath:
    return plan_path(ur5, start=START, goal=PAPER_GOAL, seed=0)


@pytest.fixture(scope="session")
def detour_plan(ur5: RobotSpec) -> PlannedPath:
    return plan_path(ur5, start=START, goal=PAPER_GOAL, obstacles=[blocking_box(ur5)], seed=0)
