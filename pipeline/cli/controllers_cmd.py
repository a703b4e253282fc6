"""``pipeline check-controller``: run the controller test kit on a built-in or plug-in
controller."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Annotated, Any

import typer
from rich.table import Table

from pipeline.cli.root import app, console, print_json


def in_child(fn: Callable[[Callable[[str], None]], Any], *, what: str, timeout_s: float) -> Any:
    """``fn(note)`` run in a forked child process; its value, or its one-line error raised here.

    A child that ends without an answer (plug-in code calling ``os._exit``, a crash in a C
    extension) or outlives ``timeout_s`` [s] is a :class:`PipelineError` naming ``what``, or
    the last text the child passed to ``note`` (e.g. the controller with its origin).
    """
    import multiprocessing

    from pipeline.errors import PipelineError

    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)

    def child() -> None:
        try:
            answer: tuple[str, Any] = ("ok", fn(lambda text: send.send(("note", text))))
        except PipelineError as err:
            answer = ("error", str(err))
        except BaseException as err:
            answer = ("error", f"{what}: {type(err).__name__}: {err}")
        send.send(answer)
        send.close()

    proc = ctx.Process(target=child, daemon=True)
    proc.start()
    send.close()
    deadline = time.monotonic() + timeout_s
    kind, value = "note", what
    try:
        while kind == "note":
            what = str(value)
            if not receive.poll(max(0.0, deadline - time.monotonic())):
                raise PipelineError(f"{what}: the check ran past {timeout_s:g} s and was stopped")
            try:
                kind, value = receive.recv()
            except EOFError:
                proc.join(5.0)
                raise PipelineError(
                    f"{what}: its process died (exit code {proc.exitcode}) during the check "
                    "(plug-in code ended the process: os._exit, or a crash)"
                ) from None
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join(5.0)
        receive.close()
    if kind == "error":
        raise PipelineError(str(value))
    return value


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
    from pipeline.control.contain import Budget, PluginScope, describe_origin, is_builtin
    from pipeline.sim.testkit import check_controller

    if is_builtin(name):
        findings = check_controller(name, robot=robot)
    else:  # plug-in code: its import and the whole kit within --budget-s, in one line,
        # in a child process: plug-in code that ends its process (os._exit) ends the child

        def kit(note: Callable[[str], None]) -> list[Any]:
            with PluginScope(name, budget=Budget(call_s=budget_s, episode_s=budget_s)) as scope:
                scope.call("import", lambda: controller_entry(name))  # unknown, broken: 1 line
                origin = controller_origin(name)
                scope.set_origin(origin)
                note(f"controller '{name}' ({describe_origin(origin)})")
                return list(scope.call("check", lambda: list(check_controller(name, robot=robot))))

        findings = in_child(kit, what=f"controller '{name}'", timeout_s=budget_s + 60.0)
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
