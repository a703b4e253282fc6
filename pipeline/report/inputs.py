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
from pipeline.analysis.consistency import MixedSetting, mixed_settings
from pipeline.analysis.measure import cs_times_s, cs_wide, sample_roles
from pipeline.analysis.protocol import ProtocolView
from pipeline.analysis.task_space import TaskSpace, tcp_errors
from pipeline.log.reader import Recording
from pipeline.report.colors import controller_colors


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
        error_series: thinned error series of the episodes whose frames were let go after
            their metrics (campaign episodes outside the sample).
        task_space: per episode, the robot's FK and the TCP (episodes without a robot
            model in the bag have none: task-space metrics n/a).
    """

    recordings: tuple[Recording, ...]
    episodes: pl.DataFrame
    metrics: pl.DataFrame
    comparisons: pl.DataFrame
    baseline: str
    skipped: tuple[Skipped, ...]
    recordings_dir: Path
    protocol: dict[str, ProtocolView] = field(default_factory=dict)
    error_series: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = field(
        default_factory=dict
    )
    task_space: dict[str, TaskSpace] = field(default_factory=dict)

    def tcp_series(self, episode: str) -> pl.DataFrame:
        """The TCP errors of an episode per ``/controller_state`` time (``time_s``,
        ``position_error_mm``, ``orientation_error_mrad``; empty without a robot model)."""
        model = self.task_space.get(episode)
        rec = self.recording(episode)
        return tcp_errors(rec.controller_states, None if model is None else {episode: model})

    def tcp_path_m(self, episode: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(times [s], (M, 3) TCP positions [m]) of the position the errors use; empty
        without a robot model."""
        model = self.task_space.get(episode)
        rec = self.recording(episode)
        t = cs_times_s(rec)
        q = cs_wide(rec, "feedback_position_rad")
        if model is None or not t.size or model.joint_names != rec.joint_names:
            return np.zeros(0), np.zeros((0, 3))
        keep = np.isfinite(q).all(axis=1)
        return t[keep], model.tcp_poses(q[keep])[:, :3, 3]

    def errors(self, episode: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(times [s], (M, n) errors) of an episode: the thinned series kept while reading
        (campaign episodes, whose frames are let go) or its ``/controller_state`` frame."""
        if episode in self.error_series:
            return self.error_series[episode]
        rec = self.recording(episode)
        return cs_times_s(rec), cs_wide(rec, "error_rad")

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
        """(episode, note) for every non-fatal oddity the reader or the frame checks noted,
        then (group, note) for each setting that differs within a group."""
        return [
            (rec.episode, note)
            for rec in self.recordings
            for note in (*rec.notes, *duplicate_stamp_notes(rec))
        ] + [
            (m.group, f"settings differ within the group: {m.note()}") for m in self.mixed_settings
        ]

    @cached_property
    def mixed_settings(self) -> list[MixedSetting]:
        """Settings recorded with more than one value within a group
        (:func:`pipeline.analysis.consistency.mixed_settings`)."""
        return mixed_settings({g: self.in_group(g) for g in self.groups()})

    @cached_property
    def _metric_rows(self) -> dict[tuple[str, str], dict[str, Any]]:
        return {(r["episode"], r["joint"]): r for r in self.metrics.iter_rows(named=True)}

    def metric(self, episode: str, joint: str | None, column: str) -> Any:
        """One metric value (None when absent)."""
        row = self._metric_rows.get((episode, joint or ""))
        return None if row is None else row.get(column)

    @cached_property
    def _by_episode(self) -> dict[str, Recording]:
        return {rec.episode: rec for rec in self.recordings}

    def recording(self, episode: str) -> Recording:
        return self._by_episode[episode]

    def controllers(self) -> list[str]:
        """Every controller in the recordings, sorted."""
        return sorted({rec.controller for rec in self.recordings})

    @property
    def compares(self) -> bool:
        """Whether the baseline ran, so reductions exist (False for one other controller)."""
        return self.baseline in self.controllers()

    @cached_property
    def campaign_of(self) -> dict[str, str | None]:
        """Episode -> its campaign (None: hand-listed)."""
        if "campaign" not in self.episodes.columns:
            return {}
        return dict(
            zip(
                self.episodes["episode"].to_list(), self.episodes["campaign"].to_list(), strict=True
            )
        )

    @cached_property
    def listed(self) -> tuple[Recording, ...]:
        """The hand-listed episodes (not part of a campaign): reported scenario by scenario."""
        return tuple(r for r in self.recordings if self.campaign_of.get(r.episode) is None)

    def campaigns(self) -> list[str]:
        """Campaign names in the recordings, sorted (summarised, not listed)."""
        return sorted({c for c in self.campaign_of.values() if c is not None})

    @cached_property
    def sample_roles(self) -> dict[str, str]:
        """The episodes shown one by one (.rrd, plot CSVs) and their role.

        Per group (scenario, or campaign/condition) and controller: every episode when
        there are at most :data:`~pipeline.analysis.measure.SHOW_ALL_UP_TO` (role ""), else
        the completed episode with the median and the one with the worst max |error| over
        joints ("median", "worst") and the first failed one ("failed"), so the outputs stay
        bounded whatever N is.
        """
        return sample_roles(self.metrics, self.episodes)

    def sample(self) -> list[Recording]:
        """The recordings of :attr:`sample_roles`, sorted by episode."""
        return [r for r in self.recordings if r.episode in self.sample_roles]

    def groups(self) -> list[str]:
        """Every group episodes are compared in (scenario, or campaign/condition), sorted."""
        return sorted(set(self.episodes.get_column("group").to_list()))

    @cached_property
    def _group_of(self) -> dict[str, str]:
        return dict(
            zip(self.episodes["episode"].to_list(), self.episodes["group"].to_list(), strict=True)
        )

    def in_group(self, group: str) -> list[Recording]:
        """Episodes of a group, baseline controller first, then by controller and name."""
        recs = [r for r in self.recordings if self._group_of.get(r.episode) == group]
        return sorted(recs, key=lambda r: (r.controller != self.baseline, r.controller, r.episode))

    def scenarios(self) -> list[str]:
        """Scenarios of the hand-listed episodes, sorted."""
        return sorted({rec.scenario for rec in self.listed})

    def in_scenario(self, scenario: str) -> list[Recording]:
        """Hand-listed episodes of a scenario, baseline controller first, then by controller
        and name."""
        recs = [r for r in self.listed if r.scenario == scenario]
        return sorted(recs, key=lambda r: (r.controller != self.baseline, r.controller, r.episode))

    @cached_property
    def _colors(self) -> dict[str, tuple[int, int, int]]:
        return controller_colors(self.controllers())

    def color(self, episode: str) -> tuple[int, int, int]:
        """The episode's controller's colour (one per controller, every output)."""
        return self._colors[self.recording(episode).controller]

    def controller_color(self, controller: str) -> tuple[int, int, int]:
        return self._colors[controller]

    def label(self, episode: str) -> str:
        """Legend label: the controller, plus the episode when it is not unique."""
        rec = self.recording(episode)
        same = [r for r in self.in_scenario(rec.scenario) if r.controller == rec.controller]
        return rec.controller if len(same) == 1 else f"{rec.controller} ({episode})"
