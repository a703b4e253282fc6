"""What every report writer reads: the recordings and the frames computed from them."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline.analysis.aggregate import (
    metric_aggregates,
    reduction_aggregates,
    runs_per_controller,
)
from pipeline.analysis.checks import duplicate_stamp_notes
from pipeline.analysis.protocol import ProtocolView
from pipeline.log.reader import Recording

# Matplotlib's tab10, as RGB bytes: one colour per episode within a scenario.
PALETTE: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
)


@dataclass(frozen=True)
class Skipped:
    """A recording left out with --skip-bad, and why."""

    source: str
    problem: str


@dataclass(frozen=True)
class ReportData:
    """Recordings plus the frames the report is made of.

    Attributes:
        recordings: one per episode, sorted by episode name.
        episodes: :func:`pipeline.analysis.episodes.episode_table`.
        metrics: :func:`pipeline.analysis.metrics.joint_metrics`.
        comparisons: :func:`pipeline.analysis.metrics.comparisons`.
        baseline: the baseline controller name.
        skipped: recordings that could not be read (with --skip-bad).
        recordings_dir: where the recordings were found.
        protocol: per episode, how the protocol was applied (motion start, error source,
            typed settings).
    """

    recordings: tuple[Recording, ...]
    episodes: pl.DataFrame
    metrics: pl.DataFrame
    comparisons: pl.DataFrame
    baseline: str
    skipped: tuple[Skipped, ...]
    recordings_dir: Path
    protocol: dict[str, ProtocolView] = field(default_factory=dict)

    @cached_property
    def metric_summary(self) -> pl.DataFrame:
        """:func:`pipeline.analysis.aggregate.metric_aggregates` of these episodes."""
        return metric_aggregates(self.metrics, self.episodes)

    @cached_property
    def reduction_summary(self) -> pl.DataFrame:
        """:func:`pipeline.analysis.aggregate.reduction_aggregates` of these comparisons."""
        return reduction_aggregates(self.comparisons, self.episodes)

    @cached_property
    def runs(self) -> dict[tuple[str, str], int]:
        """Completed episodes per (scenario, controller)."""
        return runs_per_controller(self.episodes)

    def repeated(self, scenario: str) -> bool:
        """Whether some controller ran this scenario more than once (e.g. several seeds)."""
        return any(n > 1 for (sc, _), n in self.runs.items() if sc == scenario)

    def warnings(self) -> list[tuple[str, str]]:
        """(episode, note) for every non-fatal oddity the reader or the frame checks noted."""
        return [
            (rec.episode, note)
            for rec in self.recordings
            for note in (*rec.notes, *duplicate_stamp_notes(rec))
        ]

    @cached_property
    def _metric_rows(self) -> dict[tuple[str, str], dict[str, Any]]:
        return {(r["episode"], r["joint"]): r for r in self.metrics.iter_rows(named=True)}

    def metric(self, episode: str, joint: str | None, column: str) -> Any:
        """One metric value (None when absent)."""
        row = self._metric_rows.get((episode, joint or ""))
        return None if row is None else row.get(column)

    def recording(self, episode: str) -> Recording:
        for rec in self.recordings:
            if rec.episode == episode:
                return rec
        raise KeyError(episode)

    def scenarios(self) -> list[str]:
        return sorted({rec.scenario for rec in self.recordings})

    def in_scenario(self, scenario: str) -> list[Recording]:
        """Episodes of a scenario, baseline controller first, then by controller and name."""
        recs = [r for r in self.recordings if r.scenario == scenario]
        return sorted(recs, key=lambda r: (r.controller != self.baseline, r.controller, r.episode))

    def color(self, episode: str) -> tuple[int, int, int]:
        rec = self.recording(episode)
        index = [r.episode for r in self.in_scenario(rec.scenario)].index(episode)
        return PALETTE[index % len(PALETTE)]

    def label(self, episode: str) -> str:
        """Legend label: the controller, plus the episode when it is not unique."""
        rec = self.recording(episode)
        same = [r for r in self.in_scenario(rec.scenario) if r.controller == rec.controller]
        return rec.controller if len(same) == 1 else f"{rec.controller} ({episode})"


def _columns(frame: pl.DataFrame, n_joints: int, column: str) -> NDArray[np.float64]:
    """(rows / n, n) array of a tidy one-row-per-joint frame's column, NaN where missing."""
    values = frame.get_column(column).to_numpy()
    return np.asarray(values, dtype=np.float64).reshape(-1, n_joints)


def _times(frame: pl.DataFrame, n_joints: int) -> NDArray[np.float64]:
    return np.asarray(frame.get_column("time_s").to_numpy()[::n_joints], dtype=np.float64)


def wide(rec: Recording, column: str) -> NDArray[np.float64]:
    """(N, n) array of one ``/joint_states`` sample column, joints in the recording's order."""
    return _columns(rec.samples, len(rec.joint_names), column)


def times_s(rec: Recording) -> NDArray[np.float64]:
    """(N,) ``/joint_states`` sample times [s]."""
    return _times(rec.samples, len(rec.joint_names))


def cs_wide(rec: Recording, column: str) -> NDArray[np.float64]:
    """(M, n) array of one ``/controller_state`` column (full rate)."""
    return _columns(rec.controller_states, len(rec.joint_names), column)


def cs_times_s(rec: Recording) -> NDArray[np.float64]:
    """(M,) ``/controller_state`` times [s]."""
    return _times(rec.controller_states, len(rec.joint_names))
