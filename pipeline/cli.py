"""The ``pipeline`` command: a thin Typer app. Parse, call, print, exit code.

Errors that are the user's input (:class:`PipelineError`) print one
``error: ...`` line and exit 1; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import json
import sys
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from pipeline.errors import PipelineError

app = typer.Typer(
    help=(
        "armlab pipeline: plan a motion for a robot arm (OMPL), run it in MuJoCo under "
        "PID and computed-torque control, record ROS 2 bags (MCAP) and report tracking "
        "error. Robots are YAML files (DH parameters + inertias): built-in ones are "
        "listed by `pipeline robots`; any command taking ROBOT also accepts a path."
    ),
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
console = Console()
_state = {"debug": False}


@app.callback()
def _root(
    debug: Annotated[
        bool, typer.Option("--debug", help="Show Python tracebacks for errors.")
    ] = False,
) -> None:
    _state["debug"] = debug


def print_json(obj: Any) -> None:
    """Print one JSON object on stdout."""
    sys.stdout.write(json.dumps(obj, indent=2) + "\n")


@app.command("robots")
def robots_cmd(
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """List the built-in robots: name, DOF, DH convention, whether dynamics are given."""
    from pipeline.robots import builtin_robot_names, load_spec

    specs = [load_spec(n) for n in builtin_robot_names()]
    if as_json:
        print_json(
            {
                "robots": [
                    {
                        "name": s.name,
                        "dof": s.dof,
                        "convention": s.convention,
                        "has_dynamics": s.has_dynamics,
                    }
                    for s in specs
                ]
            }
        )
        return
    table = Table("robot", "dof", "convention", "dynamics")
    for s in specs:
        table.add_row(s.name, str(s.dof), s.convention, "yes" if s.has_dynamics else "no")
    console.print(table)


def main() -> None:
    """Console-script entry point."""
    debug = "--debug" in sys.argv[1:]
    try:
        app()
    except PipelineError as err:
        if debug:
            raise
        sys.stderr.write(f"error: {err}\n")
        sys.exit(1)
