"""The recording as read: :class:`Recording` (one episode's frames and facts), the read's
options and the window sink a long recording's read feeds.

Shared by the whole read (:mod:`pipeline.log.whole`) and the windowed one
(:mod:`pipeline.log.windowed`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline.log.topics import PAIRED_COLUMNS
from pipeline.settings import ControllerSettings, EpisodeSettings

__all__ = [
    "CONTROLLER_STATE_COLUMNS",
    "F64",
    "SAMPLE_COLUMNS",
    "STREAM_ABOVE_BYTES",
    "PlannedTrajectory",
    "ReadOptions",
    "Recording",
    "SinkError",
    "WindowSink",
    "episode_name",
]

F64 = NDArray[np.float64]

# Recordings whose storage files are larger than this in all are read in two streaming
# passes, in windows (:mod:`pipeline.log.windowed`): memory does not grow with their length.
# 64 MiB is about five minutes of one of our 1 kHz UR5 episodes.
STREAM_ABOVE_BYTES = 64 << 20

# Column names of the tidy sample frame (one row per sample and joint).
SAMPLE_COLUMNS = (
    "episode",
    "stamp_ns",
    "time_s",
    "joint",
    "position_rad",
    "velocity_rad_s",
    "effort_nm",
    "reference_position_rad",
    "reference_velocity_rad_s",
    "error_rad",
    "commanded_effort_nm",
    *PAIRED_COLUMNS,
)
# Column names of the tidy /controller_state frame (every message, at its own rate).
CONTROLLER_STATE_COLUMNS = (
    "episode",
    "stamp_ns",
    "time_s",
    "joint",
    "reference_position_rad",
    "reference_velocity_rad_s",
    "feedback_position_rad",
    "error_rad",
    "commanded_effort_nm",
    *PAIRED_COLUMNS,
)


@dataclass(frozen=True)
class ReadOptions:
    """How to read recordings we did not write.

    Attributes:
        topics: role -> topic remaps (roles: :data:`pipeline.log.topics.ROLES`), for bags
            whose topics are neither ours nor the only one of their type.
        salvage: read every intact chunk before damage instead of refusing the file.
        controller: controller label (default: our metadata, else the bag's name).
        scenario: scenario label (default: our metadata, else "external").
        labels: bag name (its folder or ``.mcap`` file name without the suffix) ->
            controller label, before ``controller``.
        stream_above_bytes: storage files larger than this in all are read in windows
            (:mod:`pipeline.log.windowed`); None: :data:`STREAM_ABOVE_BYTES`.
        window_steps: control steps per window of a windowed read (0: the default).
        joint_states_only: a recording without a controller-state topic is read from its
            joint states alone (identification: positions, velocities, efforts); its
            controller-state columns are null. The report never sets it (it needs the
            controller's reference and error).
        robot: the robot (built-in name or file) of a bag without ``/robot_description``
            (``report --robot``; :mod:`pipeline.log.robot_facts`).
        tip: the TCP's frame of a robot from a bag's description or ``robot``
            (``report --tip``): the last joint's link or a frame fixed to it.
    """

    topics: Mapping[str, str] = field(default_factory=dict)
    salvage: bool = False
    controller: str | None = None
    scenario: str | None = None
    labels: Mapping[str, str] = field(default_factory=dict)
    stream_above_bytes: int | None = None
    window_steps: int = 0
    joint_states_only: bool = False
    robot: str | None = None
    tip: str | None = None


@dataclass(frozen=True)
class PlannedTrajectory:
    """The planned trajectory as recorded on ``/planned_trajectory``.

    Attributes:
        joint_names: joint order of the arrays.
        times_s: (K,) time from start of each point [s].
        positions: (K, n) [rad]; velocities: (K, n) [rad/s] (NaN where absent).
    """

    joint_names: tuple[str, ...]
    times_s: F64
    positions: F64
    velocities: F64


@dataclass(frozen=True)
class Recording:
    """One episode read back from its recording.

    Attributes:
        source: the rosbag2 directory or bare ``.mcap`` file as found.
        mcap_path: the MCAP file actually read.
        sha256: SHA-256 of the MCAP file (hex).
        size_bytes: size of the MCAP file.
        metadata: the ``armlab.episode`` metadata record (string key/values).
        settings: ``metadata["settings"]`` under the recording contract; None when absent
            (a bag we did not write), unparseable or breaking the contract (a note says
            which): everything taken from it is then n/a.
        joint_names: joint order, as in ``/joint_states``.
        samples: tidy frame, columns :data:`SAMPLE_COLUMNS`, sorted by time then joint order:
            one row per ``/joint_states`` message and joint, with the ``/controller_state``
            of the same stamp. ``time_s`` counts from the first control-rate stamp.
        controller_states: tidy frame, columns :data:`CONTROLLER_STATE_COLUMNS`: every
            ``/controller_state`` message (its full rate, even when ``/joint_states`` is
            decimated), same order and time origin. Then the columns of the roles
            paired with it (:data:`pipeline.log.topics.PAIRED`): ``true_position_rad`` /
            ``true_velocity_rad_s`` (in both frames) are the plant's true state from
            ``/ground_truth/joint_states`` where the recording has it (simulation), else null.
        has_ground_truth: the recording carries ``/ground_truth/joint_states``.
        planned: the planned trajectory, if recorded.
        robot_description: the URDF on ``/robot_description``, if recorded.
        topic_counts: messages per topic in the file.
        decoded_messages: messages decoded into ``samples`` (both control-rate topics).
        notes: non-fatal oddities (unparseable settings, dropped samples, salvage).
        salvaged: read with ``salvage`` from a damaged file (what follows the damage is
            lost), or from one holding fewer messages than it declares.
        salvage_lost_pct: share of the recording the salvage could not read [%]: of the
            messages its ``metadata.yaml`` or MCAP Statistics record declares, else a
            ``.db3``'s rows or header-stated bytes; None when not salvaged or unknown (a
            truncated bare MCAP file declares nothing).
        armlab_metadata: the bag carries our ``armlab.episode`` metadata record; without
            it nothing (robot, limits, settings) is taken from our built-in robot files.
        decimation: 1 when the frames hold every message; k > 1 for a long recording read
            in windows, whose frames hold every k-th control step (and the last one) only,
            for figures and series: the counts, end and period below then say what the
            frames no longer tell, and metrics come from the windows (:class:`WindowSink`).
        windows: how many windows a windowed read streamed (0: read whole).
        sample_count: ``/joint_states`` messages with a controller state (the rows of an
            undecimated ``samples`` frame per joint); None: count the frame.
        controller_sample_count: ``/controller_state`` messages; None: count the frame.
        end_s: the last control-rate ``time_s`` of the recording [s], on the frames' time
            axis (from the first control-rate stamp as read; from the motion start once
            :func:`pipeline.analysis.protocol.protocol_view` cut the pre-roll); None: from
            the frames.
        control_period_s: median ``/controller_state`` period [s]; None: from the frames.
        given_robot, given_tip: :attr:`ReadOptions.robot` and :attr:`ReadOptions.tip`
            as read with (:mod:`pipeline.log.robot_facts` uses them).
        duration_contradicted: the settings' trajectory duration is contradicted by the
            data (a note says how); :attr:`trajectory_duration_s` is then
            ``data_trajectory_duration_s``, the data's (None: unknown).
    """

    source: Path
    mcap_path: Path
    sha256: str
    size_bytes: int
    metadata: dict[str, str]
    settings: EpisodeSettings | None
    joint_names: tuple[str, ...]
    samples: pl.DataFrame
    controller_states: pl.DataFrame
    planned: PlannedTrajectory | None
    robot_description: str | None
    topic_counts: dict[str, int]
    decoded_messages: int
    notes: tuple[str, ...] = ()
    has_ground_truth: bool = False
    salvaged: bool = False
    salvage_lost_pct: float | None = None
    armlab_metadata: bool = True
    decimation: int = 1
    windows: int = 0
    sample_count: int | None = None
    controller_sample_count: int | None = None
    end_s: float | None = None
    control_period_s: float | None = None
    duration_contradicted: bool = False
    data_trajectory_duration_s: float | None = None
    given_robot: str | None = None
    given_tip: str | None = None

    @property
    def episode(self) -> str:
        return episode_name(self.metadata, self.source)

    def meta(self, key: str, default: str = "n/a") -> str:
        """A metadata value, falling back to the settings field of that name (a
        controller's, scenario's or robot's name), else ``default``."""
        value = self.metadata.get(key)
        if value:
            return value
        sv: Any = getattr(self.settings, key, None) if self.settings is not None else None
        if isinstance(sv, ControllerSettings):
            sv = sv.name
        elif isinstance(sv, Mapping):
            sv = sv.get("name")
        return str(sv) if sv not in (None, "") else default

    @property
    def controller(self) -> str:
        return self.meta("controller")

    @property
    def scenario(self) -> str:
        return self.meta("scenario")

    @property
    def robot(self) -> str:
        return self.meta("robot")

    @property
    def status(self) -> str:
        """The recorded status, "ok" or "diverged"; "ok" without settings (nothing says
        otherwise)."""
        return self.settings.status if self.settings is not None else "ok"

    @property
    def reason(self) -> str:
        """Why the episode diverged ("" if ok or unknown)."""
        return self.settings.reason if self.settings is not None else ""

    @property
    def trajectory_duration_s(self) -> float | None:
        """When the reference stops, counted from the motion start [s]: the planned
        trajectory's duration (settings.planner.trajectory_duration_s, else the last planned
        point's time_from_start), None if unknown; the data's when they contradict the
        settings (:func:`pipeline.log.labels.check_trajectory_duration`). On the recording's
        own ``time_s`` axis the motion ends this much after ``protocol.motion_start_s``
        (the pre-roll), which is what
        :attr:`pipeline.settings.EpisodeSettings.motion_end_from_first_sample_s` gives."""
        if self.duration_contradicted:  # the data's (a note says why)
            return self.data_trajectory_duration_s
        if self.settings is not None:
            return self.settings.planner.trajectory_duration_s
        if self.planned is not None and self.planned.times_s.size:
            return float(self.planned.times_s[-1])
        return None


def episode_name(metadata: dict[str, str], source: Path) -> str:
    """The episode's name: our metadata's, else the recording's file or directory name."""
    return metadata.get("episode") or source.name.removesuffix(".mcap")


class SinkError(Exception):
    """Carries what a :class:`WindowSink` raised out of a windowed read, whose boundary
    would otherwise report it as a recording that cannot be decoded;
    :func:`pipeline.log.reader.read_recording` raises the sink's own exception (its
    ``__cause__``)."""


class WindowSink(Protocol):
    """Receives a long recording's exact frames, one window at a time, in time order.

    :func:`pipeline.log.reader.read_recording` calls :meth:`begin` once (after its first pass)
    with the recording as then known: empty frames, every other field set (``sample_count`` not
    yet), then :meth:`window` for each window: tidy frames of a contiguous stamp interval
    (the rows the whole read would have there). Only a windowed read calls it.
    """

    def begin(self, header: Recording) -> None: ...

    def window(self, samples: pl.DataFrame, controller_states: pl.DataFrame) -> None: ...
