"""The report stage: recordings -> metrics.json, plot CSVs, figures, report.md, recording.rrd.

Everything is written into a fresh staging folder beside ``out``; when all of it
succeeded, the files of ``out`` that the previous report did not write (``plots/.gitignore``,
notes) are linked into it and the two folders swap names in one atomic step
(:mod:`pipeline.stages.report_commit`), so a failed or killed run never leaves a
half-written file under a final name, a mix of two reports, or a damaged earlier report.
Only files a previous report listed in its manifest are ever removed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import polars as pl

from pipeline.analysis.campaign_tables import TABLE_DIR, campaign_tables
from pipeline.analysis.checks import (
    merged_label_notes,
)
from pipeline.analysis.episodes import shown_status
from pipeline.analysis.measure import Measured
from pipeline.analysis.metrics import (
    check_baseline,
    comparisons,
)
from pipeline.analysis.protocol import (
    protocol_view,
)
from pipeline.analysis.task_space import FLANGE_TOOL, ToolOffset
from pipeline.errors import PipelineError, RecordingError, ReportError
from pipeline.fsutil import OutputLock, check_out_dir, remove_stale
from pipeline.log.reader import (
    ReadOptions,
    Recording,
    WindowSink,
    find_recordings,
    read_recording,
)
from pipeline.report.inputs import ReportData, Skipped
from pipeline.stages.partials import (
    bags_listed,
    find_partials,
    measure_commit,
    read_partial,
)
from pipeline.stages.report_commit import (
    commit,
    recover,
    remove_tree,
    staging_folder,
    staging_pattern,
)
from pipeline.stages.report_pool import default_jobs, measure_in_workers

if TYPE_CHECKING:  # the writers load when a report is written (see _writers)
    from pipeline.report.campaign_section import CampaignSection
    from pipeline.report.figures import FigureFile

# the baseline when none is named; recordings of one other controller are fine with it
DEFAULT_BASELINE = "pid"
# progress(step, done, total): called as work advances (for a progress bar).
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class ReportResult:
    """What a report run produced.

    Attributes:
        out_dir: the reports folder.
        files: written paths relative to ``out_dir``.
        summary: one row per episode (episode, scenario, controller, status,
            worst max |e|, mean RMS error, worst final error).
        skipped: (recording, problem) for recordings left out with skip_bad.
        decoded_messages: messages decoded from all recordings.
        warnings: (episode, note) for non-fatal oddities of the recordings read.
    """

    out_dir: Path
    files: tuple[str, ...]
    summary: pl.DataFrame
    skipped: tuple[tuple[str, str], ...]
    decoded_messages: int
    warnings: tuple[tuple[str, str], ...] = ()


def _noop(step: str, done: int, total: int) -> None:
    del step, done, total


def read_all(
    recordings_dir: Path,
    *,
    skip_bad: bool,
    progress: Progress = _noop,
    options: ReadOptions | None = None,
    measure: Callable[[Recording], Recording] | None = None,
    sink: WindowSink | None = None,
    measured: Measured | None = None,
    jobs: int | None = 1,
) -> tuple[list[Recording], list[tuple[str, str]]]:
    """Read every recording under ``recordings_dir`` (with ``options`` for bags we did not
    write: remaps, salvage, labels).

    ``measure``, when given, is applied to each recording as soon as it is read and its
    result kept instead (the report computes metrics there and lets go of the frames it no
    longer needs, so memory does not grow with the samples of every episode); ``sink``
    receives the windows of a long recording as it is read (:func:`read_recording`).
    ``measured`` is both (its ``add`` and itself); with it, ``jobs`` > 1 reads and measures
    on that many worker processes (:mod:`pipeline.stages.report_pool`), with the same
    result (None: :func:`~pipeline.stages.report_pool.default_jobs`).

    Raises:
        ReportError: no such folder, or nothing in it; duplicate episode names.
        RecordingError: a bad recording (unless ``skip_bad``).
    """
    if not recordings_dir.exists():
        raise ReportError(
            f"{recordings_dir}: no such directory; run `pipeline record` first to make recordings"
        )
    sources = find_recordings(recordings_dir)
    if not sources:
        raise ReportError(
            f"no recordings found in {recordings_dir} (expected rosbag2 folders or .mcap files); "
            "run `pipeline record` first"
        )
    good: list[Recording] = []
    bad: list[tuple[str, str]] = []

    def refused(source: Path, err: RecordingError) -> None:
        if not skip_bad:
            raise RecordingError(f"{err} (use --skip-bad to report without it)") from err
        bad.append((str(source), str(err)))

    if jobs is None:
        jobs = default_jobs(len(sources))
    if measured is not None and jobs > 1 and len(sources) > 1:
        progress("reading recordings", 0, len(sources))
        outcomes = measure_in_workers(
            sources,
            jobs=jobs,
            options=options,
            make=functools.partial(Measured, measured.tool),
            progress=lambda done: progress("reading recordings", done, len(sources)),
        )
        with contextlib.closing(outcomes):  # a refusal stops the workers at once
            for source, (kind, value) in outcomes:
                if kind == "raise":
                    raise value
                if kind == "bad":
                    refused(source, RecordingError(value))
                else:
                    good.append(measured.merge(value))
    else:
        if measured is not None:
            measure, sink = measured.add, measured
        for k, source in enumerate(sources):
            progress("reading recordings", k, len(sources))
            try:
                rec = read_recording(source, options, sink=sink)
            except RecordingError as err:
                refused(source, err)
                continue
            good.append(measure(rec) if measure is not None else rec)
    progress("reading recordings", len(sources), len(sources))
    if not good:
        raise ReportError(
            f"no readable recordings in {recordings_dir}: all {len(bad)} were skipped "
            f"(first: {bad[0][1]})"
        )
    seen: dict[str, Recording] = {}
    for rec in good:
        if rec.episode in seen:
            raise ReportError(
                f"episode '{rec.episode}' is recorded twice: {seen[rec.episode].source} and "
                f"{rec.source}; episode names must be unique"
            )
        seen[rec.episode] = rec
    return sorted(good, key=lambda r: r.episode), bad


CAMPAIGN_INDEX = f"{TABLE_DIR}/index.csv"


def run_report(
    *,
    recordings_dir: Path,
    out_dir: Path,
    baseline: str = DEFAULT_BASELINE,
    skip_bad: bool = False,
    progress: Progress = _noop,
    options: ReadOptions | None = None,
    tool: ToolOffset = FLANGE_TOOL,
    jobs: int | None = None,
) -> ReportResult:
    """Read the recordings, compute metrics and write every report output.

    ``tool`` places the TCP of the task-space metrics in the flange frame (default: the
    flange). ``jobs``: worker processes that read and measure the recordings (None: one
    per CPU for a large report, none for a small one:
    :func:`~pipeline.stages.report_pool.default_jobs`); the outputs do not depend on it.

    One run at a time writes a given ``out_dir`` (a second one refuses at once); staging
    folders that killed runs left beside it are removed first.

    Raises:
        ReportError / RecordingError: see :func:`read_all`; unknown baseline controller;
            another report is writing ``out_dir``.
    """
    shown = Path(out_dir)
    try:
        # resolved: the lock, staging and swap act on the real folder behind a symlink
        out_dir = check_out_dir(out_dir)
    except PipelineError as err:
        raise ReportError(str(err)) from err
    recordings_real = Path(os.path.realpath(recordings_dir))
    if recordings_real == out_dir or out_dir in recordings_real.parents:
        raise ReportError(
            f"{shown}: --out holds the recordings ({recordings_dir}); the report replaces "
            "its --out folder as a whole, so choose a folder of its own"
        )
    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ReportError(f"{out_dir.parent}: cannot write the report there ({err})") from err
    if out_dir.exists() and not out_dir.is_dir():
        raise ReportError(f"{out_dir}: --out is a file, expected a directory")
    try:
        with OutputLock(out_dir, command="`pipeline report`"):
            remove_stale(out_dir.parent, staging_pattern(out_dir))
            recover(out_dir)
            result = _run_report_locked(
                recordings_dir=recordings_dir,
                out_dir=out_dir,
                baseline=baseline,
                skip_bad=skip_bad,
                progress=progress,
                options=options,
                tool=tool,
                jobs=jobs,
            )
            return dataclasses.replace(result, out_dir=shown)
    except PipelineError as err:
        if isinstance(err, RecordingError | ReportError):
            raise
        raise ReportError(str(err)) from err


def _run_report_locked(
    *,
    recordings_dir: Path,
    out_dir: Path,
    baseline: str,
    skip_bad: bool,
    progress: Progress,
    options: ReadOptions | None,
    tool: ToolOffset,
    jobs: int | None,
) -> ReportResult:
    measured = Measured(tool)
    recordings, bad = read_all(
        recordings_dir,
        skip_bad=skip_bad,
        progress=progress,
        options=options,
        measured=measured,
        jobs=jobs,
    )
    recordings = with_partials(measured, recordings, recordings_dir)
    recordings = merged_label_notes(recordings, options)
    episodes = pl.concat([measured.rows[r.episode] for r in recordings], how="vertical")
    if not check_baseline(episodes, baseline) and baseline != DEFAULT_BASELINE:
        # one controller: nothing to compare, but a baseline the user named that is not
        # in the recordings is a typo, not a choice
        present = ", ".join(sorted(set(episodes.get_column("controller").to_list())))
        raise ReportError(
            f"--baseline '{baseline}': no such controller in the recordings (they hold "
            f"{present}); with one controller there is nothing to compare, so leave it out"
        )
    metrics = pl.concat([measured.metrics[r.episode] for r in recordings], how="vertical_relaxed")
    first = ReportData(
        recordings=tuple(recordings),
        episodes=episodes,
        metrics=metrics,
        comparisons=comparisons(metrics, episodes, baseline=baseline),
        baseline=baseline,
        skipped=tuple(Skipped(s, p) for s, p in bad),
        recordings_dir=recordings_dir,
        protocol=measured.views,
        error_series=measured.errors,
        task_space=measured.task_space,
    )
    data = with_sample_frames(measured, first, options)
    # The writers (matplotlib, Rerun) load here, not with this module: a report worker
    # imports this module to read and measure, and does not pay for them.
    from pipeline.report.figures import MAX_FIGURE_SCENARIOS, scenario_figures, scenario_slugs
    from pipeline.report.markdown import REPORT_FILE, render_report
    from pipeline.report.metrics_json import (
        write_episode_csvs,
        write_headline,
        write_metrics,
        write_series_csvs,
    )
    from pipeline.report.rerun_rrd import RRD_FILE, write_rrd

    # The name is known before the folder exists, so an interrupt at any point (even
    # inside mkdir) leaves nothing behind: the finally below removes what exists.
    staging = staging_folder(out_dir)
    try:
        try:
            staging.mkdir()
        except OSError as err:
            raise ReportError(f"{out_dir.parent}: cannot write the report there ({err})") from err
        files = [write_metrics(data, staging), write_headline(data, staging)]
        files += write_series_csvs(data, staging)
        files += write_episode_csvs(data, staging)
        sections = _campaigns(data, staging, progress, bagless=measured.bagless)
        files += [CAMPAIGN_INDEX, *[f for sec in sections for f in (sec.table_path, *sec.files)]]
        scenarios = data.scenarios()
        drawn = scenarios[:MAX_FIGURE_SCENARIOS]
        stems = scenario_slugs(scenarios)
        figures: dict[str, list[FigureFile]] = {}
        for k, scenario in enumerate(drawn):
            progress("drawing figures", k, len(drawn))
            figures[scenario] = scenario_figures(data, scenario, staging, stem=stems[scenario])
        progress("drawing figures", len(drawn), len(drawn))
        files += [f.relpath for figs in figures.values() for f in figs]
        progress("writing recording.rrd", 0, 1)
        write_rrd(data, staging / RRD_FILE)
        files.append(RRD_FILE)
        progress("writing recording.rrd", 1, 1)
        text = render_report(
            data, figures, omitted_figures=scenarios[len(drawn) :], campaigns=sections
        )
        (staging / REPORT_FILE).write_text(text, encoding="utf-8")
        files.append(REPORT_FILE)
        commit(staging, out_dir)
    except OSError as err:
        raise ReportError(
            f"{out_dir}: writing the report failed ({err}); earlier reports are untouched"
        ) from err
    finally:
        remove_tree(staging)
    return ReportResult(
        out_dir=out_dir,
        files=tuple(files),
        summary=_summary(data),
        skipped=tuple(bad),
        decoded_messages=sum(r.decoded_messages for r in recordings),
        warnings=tuple(data.warnings()),
    )


def with_partials(
    measured: Measured, recordings: list[Recording], recordings_dir: Path
) -> list[Recording]:
    """``recordings`` plus the campaign episodes kept as metric partials only (an
    episode whose bag is there too is read from its bag), sorted by episode.

    Raises:
        ReportError: a partial is unreadable or was measured with another --tool.
    """
    have = {r.episode for r in recordings}
    out = list(recordings)
    code = None
    for path in find_partials(recordings_dir):
        if path.stem in have:  # its bag was read (a partial is named by its key)
            continue
        p = read_partial(path)
        episode = p.recording.episode
        if episode in have:
            continue
        code = measure_commit() if code is None else code
        if p.measure_code != code:
            raise ReportError(
                f"{path}: measured by other report code ({p.measure_code or 'no git'}, "
                f"now {code or 'no git'}); re-run its campaign (`pipeline record "
                "--campaign`) to measure it again, or keep full bags"
            )
        if p.tool != measured.tool:
            raise ReportError(
                f"{path}: measured with the TCP at {p.tool}, not at --tool {measured.tool}; "
                "report without --tool, or re-run the campaign with full bags"
            )
        have.add(episode)
        measured.bagless.add(episode)
        out.append(measured.merge(p))
    return sorted(out, key=lambda r: r.episode)


def with_sample_frames(
    measured: Measured, data: ReportData, options: ReadOptions | None
) -> ReportData:
    """``data`` with the frames of the sampled campaign episodes read back."""
    recordings = list(data.recordings)
    for k, rec in enumerate(recordings):
        if (
            rec.episode in data.sample_roles
            and rec.episode in measured.errors
            and rec.episode not in measured.bagless
        ):
            raw = read_recording(rec.source, options)
            if raw.windows:  # as measured from its windows, with the notes they gave
                was = measured.views[rec.episode]
                view, _ = protocol_view(
                    raw,
                    start=(was.start_abs_error_rad, was.start_abs_effort_nm),
                    counts=(rec.sample_count or 0, rec.controller_sample_count or 0),
                )
                view = dataclasses.replace(
                    view, recording=dataclasses.replace(view.recording, notes=rec.notes)
                )
            else:
                view, _ = protocol_view(raw)
            measured.views[rec.episode] = view
            recordings[k] = view.recording
    return dataclasses.replace(data, recordings=tuple(recordings), protocol=measured.views)


def _campaigns(
    data: ReportData, staging: Path, progress: Progress, *, bagless: set[str] | None = None
) -> list[CampaignSection]:
    """Write each campaign's table (Parquet), then its section, read back from the table
    with a lazy scan: the summary is the table's numbers. A campaign some of whose
    episodes were measured from their partials (``bagless``) also lists which episodes
    have bags (``<stem>.bags.csv``)."""
    from pipeline.report.campaign_section import campaign_section
    from pipeline.report.figures import MAX_FIGURE_SCENARIOS, scenario_slugs

    settings = {ep: view.settings for ep, view in data.protocol.items()}
    tables = campaign_tables(data.metrics, data.episodes, settings)
    (staging / TABLE_DIR).mkdir(exist_ok=True)
    stems = scenario_slugs(tables)
    # the index is written even with no campaign, so the folder (a DVC output) always exists
    pl.DataFrame(
        {
            "campaign": list(tables),
            "episodes": [t.get_column("episode").n_unique() for t in tables.values()],
            "conditions": [t.get_column("condition").n_unique() for t in tables.values()],
            "table": [f"{TABLE_DIR}/{stems[name]}.parquet" for name in tables],
        },
        schema={
            "campaign": pl.String,
            "episodes": pl.Int64,
            "conditions": pl.Int64,
            "table": pl.String,
        },
    ).write_csv(staging / CAMPAIGN_INDEX)
    sections = []
    for k, (name, table) in enumerate(tables.items()):
        progress("summarising campaigns", k, len(tables))
        rel = f"{TABLE_DIR}/{stems[name]}.parquet"
        table.write_parquet(staging / rel)
        section = campaign_section(
            staging / rel,
            out_dir=staging,
            rel_table=rel,
            name=name,
            stem=stems[name],
            baseline=data.baseline,
            sample=data.sample_roles,
            draw=k < MAX_FIGURE_SCENARIOS,
        )
        names = table.get_column("episode").unique().sort().to_list()
        missing = [e for e in names if e in (bagless or ())]
        if missing:
            section = bags_listed(section, staging, stems[name], names, set(missing))
        sections.append(section)
    progress("summarising campaigns", len(tables), len(tables))
    return sections


def _summary(data: ReportData) -> pl.DataFrame:
    per_episode = data.metrics.group_by("episode").agg(
        worst_max_abs_error=pl.col("max_abs_error").max(),
        mean_rms_error=pl.col("rms_error").mean(),
        worst_final_error=pl.col("final_error").max(),
    )
    return (
        data.episodes.with_columns(
            pl.struct(pl.all()).map_elements(shown_status, return_dtype=pl.String).alias("status")
        )
        .select("episode", "scenario", "controller", "status")
        .join(per_episode, on="episode", how="left")
        .sort("scenario", "controller", "episode")
    )
