# long: the report stage and how it measures each recording as read (Measured, also for partials)
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
from typing import TYPE_CHECKING, Any

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline.analysis.campaign import TABLE_DIR, campaign_tables
from pipeline.analysis.checks import (
    Duplicates,
    duplicate_note,
    duplicate_stamp_notes,
    duplicate_stamps,
    merged_label_notes,
)
from pipeline.analysis.episodes import episode_table, limits_table, shown_status
from pipeline.analysis.metrics import (
    check_baseline,
    comparisons,
    finish_metrics,
    joint_metrics,
    metric_partials,
)
from pipeline.analysis.protocol import (
    Protocol,
    ProtocolView,
    protocol_of,
    protocol_view,
    start_state,
)
from pipeline.analysis.task_space import FLANGE_TOOL, TaskSpace, ToolOffset, task_space_of
from pipeline.constants import TOPIC_CONTROLLER_STATE, TOPIC_JOINT_STATES
from pipeline.errors import PipelineError, RecordingError, ReportError
from pipeline.fsutil import OutputLock, check_out_dir, remove_stale
from pipeline.log.reader import (
    ReadOptions,
    Recording,
    WindowSink,
    find_recordings,
    read_recording,
)
from pipeline.report.inputs import ReportData, Skipped, cs_times_s, cs_wide
from pipeline.stages.partials import (
    Measurement,
    Partial,
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
    from pipeline.report.campaigns import CampaignSection
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
    recordings = measured.with_partials(recordings, recordings_dir)
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
    data = measured.with_sample_frames(first, options)
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


# Thinned error series kept per campaign episode for the .rrd's percentile bands.
BAND_POINTS = 250


class _Streamed:
    """A long recording's windows as they are read: the protocol applied to each, their
    partial metrics, counts and duplicate stamps, and the exact state at the motion start."""

    def __init__(self, header: Recording, tool: ToolOffset) -> None:
        self.protocol: Protocol = protocol_of(header)[0]
        self.task_space = task_space_of(header, tool)
        view, _ = protocol_view(header)
        # the episode row as far as the metrics need it (motion end, end, completed)
        self.row = episode_table([view.recording], {header.episode: view})
        self.limits = limits_table([header])
        self.joints = max(len(header.joint_names), 1)
        self.partials: list[pl.DataFrame] = []
        self.counts = [0, 0]
        self.start: list[float | None] = [None, None]
        self.started = [False, False]
        self.duplicates: dict[str, Duplicates] = {}
        self.empty = self.protocol.frames(header.samples, header.controller_states)

    def window(self, samples: pl.DataFrame, controller_states: pl.DataFrame) -> None:
        js, cs = self.protocol.frames(samples, controller_states)
        first = start_state(js, cs)
        for k, (frame, value) in enumerate(((cs, first[0]), (js, first[1]))):
            if frame.height and not self.started[k]:
                self.started[k], self.start[k] = True, value
        self.counts[0] += js.height // self.joints
        self.counts[1] += cs.height // self.joints
        for topic, frame in ((TOPIC_JOINT_STATES, js), (TOPIC_CONTROLLER_STATE, cs)):
            dup = duplicate_stamps(frame)
            if dup is not None:
                old = self.duplicates.get(topic)
                self.duplicates[topic] = dup if old is None else old + dup
        if js.height or cs.height:
            self.partials.append(
                metric_partials(js, cs, self.row, self.limits, task_space=self.task_space)
            )

    def view(self, raw: Recording) -> tuple[ProtocolView, pl.DataFrame]:
        """The recording's view (decimated frames, exact counts and start state) and its
        metrics over every window."""
        view, _ = protocol_view(
            raw, start=(self.start[0], self.start[1]), counts=(self.counts[0], self.counts[1])
        )
        rec = view.recording
        span = rec.end_s + view.motion_start_s if rec.end_s is not None else 0.0
        length = f"{span / 3600:.3g}-hour" if span >= 3600 else f"{span / 60:.3g}-minute"
        topics = (TOPIC_JOINT_STATES, TOPIC_CONTROLLER_STATE)
        notes = [duplicate_note(t, self.duplicates[t]) for t in topics if t in self.duplicates]
        notes.append(
            f"{length} recording: metrics over all {self.counts[1]:,} controller-state and "
            f"{self.counts[0]:,} joint-state samples, streamed in {rec.windows} windows; "
            f"figures, series CSVs and the .rrd show every {rec.decimation}-th sample"
        )
        view = dataclasses.replace(
            view, recording=dataclasses.replace(rec, notes=(*rec.notes, *notes))
        )
        # nothing after the motion start: the metrics of empty frames, as a whole read has
        parts = self.partials or [
            metric_partials(*self.empty, self.row, self.limits, task_space=self.task_space)
        ]
        return view, finish_metrics(pl.concat(parts, how="vertical_relaxed"))


class Measured:
    """What the report keeps of each recording as it is read: its protocol view, episode
    row and metrics; a campaign episode's frames are let go (only a bounded sample of
    them is drawn, re-read afterwards) after keeping a thinned error series.

    It is also the reader's :class:`WindowSink`: a long recording's metrics are computed
    window by window as it is read (:class:`_Streamed`); its frames are decimated."""

    def __init__(self, tool: ToolOffset = FLANGE_TOOL) -> None:
        self.tool = tool
        self.task_space: dict[str, TaskSpace] = {}
        self.views: dict[str, ProtocolView] = {}
        self.rows: dict[str, pl.DataFrame] = {}
        self.metrics: dict[str, pl.DataFrame] = {}
        self.errors: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
        self.streamed: _Streamed | None = None
        self.bagless: set[str] = set()  # measured from their partials (keep_bags)

    def with_partials(self, recordings: list[Recording], recordings_dir: Path) -> list[Recording]:
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
            if p.tool != self.tool:
                raise ReportError(
                    f"{path}: measured with the TCP at {p.tool}, not at --tool {self.tool}; "
                    "report without --tool, or re-run the campaign with full bags"
                )
            have.add(episode)
            self.bagless.add(episode)
            out.append(self.merge(p))
        return sorted(out, key=lambda r: r.episode)

    def begin(self, header: Recording) -> None:
        self.streamed = _Streamed(header, self.tool)

    def window(self, samples: pl.DataFrame, controller_states: pl.DataFrame) -> None:
        assert self.streamed is not None
        self.streamed.window(samples, controller_states)

    def add(self, raw: Recording) -> Recording:
        streamed, self.streamed = self.streamed, None
        self.task_space.update(task_space_of(raw, self.tool))
        if raw.windows:
            assert streamed is not None
            view, metrics = streamed.view(raw)
            rec = view.recording
            row = episode_table([rec], {rec.episode: view})
        else:
            view, _ = protocol_view(raw)
            rec = view.recording
            row = episode_table([rec], {rec.episode: view})
            metrics = joint_metrics(
                rec.samples,
                rec.controller_states,
                row,
                limits_table([rec]),
                task_space=self.task_space,
            )
        self.rows[rec.episode] = row
        self.metrics[rec.episode] = metrics
        if view.settings is not None and view.settings.campaign is not None:
            t = cs_times_s(rec)
            step = max(1, int(np.ceil(t.size / BAND_POINTS)))
            self.errors[rec.episode] = (t[::step], cs_wide(rec, "error_rad")[::step])
            rec = dataclasses.replace(
                rec,
                samples=rec.samples.clear(),
                controller_states=rec.controller_states.clear(),
                notes=(*rec.notes, *duplicate_stamp_notes(rec)),
            )
            view = dataclasses.replace(view, recording=rec)
        self.views[rec.episode] = view
        return rec

    def measure(self, source: Path, options: ReadOptions | None) -> tuple[str, Any]:
        """Read and measure one recording and hand its measurement over (this object
        keeps nothing of it): ("ok", :class:`Measurement`), or ("bad", the text of the
        :class:`RecordingError` that refused it). What a report worker does per recording.
        """
        try:
            raw = read_recording(source, options, sink=self)
        except RecordingError as err:
            self.streamed = None
            return ("bad", str(err))
        return ("ok", self.take(self.add(raw).episode))

    def take(self, episode: str) -> Measurement:
        """Hand over what this object keeps of ``episode`` (measured by :meth:`add`); it
        keeps nothing of it after."""
        view = self.views.pop(episode)
        task_space = self.task_space.pop(episode, None)
        return Measurement(
            recording=view.recording,
            view=view,
            row=self.rows.pop(episode),
            metrics=self.metrics.pop(episode),
            errors=self.errors.pop(episode, None),
            task_space={} if task_space is None else {episode: task_space},
        )

    def merge(self, m: Measurement) -> Recording:
        """Keep ``m`` (measured elsewhere, or a partial read back) as :meth:`add` would
        have kept it; returns its recording."""
        episode = m.recording.episode
        self.task_space.update(m.task_space)
        self.rows[episode] = m.row
        self.metrics[episode] = m.metrics
        if m.errors is not None:
            self.errors[episode] = m.errors
        self.views[episode] = m.view
        return m.recording

    def with_sample_frames(self, data: ReportData, options: ReadOptions | None) -> ReportData:
        """``data`` with the frames of the sampled campaign episodes read back."""
        recordings = list(data.recordings)
        for k, rec in enumerate(recordings):
            if (
                rec.episode in data.sample_roles
                and rec.episode in self.errors
                and rec.episode not in self.bagless
            ):
                raw = read_recording(rec.source, options)
                if raw.windows:  # as measured from its windows, with the notes they gave
                    was = self.views[rec.episode]
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
                self.views[rec.episode] = view
                recordings[k] = view.recording
        return dataclasses.replace(data, recordings=tuple(recordings), protocol=self.views)


_Measured = Measured  # the former name (benches, tests)


def measure_bag(
    bag_dir: Path, *, tool: ToolOffset = FLANGE_TOOL, measure_code: str | None = None
) -> Partial:
    """Read a bag and measure it exactly as ``pipeline report`` does: its partial
    (:mod:`pipeline.stages.partials`).

    Raises:
        RecordingError: the bag cannot be read.
    """
    measured = Measured(tool)
    rec = measured.add(read_recording(bag_dir, None, sink=measured))
    return _partial(measured, rec, bag_dir.name, tool, measure_code)


def measure_recording(
    rec: Recording, *, tool: ToolOffset = FLANGE_TOOL, measure_code: str | None = None
) -> Partial:
    """Measure a recording read whole (or made in memory as its bag would read back:
    :func:`pipeline.log.whole.episode_recording`) exactly as ``pipeline report`` does."""
    measured = Measured(tool)
    return _partial(measured, measured.add(rec), rec.source.name, tool, measure_code)


def _partial(
    measured: Measured, rec: Recording, bag: str, tool: ToolOffset, measure_code: str | None
) -> Partial:
    return Partial.of(
        measured.take(rec.episode),
        measure_code=measure_commit() if measure_code is None else measure_code,
        bag=bag,
        tool=tool,
    )


def _campaigns(
    data: ReportData, staging: Path, progress: Progress, *, bagless: set[str] | None = None
) -> list[CampaignSection]:
    """Write each campaign's table (Parquet), then its section, read back from the table
    with a lazy scan: the summary is the table's numbers. A campaign some of whose
    episodes were measured from their partials (``bagless``) also lists which episodes
    have bags (``<stem>.bags.csv``)."""
    from pipeline.report.campaigns import campaign_section
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
