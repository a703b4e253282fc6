from __future__ import annotations

import pytest

from pipeline.robots import RobotSpec, load_spec


@pytest.fixture(scope="session", params=["ur5", "ur10"])
def ur_robot(request: pytest.FixtureRequest) -> RobotSpec:
    return load_spec(request.param)


@pytest.fixture(scope="session", params=["arm3_example", "ur5", "mdh_example", "panda_dh"])
def every_dof_robot(request: pytest.FixtureRequest) -> RobotSpec:
    """3, 6 (standard and modified DH) and 7 joints."""
    return load_spec(request.param)
