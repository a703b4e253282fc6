"""Paper cuts a new user meets first: options where users type them, help text that keeps its
units, robot files found where pip put them, kinematics without visual meshes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import typer.main
import yourdfpy
from rich.text import Text

from pipeline.cli import app, hoist_root_options
from pipeline.robots.packages import example_robot_data_share, package_search_path

SHARE = example_robot_data_share()
needs_erd = pytest.mark.skipif(SHARE is None, reason="example-robot-data is not installed")


def _pipeline(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pipeline", *args],
        capture_output=True, text=True, timeout=180, cwd=cwd,
    )  # fmt: skip


def test_root_options_are_accepted_after_the_command() -> None:
    args = ["fk", "arm.urdf", "0", "--package-path", "/ws/src", "-0.5", "--debug"]
    assert hoist_root_options(args) == [
        "--package-path", "/ws/src", "--debug", "fk", "arm.urdf", "0", "-0.5",
    ]  # fmt: skip
    assert hoist_root_options(["fk", "x", "--package-path=/a"]) == ["--package-path=/a", "fk", "x"]
    # a dangling option is left where it is, for Typer to refuse in one line
    assert hoist_root_options(["fk", "--package-path"]) == ["fk", "--package-path"]


def _help_texts() -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []

    def walk(cmd: object, path: str) -> None:
        out.append((path, getattr(cmd, "help", None) or ""))
        for param in getattr(cmd, "params", []):
            out.append((f"{path} {param.name}", getattr(param, "help", None) or ""))
        for name, sub in getattr(cmd, "commands", {}).items():
            walk(sub, f"{path} {name}")

    walk(typer.main.get_command(app), "pipeline")
    return out


def test_no_help_text_loses_a_bracketed_unit_to_rich_markup() -> None:
    """Rich reads ``[rad]`` as a style tag and prints nothing: units must be escaped."""
    lost = [
        (where, text)
        for where, text in _help_texts()
        if Text.from_markup(text).plain.count("[") != text.count("[")
    ]
    assert not lost, lost


@needs_erd
def test_example_robot_data_is_found_through_its_installed_distribution() -> None:
    assert SHARE is not None
    assert (SHARE / "example-robot-data" / "robots" / "panda_description").is_dir()
    assert SHARE in package_search_path()


@needs_erd
def test_fk_needs_no_visual_mesh_and_takes_package_path_after_the_command(tmp_path: Path) -> None:
    """A URDF whose visual meshes point nowhere still gives FK (equal to an independent
    parser's), and --package-path may follow the subcommand."""
    assert SHARE is not None
    src = SHARE / "example-robot-data" / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf"
    text = src.read_text()
    assert "<visual>" in text
    # collision meshes resolve only through a package folder given after the command
    # (package 'my_ur'); visual meshes name a package nobody has
    pkg = tmp_path / "pkgs"
    pkg.mkdir()
    (pkg / "my_ur").symlink_to(SHARE / "example-robot-data")
    urdf = tmp_path / "ur5_no_visuals.urdf"
    parts = text.replace("package://example-robot-data/", "package://my_ur/").split("<visual>")
    rewritten = parts[0] + "".join(
        "<visual>" + p.replace("package://my_ur/", "package://gone_pkg/", 1) for p in parts[1:]
    )
    urdf.write_text(rewritten)
    q = [0.3, -1.2, 1.4, -0.8, 1.1, 0.5]
    run = _pipeline("fk", str(urdf), *map(str, q), "--json", "--package-path", str(pkg))
    assert run.returncode == 0, run.stderr
    got = np.array(json.loads(run.stdout)["position"])
    robot = yourdfpy.URDF.load(str(src), load_meshes=False, build_scene_graph=True)
    names = [j for j in robot.actuated_joint_names]
    robot.update_cfg(dict(zip(names, q, strict=True)))
    want = robot.get_transform("tool0", robot.base_link)[:3, 3]
    assert np.abs(got - want).max() < 1e-9


def test_layouts_module_help_writes_no_folder(tmp_path: Path) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "pipeline.log.layouts", "--help"],
        capture_output=True, text=True, timeout=60, cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 0 and "usage:" in run.stdout
    assert list(tmp_path.iterdir()) == []
