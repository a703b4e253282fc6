"""The ``pipeline`` command: a thin Typer app. Parse, call, print, exit code.

Errors that are the user's input (:class:`PipelineError`) print one
``error: ...`` line and exit 1; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
from typing import Annotated, Any, Literal, NoReturn

import typer
from rich.console import Console
from rich.table import Table

from pipeline.errors import (
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    PipelineError,
    handle_sigterm,
    interrupt_exit,
)

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


_ROBOT_HELP = "Built-in robot name (see `pipeline robots`) or path to a robot YAML file."


def _joint_list(text: str, option: str) -> list[float]:
    """Parse 'a,b,c' or 'a b c' [rad] into floats, with a one-line error."""
    from pipeline.errors import KinematicsError

    parts = [p for p in text.replace(",", " ").split() if p]
    try:
        return [float(p) for p in parts]
    except ValueError as err:
        raise KinematicsError(
            f"{option}: expected numbers separated by commas or spaces [rad], got '{text}'"
        ) from err


def _check_joints(spec: Any, joints: list[float]) -> None:
    """Refuse joint values that are not finite or outside the robot's limits (one line)."""
    from pipeline.errors import KinematicsError

    if len(joints) != spec.dof:
        return  # forward_kinematics names the count
    for i, (q, j) in enumerate(zip(joints, spec.joints, strict=True)):
        if not (j.limits.lower <= q <= j.limits.upper):  # NaN fails this too
            raise KinematicsError(
                f"joint {i + 1} ({j.name}): {q!r} rad is outside its limits "
                f"[{j.limits.lower:.6g}, {j.limits.upper:.6g}] rad"
            )


