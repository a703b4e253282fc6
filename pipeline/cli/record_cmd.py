"""``pipeline record`` and ``pipeline campaigns``: plan, simulate and record episodes and
campaigns, and list the campaigns of a params file."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Annotated, Any, Literal

import typer
from rich.console import Console
from rich.table import Table

from pipeline.cli.root import app, console, print_json
from pipeline.constants import ERROR_FORMAT
from pipeline.errors import (
    PipelineError,
)

if TYPE_CHECKING:
    from pipeline.params import Episode


def check_params(params: str) -> None:
    """What ``record`` refuses before any work, for every hand-listed episode and every
    campaign of the DVC stages (``extra_campaigns`` are left to their own runs).

    DVC deletes a stage's outputs before running its command, so a mistyped
    ``dvc exp run -S`` value used to cost the committed recording; the ``check-params``
    stage, which every record stage depends on, fails first and DVC stops there.

    Raises:
        PipelineError: the first bad value (one line naming the field).
    """
    from pathlib import Path

    from pipeline.params import load_params
    from pipeline.stages.campaign_expand import expand
    from pipeline.stages.campaign_run import check_campaign_count, distinct_settings
    from pipeline.stages.record import validate_episodes

    loaded = load_params(params)
    validate_episodes(loaded, distinct_settings(loaded.episodes))
    for name in loaded.campaigns:
        if name in loaded.extra_campaigns:
            continue
        check_campaign_count(loaded, name, out=Path("recordings"), jobs=1)
        validate_episodes(loaded, distinct_settings(expand(loaded, name)))


@app.command("record")
def record_cmd(
    params: Annotated[
        str, typer.Option("--params", help="Scenarios, controllers and episodes (YAML).")
    ] = "params.yaml",
    out: Annotated[
        str | None,
        typer.Option(
            "--out",
            "-o",
            help="Directory that receives one ROS 2 bag per episode. Default: recordings "
            "(a campaign of PARAMS' extra_campaigns, outside the DVC stages: extra).",
        ),
    ] = None,
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
    episode: Annotated[
        list[str] | None,
        typer.Option(
            "--episode",
            help="With --campaign: run only this episode key (repeatable) into its full bag, "
            "e.g. one a `keep_bags` campaign kept as metric partials (the same bytes).",
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
    plugin_call_budget_s: Annotated[
        float | None,
        typer.Option(
            "--plugin-call-budget-s",
            help="Wall-clock budget of one call of a plug-in controller (import, __init__, "
            "reset, compute) \\[s]; past it the episode fails. Default: 1 "
            "(or $ARMLAB_PLUGIN_CALL_BUDGET_S).",
        ),
    ] = None,
    plugin_episode_budget_s: Annotated[
        float | None,
        typer.Option(
            "--plugin-episode-budget-s",
            help="Wall-clock budget of one episode with a plug-in controller (its import to its "
            "last call, the simulation included) \\[s]. "
            "Default: 600 (or $ARMLAB_PLUGIN_EPISODE_BUDGET_S).",
        ),
    ] = None,
    check: Annotated[
        bool,
        typer.Option(
            "--check",
            help="Only validate PARAMS (every hand-listed episode and DVC campaign, as a "
            "record does before any work), print 'params valid' and exit: the DVC stage "
            "check-params, run before DVC removes any recording.",
        ),
    ] = False,
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

    A params file runs code: a controller `type: package.module:Object` (also through
    `dvc exp run -S`) imports that module, which runs its top-level code with your rights,
    before anything is checked. Plug-in controllers (entry points and module:Object) run in a
    worker process even at -j 1, on read-only inputs, within time budgets
    (--plugin-call-budget-s, --plugin-episode-budget-s; imports 30 s): a plug-in
    that raises, exits, overruns or returns a non-finite or wrong-shaped torque fails its
    episode in one line; the others go on.
    """
    from pathlib import Path

    from pipeline.control.contain import set_budget_env

    set_budget_env(call_s=plugin_call_budget_s, episode_s=plugin_episode_budget_s)

    if check:
        check_params(params)
        console.print("params valid", markup=False, highlight=False)
        return
    if ros_distro is not None:
        _ros_distro(ros_distro)  # refused before any work
    from pipeline.stages.executors import EXECUTORS

    if executor not in EXECUTORS:
        raise PipelineError(f"--executor: expected {' or '.join(EXECUTORS)}, got '{executor}'")
    if address is not None and executor != "ray":
        raise PipelineError("--address: only with --executor ray")
    if campaign is not None:
        if only:
            raise PipelineError("--only: not with --campaign (a campaign runs whole)")
        _record_campaign(params, campaign, out=out, jobs=jobs, force=force,
                         executor=executor, address=address, ros_distro=ros_distro,
                         episodes=episode)  # fmt: skip
        return
    if episode:
        raise PipelineError("--episode: only with --campaign (hand-listed episodes: --only)")

    from pipeline.fsutil import OutputLock, check_out_dir
    from pipeline.params import load_params
    from pipeline.stages.record import check_outputs_free, prepare

    out = "recordings" if out is None else out
    check_out_dir(out)  # not "" nor the working folder: record removes folders in --out

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
    _warn_missing_facts(selected)
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
            format(o.max_abs_error_rad, ERROR_FORMAT),
            format(o.final_abs_error_rad, ERROR_FORMAT),
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


