"""``pipeline teach``: the interactive teach pendant."""

from __future__ import annotations

import signal
import sys
import threading
from typing import Annotated

import typer

from pipeline.cli.root import ROBOT_HELP, app, console


@app.command("teach")
def teach_cmd(
    robot: Annotated[str, typer.Argument(help=ROBOT_HELP, show_default=False)],
    solver: Annotated[
        str | None,
        typer.Option(
            "--solver",
            help="IK solver: 'analytic' (closed form, every solution, UR-type arms) or "
            "'numeric' (Levenberg-Marquardt, seeded from the current pose). Default: analytic "
            "where it fits, else numeric (the page says why).",
            show_default=False,
        ),
    ] = None,
    port: Annotated[
        int, typer.Option("--port", min=0, max=65535, help="TCP port of the page (0: any free).")
    ] = 8080,
    host: Annotated[
        str,
        typer.Option(
            "--host", help="Interface to listen on; 0.0.0.0 exposes the page to the network."
        ),
    ] = "127.0.0.1",
    params: Annotated[
        str,
        typer.Option(
            "--params",
            help="The params file 'Use as goal' writes (the only one: a page cannot pick another).",
        ),
    ] = "params.yaml",
) -> None:
    """Interactive IK in the browser: a local web page with a draggable flange target.

    Dragging the 6-DOF gizmo solves IK live; the page shows every analytic solution,
    the FK check of the shown one (position error \\[mm], orientation error \\[rad],
    solve time \\[ms] against < 0.1 mm, < 0.01 rad, < 5 ms), joint values with limit
    bars, manipulability and singularity warnings, joint sliders for FK, the ik-check
    error map on request, and 'Use as goal' to write the pose into a params file.
    Ctrl-C stops it.
    """

    from pipeline.robots import load_spec
    from pipeline.teach.server import TeachServer
    from pipeline.teach.session import TeachSession, choose_solver

    spec = load_spec(robot)
    ik, note = choose_solver(spec, solver)
    server = TeachServer(
        TeachSession(spec, ik), robot_arg=robot, solver_note=note, host=host, port=port,
        params_path=params,
    )  # fmt: skip
    stop = threading.Event()
    # explicit handlers: a background job starts with SIGINT ignored, and Ctrl-C must stop it
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    if note:
        sys.stderr.write(f"note: {note}\n")
    console.print(
        f"teach: {spec.name} ({ik.name} IK) at {server.url}  (open it in a browser; Ctrl-C stops)"
    )
    try:
        while not stop.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    console.print("teach: stopped")
