from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from pipeline.robots import load_spec
from pipeline.teach.server import TeachServer
from pipeline.teach.session import TeachSession, choose_solver

ROBOTS_DIR = Path(__file__).resolve().parents[2] / "pipeline" / "robots"


@pytest.fixture
def user_robot(tmp_path: Path) -> Path:
    """A user's YAML robot outside the package: the mdh example arm under another name."""
    text = (ROBOTS_DIR / "mdh_example.yaml").read_text()
    path = tmp_path / "my_arm.yaml"
    path.write_text(text.replace("name: mdh_example", "name: my_arm"))
    return path


def start_server(
    robot: str, *, solver: str | None = None, params: str = "params.yaml"
) -> TeachServer:
    spec = load_spec(robot)
    ik, note = choose_solver(spec, solver)
    return TeachServer(
        TeachSession(spec, ik), robot_arg=robot, solver_note=note, port=0, params_path=params
    )


@pytest.fixture
def ur5_server() -> Iterator[TeachServer]:
    server = start_server("ur5")
    yield server
    server.close()
