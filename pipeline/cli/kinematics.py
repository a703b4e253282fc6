"""``pipeline robots``, ``fk``, ``ik`` and ``ik-check``: the robots and their kinematics."""

from __future__ import annotations

from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from pipeline.cli.root import ROBOT_HELP, app, console, print_json
from pipeline.errors import PipelineError

# ik-check rounds trips one configuration at a time: a bound keeps a typo from running for days
MAX_IK_CHECK_SAMPLES = 1_000_000


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
    robot: Annotated[str, typer.Argument(help=ROBOT_HELP, show_default=False)],
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
    robot: Annotated[str, typer.Argument(help=ROBOT_HELP, show_default=False)],
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
    robot: Annotated[str, typer.Argument(help=ROBOT_HELP, show_default=False)],
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

    if samples > MAX_IK_CHECK_SAMPLES:
        raise PipelineError(
            f"--samples {samples:,}: at most {MAX_IK_CHECK_SAMPLES:,} random configurations "
            "(the error statistics settle long before)"
        )
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
