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


robots_app = typer.Typer(
    invoke_without_command=True, no_args_is_help=False, pretty_exceptions_enable=False
)
app.add_typer(robots_app, name="robots")


@robots_app.callback()
def robots_cmd(
    ctx: typer.Context,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """List the built-in robots: name, DOF, format (DH convention or URDF), dynamics given.

    `pipeline robots collision-matrix ARM.urdf --out ARM.srdf` writes a robot's
    disabled-collision pairs as an SRDF.
    """
    if ctx.invoked_subcommand is not None:
        return
    from pipeline.errors import SpecError
    from pipeline.robots import RobotSpec, builtin_robot_names, load_spec

    specs: list[RobotSpec] = []
    missing: dict[str, str] = {}
    for n in builtin_robot_names():
        try:
            specs.append(load_spec(n))
        except SpecError as err:  # a built-in URDF robot whose package is not installed
            missing[n] = str(err)
    if as_json:
        print_json(
            {
                "robots": [
                    {
                        "name": s.name,
                        "dof": s.dof,
                        "convention": s.convention,
                        "format": s.format,
                        "has_dynamics": s.has_dynamics,
                    }
                    for s in specs
                ],
                "unavailable": missing,
            }
        )
        return
    table = Table("robot", "dof", "format", "dynamics")
    for s in specs:
        form = f"DH ({s.convention})" if s.convention is not None else s.format
        table.add_row(s.name, str(s.dof), form, "yes" if s.has_dynamics else "no")
    console.print(table)
    for n, why in missing.items():
        console.print(f"{n}: unavailable: {why}", markup=False)


@robots_app.command("collision-matrix")
def collision_matrix_cmd(
    robot: Annotated[str, typer.Argument(help=ROBOT_HELP, show_default=False)],
    out: Annotated[
        str,
        typer.Option(
            "--out",
            "-o",
            help="SRDF file to write (refused if it exists, unless --force).",
            show_default=False,
        ),
    ],
    samples: Annotated[
        int,
        typer.Option(
            "--samples",
            min=1,
            max=10_000_000,
            help="Configurations sampled, uniform within the joint limits (MoveIt Setup "
            "Assistant's default density).",
        ),
    ] = 10_000,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Seed of the samples.")] = 0,
    force: Annotated[bool, typer.Option("--force", help="Overwrite --out.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Disabled-collision matrix as MoveIt's Setup Assistant computes it, written as SRDF.

    Among the links with collision geometry, a pair is disabled as Adjacent (a joint's
    parent and child; a link without geometry joins its neighbours), Default (in collision
    at the default pose: 0, or mid-range where 0 is outside the limits), Always (in
    collision in >= 95 % of the samples) or Never (in none). Collisions are MuJoCo's,
    meshes as convex hulls. Save it as ARM.srdf beside ARM.urdf and the URDF loader uses it.
    """
    from pathlib import Path

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from pipeline.planning.collision_matrix import check_out_path, collision_matrix, write_srdf
    from pipeline.robots import load_spec

    out_path = Path(out)
    check_out_path(out_path, force=force)  # before the work
    spec = load_spec(robot)
    with Progress(
        TextColumn("collision-matrix {task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        console=Console(stderr=True),
        transient=True,
        disable=as_json,
    ) as bars:
        task = bars.add_task(spec.name, total=samples)
        matrix = collision_matrix(
            spec, samples=samples, seed=seed, progress=lambda n: bars.advance(task, n)
        )
    write_srdf(matrix, out_path, force=force)
    counts = {r: matrix.count(r) for r in ("Adjacent", "Default", "Always", "Never")}
    if as_json:
        print_json(
            {
                "robot": matrix.robot,
                "srdf": str(out_path),
                "links": len(matrix.links),
                "samples": matrix.samples,
                "seed": matrix.seed,
                "disabled": counts,
                "checked_pairs": [list(p) for p in matrix.checked],
            }
        )
        return
    shown = ", ".join(f"{n} {r}" for r, n in counts.items())
    console.print(
        f"{matrix.robot}: {len(matrix.links)} links with geometry, {len(matrix.disabled)} "
        f"pairs disabled ({shown}), {len(matrix.checked)} checked; wrote {out_path}",
        markup=False,
    )


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
        return  # flange_pose names the count
    limits = zip(spec.joint_names, spec.lower.tolist(), spec.upper.tolist(), strict=True)
    for i, (q, (name, lower, upper)) in enumerate(zip(joints, limits, strict=True)):
        if not (lower <= q <= upper):  # NaN fails this too
            raise KinematicsError(
                f"joint {i + 1} ({name}): {q!r} rad is outside its limits "
                f"[{lower:.6g}, {upper:.6g}] rad"
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
    """Forward kinematics: the flange pose in the robot's base frame.

    The flange is the frame after the last controlled joint: a DH robot's ``tool0``, a URDF or
    MJCF robot's tip link (or its sidecar's ``flange:``). Visual meshes are not needed.

    Any number of joints. Prints position \\[m], quaternion (w, x, y, z) and
    roll/pitch/yaw \\[rad] with R = Rz(yaw) Ry(pitch) Rx(roll).
    """
    from pipeline.kinematics import flange_pose, pose_summary
    from pipeline.robots import load_spec

    spec = load_spec(robot)
    _check_joints(spec, joints)
    pose = pose_summary(flange_pose(spec, joints))
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
            help="Flange position X Y Z \\[m] in the robot's base frame.",
            show_default=False,
        ),
    ],
    quaternion: Annotated[
        tuple[float, float, float, float] | None,
        typer.Option(
            "--quaternion",
            help="Flange orientation as a quaternion W X Y Z (normalised here). "
            "Give this or --rpy (robots with 6 or more joints; fewer joints get "
            "position-only IK and take neither).",
            show_default=False,
        ),
    ] = None,
    rpy: Annotated[
        tuple[float, float, float] | None,
        typer.Option(
            "--rpy",
            help="Flange orientation as roll pitch yaw \\[rad], R = Rz(yaw) Ry(pitch) Rx(roll). "
            "Give this or --quaternion (robots with 6 or more joints).",
            show_default=False,
        ),
    ] = None,
    solver: Annotated[
        str,
        typer.Option(
            "--solver",
            help="IK solver: 'numeric' (Levenberg-Marquardt, any arm and joint count, one "
            "solution) or 'analytic' (closed form, UR-type arms, every solution within limits).",
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
    rest_joints: Annotated[
        str | None,
        typer.Option(
            "--rest-joints",
            help="Rest posture \\[rad], one per joint within the limits: a redundant arm "
            "(7+ joints) pulls its spare joints toward it in the null space of the pose "
            "(numeric). Default: middle of each joint's range.",
            show_default=False,
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Inverse kinematics: joint vectors \\[rad] that put the flange at the given pose.

    Any joint count. 6 joints or more: the full pose (position and orientation);
    a redundant arm (7+) also pulls its spare joints toward a rest posture
    (--rest-joints). Fewer than 6 joints cannot reach arbitrary 6-D poses: IK is
    position-only (give --position alone; the orientation follows from it).
    Every printed solution is checked by forward kinematics (errors shown).
    Exits 1 with one line if the pose is unreachable.
    """
    from rich import box
    from rich.table import Column

    from pipeline.errors import KinematicsError
    from pipeline.kinematics import (
        DEFAULT_TOL_M,
        DEFAULT_TOL_RAD,
        IKOptions,
        make_solver,
        meets_tolerance,
        pose_summary,
        position_only,
        target_pose,
        verify_solution,
    )
    from pipeline.robots import load_spec

    spec = load_spec(robot)
    only_position = position_only(spec)
    if only_position:
        if quaternion is not None or rpy is not None:
            raise KinematicsError(
                f"robot '{spec.name}' has {spec.dof} joint{'s' * (spec.dof != 1)}: its IK "
                "matches the flange "
                "position only (an orientation needs 6 joints); drop --rpy / --quaternion"
            )
        rpy = (0.0, 0.0, 0.0)  # not matched: any rotation completes the 4x4 target
    target = target_pose(position, quaternion_wxyz=quaternion, rpy_rad=rpy)
    seed = None if seed_joints is None else _joint_list(seed_joints, "--seed-joints")
    rest = None if rest_joints is None else tuple(_joint_list(rest_joints, "--rest-joints"))
    result = make_solver(solver, spec, options=IKOptions(rest_q=rest)).solve(target, seed_q=seed)
    if not result.ok:
        raise KinematicsError(result.reason)
    rows = []
    for q in result.solutions:
        pos_err, ang_err = verify_solution(spec, q, target)
        if meets_tolerance(spec, pos_err, ang_err, tol_m=DEFAULT_TOL_M, tol_rad=DEFAULT_TOL_RAD):
            rows.append(([float(v) for v in q], pos_err, ang_err))
    if not rows:
        within = f"{DEFAULT_TOL_M:g} m" + ("" if only_position else f" / {DEFAULT_TOL_RAD:g} rad")
        raise KinematicsError(
            f"robot '{spec.name}': {solver} IK returned {len(result.solutions)} solution(s) but "
            f"none reproduces the target within {within}"
        )
    if as_json:
        target_json: dict[str, Any] = (
            {"position": pose_summary(target)["position"]} if only_position
            else pose_summary(target)
        )  # fmt: skip
        print_json(
            {
                "robot": spec.name,
                "solver": solver,
                "position_only": only_position,
                "target": target_json,
                "solutions": [r[0] for r in rows],
                "position_error_m": [r[1] for r in rows],
                # a position-only robot's orientation is whatever its position implies
                "orientation_error_rad": None if only_position else [r[2] for r in rows],
            }
        )
        return
    errors = [Column("pos \\[m]", min_width=5)]
    if not only_position:
        errors.append(Column("ori \\[rad]", min_width=5))
    what = "position-only " if only_position else ""
    digits = 4 if spec.dof <= 6 else 3  # seven joints and both errors fit 80 columns
    table = Table(
        "#", *(Column(f"q{i}", justify="right", min_width=digits + 3)
               for i in range(1, spec.dof + 1)),
        *errors, title=f"{spec.name}: {len(rows)} {what}IK solution(s) \\[rad] ({solver})",
        box=box.SIMPLE, pad_edge=False, collapse_padding=True,
    )  # fmt: skip
    for i, (q, pos_err, ang_err) in enumerate(rows, start=1):
        shown = [f"{pos_err:.0e}"] + ([] if only_position else [f"{ang_err:.0e}"])
        table.add_row(str(i), *(f"{v:.{digits}f}" for v in q), *shown)
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
    < 5 ms (p99). Any joint count; below 6 joints IK is position-only and the
    orientation is not judged. Writes an error map over the workspace (PNG).
    Exits 1 on FAIL.
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
        judged = (
            ("n/a (position-only IK)", "")
            if report.position_only
            else ("< 1e-2", ok[c["orientation_error"]])
        )
        table.add_row("orientation error max / median \\[rad]",
                      f"{oe.max:.2e} / {oe.median:.2e}", *judged)  # fmt: skip
        table.add_row("solve time mean / median / p99 \\[ms]",
                      f"{st.mean:.3f} / {st.median:.3f} / {st.p99:.3f}", "p99 < 5",
                      ok[c["solve_time"]])  # fmt: skip
        console.print(table)
        verdict = "[green]PASS[/green]" if report.passed else "[red]FAIL[/red]"
        console.print(f"{verdict}; wrote {report.error_map_png} and {report.summary_json}")
    if not report.passed:
        raise typer.Exit(1)
