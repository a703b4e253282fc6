from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.robots import RobotSpec, load_spec

TESTS = Path(__file__).resolve().parent


@pytest.fixture(scope="session")
def ur5() -> RobotSpec:
    return load_spec("ur5")


@pytest.fixture(scope="session", params=["ur5", "ur10", "mdh_example"])
def any_robot(request: pytest.FixtureRequest) -> RobotSpec:
    return load_spec(request.param)


@pytest.fixture(scope="session", params=["ur5", "ur10"])
def dynamic_robot(request: pytest.FixtureRequest) -> RobotSpec:
    return load_spec(request.param)


# --- running on several workers (`pytest -n 2`, pytest-xdist with --dist loadgroup) -----------
#
# A shared fixture is made once per worker process. Tests that share an expensive one (module
# scope: a recorded bag, a report; session scope in a sub-folder's conftest: the identification
# bags) are sent to one worker together, as an xdist group named after where the fixture lives,
# so it is still made once. The robot fixtures above are cheap and group nothing. A test that
# names its own group (`@pytest.mark.xdist_group("ray")`: tests that start a local Ray instance,
# one at a time) keeps it.


def _fixture_home(fixturedef: pytest.FixtureDef[object], module: str) -> str | None:
    """The group a shared fixture puts its users in: its module or its conftest's folder."""
    if fixturedef.scope == "function" or fixturedef.func.__module__ == __name__:
        return None
    path = fixturedef.baseid.split("::")[0]  # "" for a plugin's fixture
    if not path:
        return None
    if fixturedef.scope in ("module", "class"):
        return module  # made once per module, wherever it is defined
    return path  # package or session scope: made once per worker for the whole folder


def _group(item: pytest.Item) -> str | None:
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return None
    module = item.nodeid.split("::")[0]
    homes = set()
    for name in info.names_closure:
        for fixturedef in info.name2fixturedefs.get(name, ()):
            home = _fixture_home(fixturedef, module)
            if home is not None:
                homes.add(home)
    if not homes:
        return None
    # a folder's session fixture outranks a module's fixture inside that folder
    return min(homes, key=lambda home: (home.endswith(".py"), home))


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not hasattr(config, "workerinput"):
        return  # a plain run: nothing to distribute, the collection order is kept
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            group = _group(item)
            if group is not None:
                item.add_marker(pytest.mark.xdist_group(group))
    # the long tests first, so the two workers do not end on one of them (stable: every worker
    # must see the same order)
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
