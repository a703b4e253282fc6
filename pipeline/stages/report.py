"""The report stage: recordings -> metrics.json, plot CSVs, figures, report.md, recording.rrd.

Everything is written into a fresh staging folder beside ``out`` and moved into
place only when all of it succeeded, so a failed or killed run never leaves a
half-written file under a final name or destroys an earlier report.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import polars as pl

from pipeline.analysis.episodes import episode_table, limits_table
from pipeline.analysis.metrics import check_baseline, comparisons, joint_metrics
from pipeline.errors import RecordingError, ReportError
from pipeline.log.reader import Recording, find_recordings, read_recording
from pipeline.report.figures import MAX_FIGURE_SCENARIOS, FigureFile, scenario_figures
from pipeline.report.inputs import ReportData, Skipped
from pipeline.report.markdown import REPORT_FILE, render_report
from pipeline.report.metrics_json import write_metrics, write_series_csvs
from pipeline.report.rerun_rrd import RRD_FILE, write_rrd

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
    """

    out_dir: Path
    files: tuple[str, ...]
    summary: pl.DataFrame
    skipped: tuple[tuple[str, str], ...]
    decoded_messages: int


def _noop(step: str, done: int, total: int) -> None:
    del step, done, total


def read_all(
    recordings_dir: Path, *, skip_bad: bool, progress: Progress = _noop
) -> tuple[list[Recording], list[tuple[str, str]]]:
    """Read every recording under ``recordings_dir``.

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
    for k, source in enumerate(sources):
        progress("reading recordings", k, len(sources))
        try:
            good.append(read_recording(source))
        except RecordingError as err:
            if not skip_bad:
                raise RecordingError(f"{err} (use --skip-bad to report without it)") from err
            bad.append((str(source), str(err)))
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


def _commit(staging: Path, out_dir: Path, names: list[str]) -> None:
    """Move staged outputs into ``out_dir``: files replaced atomically, folders swapped."""
    out_dir.mkdir(parents=True, exist_ok=True)
    trash = staging / ".previous"
    trash.mkdir()
    for name in names:
        src, dst = staging / name, out_dir / name
        if src.is_dir():
            if dst.exists():
                os.replace(dst, trash / name)
            os.replace(src, dst)
        else:
            os.replace(src, dst)


def run_report(
    *,
    recordings_dir: Path,
    out_dir: Path,
    baseline: str = "pid",
    skip_bad: bool = False,
    progress: Progress = _noop,
) -> ReportResult:
    """Read the recordings, compute metrics and write every report output.

    Raises:
        ReportError / RecordingError: see :func:`read_all`; unknown baseline controller.
    """
    recordings, bad = read_all(recordings_dir, skip_bad=skip_bad, progress=progress)
    episodes = episode_table(recordings)
    check_baseline(episodes, baseline)
    samples = pl.concat([r.samples for r in recordings], how="vertical")
    metrics = joint_metrics(samples, episodes, limits_table(recordings))
    data = ReportData(
        recordings=tuple(recordings),
        episodes=episodes,
        metrics=metrics,
        comparisons=comparisons(metrics, episodes, baseline=baseline),
        baseline=baseline,
        skipped=tuple(Skipped(s, p) for s, p in bad),
        recordings_dir=recordings_dir,
    )
    out_dir = Path(out_dir)
    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=out_dir.parent))
    except OSError as err:
        raise ReportError(f"{out_dir.parent}: cannot write the report there ({err})") from err
    try:
        files = [write_metrics(data, staging), *write_series_csvs(data, staging)]
        scenarios = data.scenarios()
        drawn = scenarios[:MAX_FIGURE_SCENARIOS]
        figures: dict[str, list[FigureFile]] = {}
        for k, scenario in enumerate(drawn):
            progress("drawing figures", k, len(drawn))
            figures[scenario] = scenario_figures(data, scenario, staging)
        progress("drawing figures", len(drawn), len(drawn))
        files += [f.relpath for figs in figures.values() for f in figs]
        progress("writing recording.rrd", 0, 1)
        write_rrd(data, staging / RRD_FILE)
        files.append(RRD_FILE)
        progress("writing recording.rrd", 1, 1)
        text = render_report(data, figures, omitted_figures=scenarios[len(drawn) :])
        (staging / REPORT_FILE).write_text(text, encoding="utf-8")
        files.append(REPORT_FILE)
        top = sorted({f.split("/", 1)[0] for f in files})
        _commit(staging, out_dir, top)
    except OSError as err:
        raise ReportError(
            f"{out_dir}: writing the report failed ({err}); earlier reports are untouched"
        ) from err
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return ReportResult(
        out_dir=out_dir,
        files=tuple(files),
        summary=_summary(data),
        skipped=tuple(bad),
        decoded_messages=sum(r.decoded_messages for r in recordings),
    )


def _summary(data: ReportData) -> pl.DataFrame:
    per_episode = data.metrics.group_by("episode").agg(
        worst_max_abs_error=pl.col("max_abs_error").max(),
        mean_rms_error=pl.col("rms_error").mean(),
        worst_final_error=pl.col("final_error").max(),
    )
    return (
        data.episodes.select("episode", "scenario", "controller", "status")
        .join(per_episode, on="episode", how="left")
        .sort("scenario", "controller", "episode")
    )
