"""The root of the ``pipeline`` command: the Typer app every command group registers on,
its ``--debug`` option, the console and the JSON printer the commands share."""

from __future__ import annotations

import json
import sys
from typing import Annotated, Any

import typer
from rich.console import Console

app = typer.Typer(
    help=(
        "armlab pipeline: plan a motion for a robot arm (OMPL), run it in MuJoCo under "
        "PID and computed-torque control, record ROS 2 bags (MCAP) and report tracking "
        "error. A robot is a DH YAML, URDF (+ SRDF) or MJCF file, with any number of "
        "joints: built-in ones are listed by `pipeline robots`; any command taking ROBOT "
        "also accepts a path."
    ),
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
console = Console()
STATE = {"debug": False}
"""Options of the root command the commands read (``--debug``)."""


def _print_version(value: bool) -> None:
    if value:
        from pipeline import __version__

        sys.stdout.write(f"armlab-pipeline {__version__}\n")
        raise typer.Exit()


@app.callback()
def _root(
    debug: Annotated[
        bool, typer.Option("--debug", help="Show Python tracebacks for errors.")
    ] = False,
    package_path: Annotated[
        list[str] | None,
        typer.Option(
            "--package-path",
            help="Folder that package:// URIs of a robot's URDF resolve in (repeatable; "
            "before ARMLAB_PACKAGE_PATH and ROS_PACKAGE_PATH).",
        ),
    ] = None,
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            help="Print the version and exit.",
            callback=_print_version,
            is_eager=True,
        ),
    ] = False,
) -> None:
    del version
    STATE["debug"] = debug
    if package_path:
        # an environment variable: episode worker processes inherit it
        import os

        rest = [p for p in os.environ.get("ARMLAB_PACKAGE_PATH", "").split(os.pathsep) if p]
        os.environ["ARMLAB_PACKAGE_PATH"] = os.pathsep.join([*package_path, *rest])


def print_json(obj: Any) -> None:
    """Print one JSON object on stdout."""
    sys.stdout.write(json.dumps(obj, indent=2) + "\n")


ROBOT_HELP = (
    "Built-in robot name (see `pipeline robots`) or path to a robot file: DH YAML, URDF, "
    "MJCF (.xml), or a .armlab.yaml naming a URDF."
)
