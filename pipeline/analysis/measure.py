"""Measuring a recording as it is read: its protocol view, episode row, metrics and the
thinned error series the report keeps (:class:`Measured`), what that gives per recording
(:class:`Measurement`: what a report worker sends back and a partial holds), which episodes
the report shows one by one (:func:`sample_roles`), and the per-joint arrays of a tidy frame.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline.analysis.checks import (
    Duplicates,
    duplicate_note,
    duplicate_stamp_notes,
    duplicate_stamps,
)
from pipeline.analysis.episodes import comparable, episode_table, limits_table
from pipeline.analysis.metrics import finish_metrics, joint_metrics, metric_partials
from pipeline.analysis.protocol import (
    Protocol,
    ProtocolView,
    protocol_of,
    protocol_view,
    start_state,
)
from pipeline.analysis.task_space import FLANGE_TOOL, TaskSpace, ToolOffset, task_space_of
from pipeline.constants import TOPIC_CONTROLLER_STATE, TOPIC_JOINT_STATES
from pipeline.errors import RecordingError
from pipeline.log.reader import ReadOptions, Recording, read_recording

# A (group, controller) with at most this many episodes is shown whole in the .rrd and the
# plot CSVs; a larger one by its labelled sample (median and worst episode).
SHOW_ALL_UP_TO = 3


def sample_roles(metrics: pl.DataFrame, episodes: pl.DataFrame) -> dict[str, str]:
    """:attr:`ReportData.sample_roles` from the metric frame and the episode table alone
    (a campaign run uses it on its partials to know which episodes the report shows)."""
    worst = metrics.group_by("episode").agg(score=pl.col("max_abs_error").max())
    eps = episodes.join(worst, on="episode", how="left").sort("episode")
    key = "group" if "group" in eps.columns else "scenario"
    roles: dict[str, str] = {}
    for _, grp in eps.group_by(key, "controller", maintain_order=True):
        if grp.height <= SHOW_ALL_UP_TO:
            roles.update(dict.fromkeys(grp["episode"].to_list(), ""))
            continue
        # a salvaged episode cut before its motion end is neither a median nor a worst run
        ok = grp.filter(comparable(grp) & pl.col("score").is_not_null())
        ok = ok.sort("score", "episode")
        if ok.height:
            roles[ok["episode"][(ok.height - 1) // 2]] = "median"
            roles[ok["episode"][-1]] = "worst"
        failed = grp.filter(pl.col("status") != "ok")
        if failed.height:
            roles[failed["episode"][0]] = "failed"
    return roles


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


@dataclass(frozen=True)
class Measurement:
    """What the report keeps of one recording once it is measured (what a report worker
    sends back, and what a partial holds).

    Attributes:
        recording: the recording as kept (a campaign episode's frames let go: settings,
            notes, counts).
        view: its protocol view (``view.recording`` is ``recording``).
        row: its row of :func:`pipeline.analysis.episodes.episode_table`.
        metrics: its rows of :func:`pipeline.analysis.metrics.joint_metrics`.
        errors: the thinned error series (times [s], errors [rad]) of a campaign episode,
            for the .rrd's bands; else None.
        task_space: episode -> its FK model (empty when the bag has no robot model).
    """

    recording: Recording
    view: ProtocolView
    row: pl.DataFrame
    metrics: pl.DataFrame
    errors: tuple[NDArray[np.float64], NDArray[np.float64]] | None
    task_space: dict[str, TaskSpace]


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
