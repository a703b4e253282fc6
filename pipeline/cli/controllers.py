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
    budget_s: Annotated[
        float,
        typer.Option(
            "--budget-s", min=0.001, help="Wall-clock budget of the whole check of a plug-in \\[s]."
        ),
    ] = 60.0,
) -> None:
    """Run the controller test kit: shapes, gains in effect, gains, determinism, reset,
    closed loop.

    Exits 1 if any check fails (each failure says why in one line). A plug-in that raises,
    exits (sys.exit, KeyboardInterrupt) or runs past --budget-s (its import included) is
    one error line naming the controller, its origin and the reason.
    """
    from pipeline.control import controller_entry, controller_origin
    from pipeline.control.contain import Budget, PluginScope, is_builtin
    from pipeline.sim.testkit import check_controller

    if is_builtin(name):
        findings = check_controller(name, robot=robot)
    else:  # plug-in code: its import and the whole kit within --budget-s, in one line
        with PluginScope(name, budget=Budget(call_s=budget_s, episode_s=budget_s)) as scope:
            scope.call("import", lambda: controller_entry(name))  # unknown, broken: one line
            scope.set_origin(controller_origin(name))
            findings = scope.call("check", lambda: list(check_controller(name, robot=robot)))
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