@app.command("fk", context_settings={"ignore_unknown_options": True})
def fk_cmd(
    robot: Annotated[str, typer.Argument(help=_ROBOT_HELP, show_default=False)],
    joints: Annotated[
        list[float],
        typer.Argument(
            help="Joint positions \\[rad], one per joint in chain order; negative values are "
            "fine (e.g. `pipeline fk ur5 0 -1.57 0 0 0 0`).",
            show_default=False,
        ),
    ],
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Forward kinematics: the flange pose (DH frame n) in the DH base frame.

    Prints position \\[m], quaternion (w, x, y, z) and roll/pitch/yaw \\[rad] with
    R = Rz(yaw) Ry(pitch) Rx(roll).
    """
    from pipeline.kinematics.base import pose_summary
    from pipeline.model.dh import forward_kinematics
    from pipeline.robots import load_spec

    spec = load_spec(robot)
    _check_joints(spec, joints)
    pose = pose_summary(forward_kinematics(spec, joints))
    if as_json:
        print_json({"robot": spec.name, "joints": [float(q) for q in joints], **pose})
        return
    table = Table("quantity", "value", title=f"{spec.name}: flange in base frame")
    # "\\[" keeps rich from reading the units as markup tags
    table.add_row("joints \\[rad]", " ".join(f"{q:.6g}" for q in joints))
    table.add_row("position \\[m]", " ".join(f"{v:.6f}" for v in pose["position"]))
    table.add_row("quaternion (w x y z)", " ".join(f"{v:.6f}" for v in pose["quaternion_wxyz"]))
    table.add_row("rpy (roll pitch yaw) \\[rad]", " ".join(f"{v:.6f}" for v in pose["rpy"]))
    console.print(table)


@app.command("ik")
def ik_cmd(
    robot: Annotated[str, typer.Argument(help=_ROBOT_HELP, show_default=False)],
    position: Annotated[
        tuple[float, float, float],
        typer.Option(
            "--position",
            help="Flange position X Y Z \\[m] in the DH base frame.",
            show_default=False,
        ),
    ],
    quaternion: Annotated[
        tuple[float, float, float, float] | None,
        typer.Option(
            "--quaternion",
            help="Flange orientation as a quaternion W X Y Z (normalised here). "
            "Give this or --rpy.",
            show_default=False,
        ),
    ] = None,
    rpy: Annotated[
        tuple[float, float, float] | None,
        typer.Option(
            "--rpy",
            help="Flange orientation as roll pitch yaw \\[rad], R = Rz(yaw) Ry(pitch) Rx(roll). "
            "Give this or --quaternion.",
            show_default=False,
        ),
    ] = None,
    solver: Annotated[
        str,
        typer.Option(
            "--solver",
            help="IK solver: 'numeric' (Levenberg-Marquardt, any arm, one solution) or "
            "'analytic' (closed form, UR-type arms, every solution within limits).",
        ),
    ] = "numeric",
    seed_joints: Annotated[
        str | None,
        typer.Option(
            "--seed-joints",
            help="Seed joints \\[rad], one per joint, comma- or space-separated "
            "(e.g. '0,-1.57,0,0,0,0'): numeric starts there; solutions nearest to it come "
            "first. Default: middle of each joint's range.",
            show_default=False,
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Inverse kinematics: joint vectors \\[rad] that put the flange at the given pose.

    Every printed solution is checked by forward kinematics (errors shown).
    Exits 1 with one line if the pose is unreachable.
    """
    from rich import box
    from rich.table import Column

    from pipeline.errors import KinematicsError
    from pipeline.kinematics import (
        DEFAULT_TOL_M,
        DEFAULT_TOL_RAD,
        make_solver,
        pose_summary,
        target_pose,
        verify_solution,
    )
    from pipeline.robots import load_spec

    spec = load_spec(robot)
    target = target_pose(position, quaternion_wxyz=quaternion, rpy_rad=rpy)
    seed = None if seed_joints is None else _joint_list(seed_joints, "--seed-joints")
    result = make_solver(solver, spec).solve(target, seed_q=seed)
    if not result.ok:
        raise KinematicsError(result.reason)
    rows = []
    for q in result.solutions:
        pos_err, ang_err = verify_solution(spec, q, target)
        if pos_err <= DEFAULT_TOL_M and ang_err <= DEFAULT_TOL_RAD:
            rows.append(([float(v) for v in q], pos_err, ang_err))
    if not rows:
        raise KinematicsError(
            f"robot '{spec.name}': {solver} IK returned {len(result.solutions)} solution(s) but "
            f"none reproduces the target within {DEFAULT_TOL_M:g} m / {DEFAULT_TOL_RAD:g} rad"
        )
    if as_json:
        print_json(
            {
                "robot": spec.name,
                "solver": solver,
                "target": pose_summary(target),
                "solutions": [r[0] for r in rows],
                "position_error_m": [r[1] for r in rows],
                "orientation_error_rad": [r[2] for r in rows],
            }
        )
        return
    table = Table(
        "#", *(Column(f"q{i}", justify="right", min_width=7) for i in range(1, spec.dof + 1)),
        Column("pos \\[m]", min_width=5), Column("ori \\[rad]", min_width=5),
        title=f"{spec.name}: {len(rows)} IK solution(s) \\[rad] ({solver})", box=box.SIMPLE,
        pad_edge=False,
    )  # fmt: skip
    for i, (q, pos_err, ang_err) in enumerate(rows, start=1):
        table.add_row(str(i), *(f"{v:.4f}" for v in q), f"{pos_err:.0e}", f"{ang_err:.0e}")
    console.print(table)


@app.command("ik-check")
def ik_check_cmd(
    robot: Annotated[str, typer.Argument(help=_ROBOT_HELP, show_default=False)],
    solver: Annotated[
        str,
        typer.Option("--solver", help="IK solver to check: 'numeric' or 'analytic'."),
    ] = "numeric",
    samples: Annotated[
        int,
        typer.Option("--samples", min=1, help="Random joint configurations to round-trip."),
    ] = 1000,
    seed: Annotated[
        int,
        typer.Option(
            "--seed",
            min=0,
            help="Seed of the random configurations and the IK restarts (>= 0).",
        ),
    ] = 0,
    out: Annotated[
        str,
        typer.Option("--out", "-o", help="Folder that receives ik_check.json and error_map.png."),
    ] = "reports/ik-check",
    min_success_rate: Annotated[
        float,
        typer.Option(
            "--min-success-rate",
            min=0.0,
            max=1.0,
            help="Fraction of samples that must solve within the error targets to pass.",
        ),
    ] = 0.995,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Validate IK: random joints within limits -> FK -> IK -> FK.

    Reports success rate, position error \\[m] and orientation error \\[rad] (max,
    median over every returned solution), solve time \\[ms] (mean, median, p99),
    and PASS/FAIL against the kinematics notes' targets: < 0.1 mm, < 0.01 rad,
    < 5 ms (p99). Writes an error map over the workspace (PNG). Exits 1 on FAIL.
    """
    from pathlib import Path

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from pipeline.fsutil import ensure_dir
    from pipeline.kinematics.check import run_ik_check
    from pipeline.robots import load_spec

    spec = load_spec(robot)
    ensure_dir(Path(out))  # before the work: a bad --out fails in a second, not after it
    with Progress(
        TextColumn("ik-check {task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        console=Console(stderr=True),
        transient=True,
        disable=as_json,
    ) as bars:
        task = bars.add_task(f"{spec.name} ({solver})", total=samples)
        report = run_ik_check(
            spec,
            solver_name=solver,
            samples=samples,
            seed=seed,
            out_dir=Path(out),
            min_success_rate=min_success_rate,
            progress=lambda n: bars.advance(task, n),
        )
    if as_json:
        print_json(report.to_json())
    else:
        ok = {True: "[green]pass[/green]", False: "[red]FAIL[/red]"}
        table = Table(
            "quantity", "value", "target", "",
            title=f"IK check: {report.robot}, {report.solver}, {report.samples} samples",
        )  # fmt: skip
        c, pe, oe, st = (report.checks, report.position_error_m,
                         report.orientation_error_rad, report.solve_time_ms)  # fmt: skip
        table.add_row(
            "success rate", f"{100 * report.success_rate:.2f} %",
            f">= {100 * min_success_rate:g} %", ok[c["success_rate"]],
        )  # fmt: skip
        table.add_row("position error max / median \\[m]", f"{pe.max:.2e} / {pe.median:.2e}",
                      "< 1e-4", ok[c["position_error"]])  # fmt: skip
        table.add_row("orientation error max / median \\[rad]", f"{oe.max:.2e} / {oe.median:.2e}",
                      "< 1e-2", ok[c["orientation_error"]])  # fmt: skip
        table.add_row("solve time mean / median / p99 \\[ms]",
                      f"{st.mean:.3f} / {st.median:.3f} / {st.p99:.3f}", "p99 < 5",
                      ok[c["solve_time"]])  # fmt: skip
        console.print(table)
        verdict = "[green]PASS[/green]" if report.passed else "[red]FAIL[/red]"
        console.print(f"{verdict}; wrote {report.error_map_png} and {report.summary_json}")
    if not report.passed:
        raise typer.Exit(1)


@app.command("teach")
def teach_cmd(
    robot: Annotated[str, typer.Argument(help=_ROBOT_HELP, show_default=False)],
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
        str, typer.Option("--params", help="Default params file for 'Use as goal'.")
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
    import signal
    import threading

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
        str, typer.Option("--robot", help="Robot to check on (name or YAML path).")
    ] = "ur5",
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Run the controller test kit: shapes, settings, gains, determinism, reset, closed loop.

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


def _interrupt_in_chain(err: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (Ctrl-C, or :class:`Terminated` for SIGTERM) anywhere in the
    exception's cause chain, or None."""
    seen: set[int] = set()
    cause: BaseException | None = err
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return cause
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return None


def _stop(err: BaseException) -> NoReturn:
    """One line (``interrupted`` or ``terminated``) and 130 or 143."""
    word, code = interrupt_exit(err)
    sys.stderr.write(f"{word}\n")
    sys.exit(code)


def main() -> None:
    """Console-script entry point."""
    debug = "--debug" in sys.argv[1:]
    if debug:  # accepted anywhere on the line, not only before the command
        sys.argv = [sys.argv[0], "--debug", *(a for a in sys.argv[1:] if a != "--debug")]
    # A job started in the background by a non-interactive shell inherits SIGINT ignored;
    # `kill -INT` must still stop a run (and say what it finished).
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
    handle_sigterm()  # SIGTERM takes Ctrl-C's path: the same cleanup, then 143
    try:
        app()
    except SystemExit as exit_:
        if exit_.code == EXIT_INTERRUPTED:  # typer ends a command's Ctrl-C silently with 130
            _stop(_interrupt_in_chain(exit_) or KeyboardInterrupt())
        raise
    except KeyboardInterrupt as err:
        if debug:
            raise
        _stop(err)
    except ImportError as err:
        # Ctrl-C inside a C extension's module init surfaces as "initialization failed"
        interrupt = _interrupt_in_chain(err)
        if debug or interrupt is None:
            raise
        _stop(interrupt)
    except PipelineError as err:
        if debug:
            raise
        code = getattr(err, "exit_code", 1)
        if code in (EXIT_INTERRUPTED, EXIT_TERMINATED):  # record's Interrupted
            sys.stderr.write(f"{err}\n")
            sys.exit(code)
        sys.stderr.write(f"error: {err}\n")
        sys.exit(1)


@app.command("record")
def record_cmd(
    params: Annotated[
        str, typer.Option("--params", help="Scenarios, controllers and episodes (YAML).")
    ] = "params.yaml",
    out: Annotated[
        str, typer.Option("--out", "-o", help="Directory that receives one ROS 2 bag per episode.")
    ] = "recordings",
    only: Annotated[
        list[str] | None,
        typer.Option("--only", help="Run only this episode (repeatable). Default: all."),
    ] = None,
    jobs: Annotated[
        int, typer.Option("--jobs", "-j", min=1, help="Episodes run in parallel (processes).")
    ] = 1,
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite recordings that already exist.")
    ] = False,
    ros_distro: Annotated[
        str | None,
        typer.Option(
            "--ros-distro",
            help="Write the message definitions and metadata of this ROS 2 distribution "
            "(jazzy or humble) so its subscribers decode every topic. Default: sim.ros_distro "
            "in PARAMS (jazzy).",
        ),
    ] = None,
    campaign: Annotated[
        str | None,
        typer.Option(
            "--campaign",
            help="Run this campaign of PARAMS into OUT/<campaign>/ (see `pipeline campaigns`); "
            "a re-run skips the episodes already recorded.",
        ),
    ] = None,
    executor: Annotated[
        str,
        typer.Option("--executor", help="local (processes, --jobs) or ray (a Ray instance)."),
    ] = "local",
    address: Annotated[
        str | None,
        typer.Option("--address", help="Ray cluster to join (e.g. auto); default: start one."),
    ] = None,
) -> None:
    """Plan, simulate and record every episode in PARAMS as a ROS 2 bag (MCAP).

    Each scenario is planned once (OMPL RRTConnect, seeded), time-parameterized
    (TOPP-RA), then run in MuJoCo under each controller. Each episode's bag is
    written atomically to OUT/<episode>/ (the episode's key in PARAMS). If a
    selected episode's bag already exists, nothing runs unless --force (or pick
    others with --only). Exits 1 if any episode failed, after writing the others.
    Episodes that would not fit in memory (or run over 2 h) are refused before any
    work. One run per OUT at a time; Ctrl-C exits 130 and says which episodes were
    recorded.
    With --campaign, runs that campaign instead of the hand-listed episodes.
    """
    from pathlib import Path

    if ros_distro is not None:
        _ros_distro(ros_distro)  # refused before any work
    if executor not in ("local", "ray"):
        raise PipelineError(f"--executor: expected local or ray, got '{executor}'")
    if address is not None and executor != "ray":
        raise PipelineError("--address: only with --executor ray")
    if campaign is not None:
        if only:
            raise PipelineError("--only: not with --campaign (a campaign runs whole)")
        _record_campaign(params, campaign, out=Path(out), jobs=jobs, force=force,
                         executor=executor, address=address, ros_distro=ros_distro)  # fmt: skip
        return

    from pipeline.fsutil import OutputLock
    from pipeline.params import load_params
    from pipeline.stages.record import check_outputs_free, prepare

    loaded = load_params(params)
    if not loaded.episodes:
        names = ", ".join(loaded.campaigns)
        raise PipelineError(
            f"{params}: no hand-listed episodes; run a campaign with --campaign NAME ({names})"
        )
    if ros_distro is not None:
        loaded = loaded.with_ros_distro(_ros_distro(ros_distro))
    # every input error first: a refused run creates nothing
    selected = prepare(loaded, out_dir=Path(out), only=only, force=force, jobs=jobs)
    # One run per --out at a time: two runs would mix episodes of two params files.
    with OutputLock(Path(out), command="`pipeline record`"):
        check_outputs_free(selected, Path(out), force=force)  # again, now that we own it
        outcomes = _record_with_progress(loaded, selected, out=Path(out), jobs=jobs,
                                         force=force, executor=executor,
                                         address=address)  # fmt: skip
    table = Table("episode", "status", "max |e| (rad)", "final |e| (rad)", "sim (s)", "wall (s)")
    for o in outcomes:
        table.add_row(
            o.name,
            o.status if o.status == "ok" else f"[red]{o.status}[/red]",
            f"{o.max_abs_error_rad:.3e}",
            f"{o.final_abs_error_rad:.3e}",
            f"{o.duration_s:.2f}",
            f"{o.wall_s:.2f}",
        )
    console.print(table)
    for o in outcomes:
        if o.contact:
            sys.stderr.write(f"warning: {o.name}: contact during execution: {o.contact}\n")
    failed = [o for o in outcomes if o.status != "ok"]
    for o in failed:
        sys.stderr.write(f"error: {o.name}: {o.reason}\n")
    if failed:
        raise typer.Exit(1)
    console.print(f"wrote {len(outcomes)} recording(s) to {out}/")


def _record_with_progress(
    loaded: Any, selected: Any, *, out: Any, jobs: int, force: bool, executor: str = "local",
    address: str | None = None,
) -> list[Any]:  # fmt: skip
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from pipeline.stages.record import record

    with Progress(
        TextColumn("{task.description:<32}"),
        BarColumn(),
        TextColumn("{task.percentage:>5.1f}%"),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=False,
        disable=not sys.stderr.isatty(),  # no bar spam in logs (dvc repro, CI)
    ) as bars:
        tasks = {e.name: bars.add_task(e.name, total=1.0) for e in selected}
        plan_task = bars.add_task("planning", total=len({e.scenario_name for e in selected}))

        def on_event(kind: str, name: str, value: float) -> None:
            if kind == "plan":
                bars.advance(plan_task, 1)
            elif name in tasks:
                bars.update(tasks[name], completed=value)

        return record(loaded, selected, out_dir=out, jobs=jobs, force=force, on_event=on_event,
                      executor=executor, address=address)  # fmt: skip


def _run_campaign(
    loaded: Any, run: Any, *, jobs: int, executor: str, address: str | None
) -> list[Any] | None:
    """Run a planned campaign under one progress bar with ETA (None: nothing to run)."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from pipeline.stages.campaign_run import completion_marker
    from pipeline.stages.record import record

    err = Console(stderr=True)
    name = run.name
    if run.skipped:
        err.print(f"{name}: {len(run.skipped)} of {len(run.episodes)} episode(s) already "
                  f"recorded with these settings and code; running {len(run.pending)}")  # fmt: skip
    if run.stray:
        more = f" (and {len(run.stray) - 1} more)" if len(run.stray) > 1 else ""
        err.print(f"warning: {run.out_dir}: {run.stray[0]}{more} is not an episode of "
                  f"campaign {name} (left in place; the report will read it)")  # fmt: skip
    if not run.pending:
        console.print(f"campaign {name}: all {len(run.episodes)} episode(s) recorded in "
                      f"{run.out_dir}/")  # fmt: skip
        return None
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=err,
        disable=not err.is_terminal,  # no bar spam in logs (dvc repro, CI)
    ) as bars:
        task = bars.add_task(f"{name}", total=len(run.pending))
        running: dict[str, float] = {}
        finished = [0]

        def on_event(kind: str, episode: str, value: float) -> None:
            if kind == "episode":
                running[episode] = value
            elif kind == "done":
                running.pop(episode, None)
                finished[0] += 1
            elif kind == "plan":
                return
            bars.update(task, completed=finished[0] + sum(running.values()))

        outcomes: list[Any] = record(
            loaded, run.pending, out_dir=run.out_dir, jobs=jobs, force=True,
            on_event=completion_marker(run, on_event), executor=executor, address=address,
            commit=run.commit,
        )  # fmt: skip
    return outcomes


def _ros_distro(name: str) -> Literal["jazzy", "humble"]:
    if name not in ("jazzy", "humble"):
        from pipeline.errors import ParamsError

        raise ParamsError(f"--ros-distro: {name!r}, expected jazzy or humble")
    return "humble" if name == "humble" else "jazzy"


SUMMARY_TABLE_MAX = 30  # larger campaigns: counts and the failures, not a row per episode


def _record_campaign(
    params: str, name: str, *, out: Any, jobs: int, force: bool, executor: str,
    address: str | None, ros_distro: str | None = None,
) -> None:  # fmt: skip
    """``pipeline record --campaign NAME``: one progress bar with ETA over the campaign."""
    from pipeline.fsutil import OutputLock, ensure_dir
    from pipeline.params import load_params
    from pipeline.stages.campaign_run import check_campaign_size, distinct_settings, plan_run
    from pipeline.stages.record import check_outputs_free, validate_episodes

    loaded = load_params(params)
    if ros_distro is not None:
        loaded = loaded.with_ros_distro(_ros_distro(ros_distro))
    run = plan_run(loaded, name, out=out, force=force)
    # every input error first: a refused run creates nothing
    validate_episodes(loaded, distinct_settings(run.pending))
    check_campaign_size(loaded, run, motion_s=0.0, jobs=jobs)
    ensure_dir(run.out_dir)
    # one run per campaign folder at a time (two would write the same episodes)
    with OutputLock(run.out_dir, command=f"`pipeline record --campaign {name}`"):
        run = plan_run(loaded, name, out=out, force=force)  # what is done now that we own it
        check_outputs_free(run.pending, run.out_dir, force=True)  # sweeps dead runs' work
        outcomes = _run_campaign(loaded, run, jobs=jobs, executor=executor, address=address)
    if outcomes is None:
        return
    failed = [o for o in outcomes if o.status != "ok"]
    if len(outcomes) <= SUMMARY_TABLE_MAX:
        table = Table("episode", "status", "max |e| (rad)", "final |e| (rad)", "wall (s)")
        for o in outcomes:
            table.add_row(
                o.name, o.status if o.status == "ok" else f"[red]{o.status}[/red]",
                f"{o.max_abs_error_rad:.3e}", f"{o.final_abs_error_rad:.3e}", f"{o.wall_s:.2f}",
            )  # fmt: skip
        console.print(table)
    counts: dict[str, int] = {}
    for o in outcomes:
        counts[o.status] = counts.get(o.status, 0) + 1
    touched = sum(1 for o in outcomes if o.contact)
    console.print(
        f"campaign {name}: {', '.join(f'{n} {s}' for s, n in sorted(counts.items()))}"
        + (f", {len(run.skipped)} skipped (already recorded)" if run.skipped else "")
        + (f", {touched} with contact" if touched else "")
        + f" -> {run.out_dir}/"
    )
    for o in failed:
        sys.stderr.write(f"error: {name}/{o.name}: {o.status}: {o.reason}\n")
    if failed:
        raise typer.Exit(1)


@app.command("campaigns")
def campaigns_cmd(
    params: Annotated[
        str, typer.Option("--params", help="Scenarios, controllers and campaigns (YAML).")
    ] = "params.yaml",
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """List the campaigns in PARAMS: size, base scenario, and what each sweeps."""
    from pipeline.params import load_params
    from pipeline.stages.campaign import campaign_axes

    loaded = load_params(params)
    rows: list[dict[str, Any]] = []
    for name in loaded.campaigns:
        c = campaign_axes(loaded, name)
        axes = [
            {"axis": "controller", "values": list(c.controllers), "drawn": False},
            *({"axis": a.path, "values": list(a.texts), "drawn": a.drawn} for a in c.axes),
            {"axis": "seed", "values": list(c.seeds), "drawn": False},
        ]
        rows.append({"campaign": name, "scenario": c.scenario_name, "episodes": c.size,
                     "axes": axes})  # fmt: skip
    if as_json:
        print_json({"campaigns": rows})
        return
    table = Table("campaign", "scenario", "episodes", "sweeps (values)")
    for row in rows:
        parts = []
        for a in row["axes"]:
            vals = [str(v) for v in a["values"]]
            shown = ", ".join(vals) if len(vals) <= 6 else f"{', '.join(vals[:3])}, ... {vals[-1]}"
            tag = " drawn" if a["drawn"] else ""
            parts.append(f"{a['axis']} ({len(vals)}{tag}): {shown}")
        table.add_row(row["campaign"], row["scenario"], f"{row['episodes']:,}", "\n".join(parts))
    console.print(table)
    if not rows:
        console.print(f"{params}: no campaigns")


def _remaps(items: list[str]) -> dict[str, str]:
    """``ROLE=/name`` options -> {role: topic}."""
    from pipeline.errors import RecordingError
    from pipeline.log.reader import ROLES

    remaps: dict[str, str] = {}
    for item in items:
        role, sep, name = item.partition("=")
        if not sep or not name.startswith("/") or role not in ROLES:
            raise RecordingError(
                f"--topic {item}: expected ROLE=/topic with ROLE one of {', '.join(ROLES)}"
            )
        remaps[role] = name
    return remaps


def _labels(items: list[str]) -> dict[str, str]:
    """``--label BAG=CONTROLLER`` items as a dict (a one-line error for a bad one)."""
    out: dict[str, str] = {}
    for item in items:
        bag, sep, controller = item.partition("=")
        if not sep or not bag.strip() or not controller.strip():
            raise PipelineError(f"--label {item}: expected BAG=CONTROLLER")
        out[bag.strip().removesuffix(".mcap")] = controller.strip()
    return out


@app.command("report")
def report_cmd(
    recordings: Annotated[
        str, typer.Option("--recordings", help="Folder of recordings (rosbag2 folders / .mcap).")
    ] = "recordings",
    out: Annotated[
        str, typer.Option("--out", "-o", help="Folder that receives report.md, metrics.json, .rrd.")
    ] = "reports",
    baseline: Annotated[
        str, typer.Option("--baseline", help="Controller the others are compared against.")
    ] = "pid",
    skip_bad: Annotated[
        bool,
        typer.Option("--skip-bad", help="Skip unreadable recordings (listed in the report)."),
    ] = False,
    topic: Annotated[
        list[str] | None,
        typer.Option(
            "--topic",
            help="ROLE=/name: the topic serving a role (joint_states, controller_state, "
            "planned_trajectory, robot_description, ground_truth) when it is neither ours "
            "nor the only one of its message type. Repeatable.",
        ),
    ] = None,
    controller: Annotated[
        str | None,
        typer.Option(
            "--controller",
            help="Controller label for bags without our metadata (default: the bag's name).",
        ),
    ] = None,
    label: Annotated[
        list[str] | None,
        typer.Option(
            "--label",
            help="BAG=CONTROLLER: the controller label of one bag (its folder or .mcap "
            "name), before --controller; bags with different labels are different "
            "controllers. Repeatable.",
        ),
    ] = None,
    scenario: Annotated[
        str | None,
        typer.Option(
            "--scenario",
            help="Scenario label for bags without our metadata (default: 'external').",
        ),
    ] = None,
    tool_offset: Annotated[
        str | None,
        typer.Option(
            "--tool-offset",
            help="The tool centre point of the task-space metrics in the flange frame: "
            "x,y,z [m] or x,y,z,roll,pitch,yaw [m, rad] (default: the flange).",
        ),
    ] = None,
    salvage: Annotated[
        bool,
        typer.Option(
            "--salvage",
            help="Read a truncated or damaged bag up to the damage (every intact MCAP "
            "chunk, a .db3's message rows before the first unreadable one); its status "
            "reads 'ok (salvaged: N % lost)' and, cut before the motion end, it is not "
            "compared. Default: refuse it.",
        ),
    ] = False,
) -> None:
    """Read every recording and write OUT/report.md (+ figures), metrics.json, plot CSVs
    and recording.rrd (open it with `rerun OUT/recording.rrd`).

    Outputs are staged and moved into place only when all succeeded: a failed run
    leaves earlier reports untouched.

    \b
    Your own robot's bag (ROS 2 Humble or Jazzy, MCAP or sqlite3 .db3; any
    topic names):
      pipeline report --recordings my_bags/ --baseline jtc \\
        --topic controller_state=/arm_controller/controller_state \\
        --controller jtc --scenario pick
    Topics are found by message type: sensor_msgs/msg/JointState and
    control_msgs/msg/JointTrajectoryControllerState (Humble's desired/actual
    or Jazzy's reference/feedback, told apart by the schema); --topic picks
    one when a bag has several. The joints analysed are the controller's,
    picked by name from /joint_states (extra joints and other publishers are
    left out). Robot name and effort limits come from the bag's own
    /robot_description URDF (never from a built-in robot of the same name;
    without it saturation is n/a); what needs our metadata (gains, plant,
    motion start) is n/a, with the reason in the report. A damaged bag is
    refused; --salvage reads it up to the damage and marks its status.
    """
    from pathlib import Path

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from pipeline.analysis.task_space import FLANGE_TOOL, ToolOffset
    from pipeline.log.reader import ReadOptions
    from pipeline.stages.report import run_report

    tool = FLANGE_TOOL if tool_offset is None else ToolOffset.parse(tool_offset)

    progress_console = Console(stderr=True)
    with Progress(
        TextColumn("{task.description:<24}"),
        BarColumn(),
        MofNCompleteColumn(),
        console=progress_console,
        transient=True,
        # No bar when stderr is not a terminal: error lines stay alone there.
        disable=not progress_console.is_terminal,
    ) as bars:
        tasks: dict[str, Any] = {}

        def on_progress(step: str, done: int, total: int) -> None:
            if step not in tasks:
                tasks[step] = bars.add_task(step, total=total)
            bars.update(tasks[step], completed=done, total=total)

        result = run_report(
            recordings_dir=Path(recordings),
            out_dir=Path(out),
            baseline=baseline,
            skip_bad=skip_bad,
            progress=on_progress,
            options=ReadOptions(
                topics=_remaps(topic or []),
                salvage=salvage,
                controller=controller,
                scenario=scenario,
                labels=_labels(label or []),
            ),
            tool=tool,
        )
    from rich import box
    from rich.markup import escape

    # Fits 80 columns: scenario as a heading row, names fold (never "…"), numbers whole.
    table = Table(
        box=box.SIMPLE_HEAD,
        pad_edge=False,
        padding=(0, 1, 0, 0),
        caption="errors \\[rad]: max |e| and final = worst joint, RMS = mean over joints",
        caption_justify="left",
    )
    table.add_column("scenario / episode", overflow="fold")
    table.add_column("controller", overflow="fold")
    table.add_column("status", overflow="fold")
    for header in ("max |e|", "RMS", "final"):
        table.add_column(header, justify="right", no_wrap=True)
    scenario = None
    for row in result.summary.iter_rows(named=True):
        if row["scenario"] != scenario:
            scenario = row["scenario"]
            table.add_row(f"[bold]{escape(str(scenario))}[/bold]")
        cells = [row[k] for k in ("worst_max_abs_error", "mean_rms_error", "worst_final_error")]
        status = escape(str(row["status"]))
        table.add_row(
            "  " + escape(str(row["episode"])),
            escape(str(row["controller"])),
            status
            if row["status"] == "ok"
            else f"[yellow]{status}[/yellow]"
            if str(row["status"]).startswith("ok (salvaged")
            else f"[red]{status}[/red]",
            *("n/a" if c is None else f"{c:.3e}" for c in cells),
        )
    console.print(table)
    for source, problem in result.skipped:
        # The problem names the file already ("<path>: ..."); say it once.
        shown = problem if source in problem else f"{source}: {problem}"
        sys.stderr.write(f"skipped: {shown}\n")
    for episode, note in result.warnings:
        sys.stderr.write(f"warning: {episode}: {note}\n")
    console.print(
        f"wrote {len(result.files)} file(s) to {result.out_dir}/ "
        "(report.md, metrics.json, recording.rrd)"
    )
