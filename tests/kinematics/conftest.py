from __future__ import annotations

import pytest

from pipeline.robots import RobotSpec, load_spec


@pytest.fixture(scope="session", params=["ur5", "ur10"])
def ur_robot(request: pytest.FixtureRequest) -> RobotSpec:
    return load_spec(request.param)
