from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

import pytest

from pipeline.robots import RobotSpec, load_spec

TESTS = Path(__file__).resolve().parent


@pytest.fixture(scope="session", autouse=True)
def _private_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The suite's converted meshes go to a cache of its own (subprocesses inherit it),
    never the user's ~/.cache/armlab: a test sees what a first run does."""
    import os

    os.environ.setdefault("ARMLAB_CACHE_DIR", str(tmp_path_factory.mktemp("armlab-cache")))


@pytest.fixture(scope="session")
def ur5() -> RobotSpec:
    return load_spec("ur5")


@pytest.fixture(scope="session", params=["ur5", "ur10", "mdh_example"])
def any_robot(request: pytest.FixtureRequest) -> RobotSpec:
    return load_spec(request.param)


@pytest.fixture(scope="session", params=["ur5", "ur10"])
def dynamic_robot(request: pytest.FixtureRequest) -> RobotSpec:
    return load_spec(request.param)


@pytest.fixture(scope="session")
def panda_xml(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """example-robot-data's Panda as an MJCF file (:func:`tests.robots.panda_files.panda_mjcf`);
    skipped without example-robot-data."""
    from tests.robots.panda_files import ERD, panda_mjcf

    if ERD is None:
        pytest.skip("example-robot-data is not installed")
    return panda_mjcf(tmp_path_factory.mktemp("panda_mjcf"))


# --- running on several workers (`pytest -n 2 --dist loadscope`, pytest-xdist) ----------------
#
# A shared fixture is made once per worker process, so each test module goes to one worker
# whole (loadscope: a module's recorded bags or report are made once). A test that names an
# xdist group (`@pytest.mark.xdist_group("ray")`: the tests that start a local Ray instance)
# runs in that group instead, on one worker, one after another. pytest-xdist's own loadgroup
# cannot do this under pytest 9 (it renames items through `item._nodeid`, which pytest 9 no
# longer reads), so the scheduler below reads the groups from the test sources.


def _explicit_groups() -> dict[str, str]:
    """``path::test`` -> group, for every test decorated ``@pytest.mark.xdist_group("name")``."""
    out = {}
    for path in sorted(TESTS.rglob("test_*.py")):
        rel = path.relative_to(TESTS.parent).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.FunctionDef) and node.name.startswith("test_")):
                continue
            for deco in node.decorator_list:
                if (
                    isinstance(deco, ast.Call)
                    and isinstance(deco.func, ast.Attribute)
                    and deco.func.attr == "xdist_group"
                    and deco.args
                    and isinstance(deco.args[0], ast.Constant)
                ):
                    out[f"{rel}::{node.name}"] = str(deco.args[0].value)
    return out


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    groups = _explicit_groups()

    class ModulesAndGroups(LoadScopeScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            return groups.get(nodeid.split("[")[0]) or nodeid.split("::")[0]

    # work units in collection order, which puts the modules with slow tests first (below)
    config.option.loadscopereorder = False
    return ModulesAndGroups(config, log)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not hasattr(config, "workerinput"):
        return  # a plain run: the collection order is kept
    # the slow tests first, so the two workers do not end on one of them (a stable sort: every
    # worker must see the same order)
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
