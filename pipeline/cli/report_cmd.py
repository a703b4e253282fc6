"""``pipeline report``: read recordings, compare controllers, write the report."""

from __future__ import annotations

import sys
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from pipeline.cli.root import app, console
from pipeline.constants import ERROR_FORMAT
from pipeline.errors import PipelineError

# pipeline.log.topics.ROLES, written here by `make sync` (importing it would load the bag
# code on every `pipeline` command)
READER_ROLES = (
    # begin generated: reader roles (make sync)
    "joint_states, controller_state, planned_trajectory, robot_description, ground_truth"
    # end generated: reader roles
)


def _labels(items: list[str]) -> dict[str, str]:
    """``--label BAG=CONTROLLER`` items as a dict (a one-line error for a bad one)."""
    out: dict[str, str] = {}
    for item in items:
        bag, sep, controller = item.partition("=")
        if not sep or not bag.strip() or not controller.strip():
            raise PipelineError(f"--label {item}: expected BAG=CONTROLLER")
        out[bag.strip().removesuffix(".mcap")] = controller.strip()
    return out


def topic_remaps(items: list[str]) -> dict[str, str]:
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
            help=f"ROLE=/name: the topic serving a role ({READER_ROLES}) when it is neither "
            "ours nor the only one of its message type. Repeatable.",
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
            "x,y,z \\[m] or x,y,z,roll,pitch,yaw \\[m, rad] (default: the flange).",
        ),
    ] = None,
    robot: Annotated[
        str | None,
        typer.Option(
            "--robot",
            help="The robot (built-in name or file: URDF, MJCF, DH YAML, sidecar) of bags "
            "without /robot_description, for the task-space (TCP) metrics; its joints must "
            "be the bag's. A bag with its own description keeps it.",
        ),
    ] = None,
    tip: Annotated[
        str | None,
        typer.Option(
            "--tip",
            help="The flange frame of the TCP for a robot from a bag's /robot_description "
            "or --robot: the last joint's link or a frame fixed to it (default: tool0 where "
            "the robot has one, else the last link).",
        ),
    ] = None,
    jobs: Annotated[
        int | None,
        typer.Option(
            "--jobs",
            "-j",
            min=1,
            help="Worker processes that read and measure the recordings (default: one per "
            "CPU when there are many recordings, else none). The outputs do not depend on it.",
        ),
    ] = None,
    salvage: Annotated[
        bool,
        typer.Option(
            "--salvage",
            help="Read a truncated or damaged bag up to the damage (every intact MCAP "
            "chunk, a .db3's message rows before the first unreadable one), or one holding "
            "fewer messages than its metadata.yaml or Statistics record declares; its "
            "status reads 'ok (salvaged: N % lost)', N % of the messages it declares, and, "
            "cut before the motion end, it is not compared. Default: refuse it.",
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
    without it saturation is n/a; --robot gives the robot of a bag without one,
    --tip its flange frame); what needs our metadata (gains, plant,
    motion start) is n/a, with the reason in the report. A damaged bag is
    refused; --salvage reads it up to the damage and marks its status.
    """
    from pathlib import Path

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from pipeline.analysis.task_space import FLANGE_TOOL, ToolOffset
    from pipeline.fsutil import check_out_dir
    from pipeline.log.reader import ReadOptions
    from pipeline.stages.report import run_report

    check_out_dir(out)  # "" is the working folder to Path; say what was given
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
                topics=topic_remaps(topic or []),
                salvage=salvage,
                controller=controller,
                scenario=scenario,
                labels=_labels(label or []),
                robot=robot,
                tip=tip,
            ),
            tool=tool,
            jobs=jobs,
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
            *("n/a" if c is None else format(c, ERROR_FORMAT) for c in cells),
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


@app.command("layouts")
def layouts_cmd(
    bag: Annotated[
        str, typer.Option("--bag", help="A recording (rosbag2 folder or .mcap), ours or not.")
    ],
    out: Annotated[
        str, typer.Option("--out", "-o", help="Folder for foxglove.json and plotjuggler.xml.")
    ],
    topic: Annotated[
        list[str] | None,
        typer.Option(
            "--topic", help="ROLE=/name: the topic serving a role, as for `report`. Repeatable."
        ),
    ] = None,
) -> None:
    """Write the Foxglove and PlotJuggler layouts for one bag: a tab per joint of the bag
    (its names, in its order), the plots of the topics it has (a plot on a topic it lacks,
    such as a real robot's /ground_truth/joint_states, is left out and named)."""
    from pathlib import Path

    from pipeline.errors import RecordingError
    from pipeline.log.layouts import bag_plots, write_layouts
    from pipeline.log.reader import ReadOptions, read_recording

    remaps = topic_remaps(topic or [])
    rec = read_recording(Path(bag), ReadOptions(topics=remaps))
    plots, missing = bag_plots(rec.topic_counts, remaps)
    if not plots:
        raise RecordingError(f"{bag}: none of the layouts' topics is in the bag")
    for written in write_layouts(Path(out), rec.joint_names, plots):
        console.print(str(written), highlight=False, soft_wrap=True)
    if missing:
        console.print(
            f"left out (not in the bag; name a role's topic with --topic ROLE=/name): "
            f"{', '.join(missing)}",
            highlight=False,
            soft_wrap=True,
        )