def _ros_distro(name: str) -> Literal["jazzy", "humble"]:
    if name not in ("jazzy", "humble"):
        from pipeline.errors import ParamsError

        raise ParamsError(f"--ros-distro: {name!r}, expected jazzy or humble")
    return "humble" if name == "humble" else "jazzy"


SUMMARY_TABLE_MAX = 30  # larger campaigns: counts and the failures, not a row per episode


def _warn_missing_facts(episodes: Sequence[Episode]) -> None:
    """Say on stderr, before any work, which facts the robots lack and what stands in."""
    from pipeline.stages.record import missing_fact_lines

    for line in missing_fact_lines(episodes):
        sys.stderr.write(f"warning: {line}\n")


class _CampaignView:
    """A campaign run on the terminal: messages on stderr (the result line on stdout) and
    one progress bar with ETA over the pending episodes."""

    def __init__(self) -> None:
        self.err = Console(stderr=True)

    def say(self, text: str, *, kind: str = "status") -> None:
        if kind == "line":
            sys.stderr.write(text + "\n")
        elif kind == "warning":
            self.err.print(text, markup=False, highlight=False)
        elif kind == "stdout":
            console.print(text)
        else:
            self.err.print(text)

    @contextlib.contextmanager
    def progress(self, run: Any) -> Iterator[Callable[[str, str, float], None]]:
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        with Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=self.err,
            disable=not self.err.is_terminal,  # no bar spam in logs (dvc repro, CI)
        ) as bars:
            task = bars.add_task(f"{run.name}", total=len(run.pending))
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

            yield on_event


def _record_campaign(
    params: str, name: str, *, out: str | None, jobs: int, force: bool, executor: str,
    address: str | None, ros_distro: str | None = None, episodes: list[str] | None = None,
) -> None:  # fmt: skip
    """``pipeline record --campaign NAME``: one progress bar with ETA over the campaign."""
    from pathlib import Path

    from pipeline.params import load_params
    from pipeline.stages.campaign_record import record_campaign

    loaded = load_params(params)
    if ros_distro is not None:
        loaded = loaded.with_ros_distro(_ros_distro(ros_distro))
    done = record_campaign(
        loaded, name, out=None if out is None else Path(out), jobs=jobs, force=force,
        executor=executor, address=address, only=episodes, view=_CampaignView(),
    )  # fmt: skip
    run, outcomes = done.run, done.outcomes
    if outcomes is None:
        return
    failed = [o for o in outcomes if o.status != "ok"]
    if len(outcomes) <= SUMMARY_TABLE_MAX:
        table = Table("episode", "status", "max |e| (rad)", "final |e| (rad)", "wall (s)")
        for o in outcomes:
            table.add_row(
                o.name, o.status if o.status == "ok" else f"[red]{o.status}[/red]",
                format(o.max_abs_error_rad, ERROR_FORMAT),
                format(o.final_abs_error_rad, ERROR_FORMAT), f"{o.wall_s:.2f}",
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
    """List the campaigns in PARAMS: size, base scenario, and what each sweeps (those
    under extra_campaigns are not DVC stages: `make demo` does not run them)."""
    from pipeline.params import load_params
    from pipeline.stages.campaign_expand import campaign_axes

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
                     "axes": axes, "extra": name in loaded.extra_campaigns})  # fmt: skip
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
        shown_name = row["campaign"] + ("\n(extra: no DVC stage)" if row["extra"] else "")
        table.add_row(shown_name, row["scenario"], f"{row['episodes']:,}", "\n".join(parts))
    console.print(table)
    if not rows:
        console.print(f"{params}: no campaigns")
