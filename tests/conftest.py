from __future__ import annotations

import pytest

from pipeline.robots import RobotSpec, load_spec


@pytest.fixture(scope="session")
def ur5() -> RobotSpec:
    return load_spec("ur5")


@pytest.fixture(scope="session", params=["ur5", "ur10", "mdh_example"])
def any_robot(request: pytest.FixtureRequest) -> RobotSpec:
    return load_spec(request.param)


@pytest.fixture(scope="session", params=["ur5", "ur10"])
def dynamic_robot(request: pytest.FixtureRequest) -> RobotSpec:
    return load_spec(request.param)
