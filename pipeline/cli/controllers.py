"""``pipeline check-controller``: run the controller test kit on a built-in or plug-in
controller."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.table import Table

from pipeline.cli.root import app, console, print_json


@app.command("check-controller")
def check_controller_cmd(
    name: Annotated[
        str,
        typer.Argument(
            help="Controller: a built-in name, an installed entry point (armlab.controllers) "
            "or package.module:Object.",
            show_default=False,
        ),
    ],
    robot: Annotated[
        str,
        typer.Option(
            "--robot",
            help="Robot to check on: a built-in name or a robot file (DH YAML, URDF, MJCF); "
            "the checks start from its SRDF named state, else mid-range.",
        ),
    ] = "ur5",
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Run the controller test kit: shapes, gains in effect, gains, determinism, reset,
    closed loop.

    Exits 1 if any check fails (each failure says why in one line).
    """
    from pipeline.control import controller_entry
    from pipeline.sim.testkit import check_controller

    controller_entry(name)  # an unknown or broken plug-in: one error line
    findings = check_controller(name, robot=robot)
    ok = all(f.ok for f in findings)
    if as_json:
        print_json({"controller": name, "ok": ok, "findings": [vars(f) for f in findings]})
    else:
        table = Table("check", "", "detail", title=f"controller '{name}'")
        for f in findings:
            table.add_row(f.check, "ok" if f.ok else "[red]FAIL[/red]", f.detail)
        console.print(table)
    if not ok:
        raise typer.Exit(1)
