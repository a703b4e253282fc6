"""Read recordings (rosbag2 directories or bare ``.mcap`` files) into Polars frames.

This is the report stage's only way into a recording, so it trusts nothing: the MCAP file is
streamed and validated by :class:`pipeline.log.mcap.McapScan` (every CRC, one chunk in memory
at a time), messages are decoded through their embedded schemas
(:mod:`pipeline.log.decode`), and any failure is a :class:`RecordingError` naming the file.

Topics are found by role: the joint states (``sensor_msgs/msg/JointState``), the controller
state (``control_msgs/msg/JointTrajectoryControllerState``, Jazzy's reference/feedback or
Humble's desired/actual, detected from the schema), the planned trajectory and the robot
description. A role takes the topic named by a remap (``topics={"controller_state":
"/arm_controller/controller_state"}``), else our topic name, else the one topic of its type.
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol
from xml.etree import ElementTree

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline.constants import (
    METADATA_EPISODE,
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
    TOPIC_PLANNED_TRAJECTORY,
    TOPIC_ROBOT_DESCRIPTION,
    TYPE_CONTROLLER_STATE,
    TYPE_JOINT_STATE,
    TYPE_JOINT_TRAJECTORY,
    TYPE_STRING,
)
from pipeline.errors import RecordingError
from pipeline.log import cdr
from pipeline.log.db3 import Db3Scan, wal_copies
from pipeline.log.decode import DecodeError, Group, TopicDecoder, Want, leaf_rows
from pipeline.log.mcap import MESSAGE_PREFIX, McapChannel, McapScan, Salvage
from pipeline.log.msgdef import MsgTypes, parse_msgdef, root_type_name
from pipeline.log.rosbag2 import find_recordings, storage_files

__all__ = [
    "STREAM_ABOVE_BYTES",
    "PlannedTrajectory",
    "Recording",
    "WindowSink",
    "find_recordings",
    "read_recording",
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
    "true_position_rad",
    "true_velocity_rad_s",
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
    "true_position_rad",
    "true_velocity_rad_s",
)


@dataclass(frozen=True)
class Role:
    """What a recording's topic is for: its message type and our topic name for it.

    ``by_type``: without a remap, the one topic of this type serves when ours is absent
    (not for generic types like std_msgs/String, or for our simulation-only topics).
    """

    type: str
    default_topic: str
    by_type: bool


ROLES: dict[str, Role] = {
    "joint_states": Role(TYPE_JOINT_STATE, TOPIC_JOINT_STATES, True),
    "controller_state": Role(TYPE_CONTROLLER_STATE, TOPIC_CONTROLLER_STATE, True),
    "planned_trajectory": Role(TYPE_JOINT_TRAJECTORY, TOPIC_PLANNED_TRAJECTORY, True),
    "robot_description": Role(TYPE_STRING, TOPIC_ROBOT_DESCRIPTION, False),
    "ground_truth": Role(TYPE_JOINT_STATE, TOPIC_GROUND_TRUTH, False),
}


@dataclass(frozen=True)
class ReadOptions:
    """How to read recordings we did not write.

    Attributes:
        topics: role -> topic remaps (roles: :data:`ROLES`), for bags whose topics are
            neither ours nor the only one of their type.
        salvage: read every intact chunk before damage instead of refusing the file.
        controller: controller label (default: our metadata, else the bag's name).
        scenario: scenario label (default: our metadata, else "external").
        stream_above_bytes: storage files larger than this in all are read in windows
            (:mod:`pipeline.log.windowed`); None: :data:`STREAM_ABOVE_BYTES`.
        window_steps: control steps per window of a windowed read (0: the default).
    """

    topics: Mapping[str, str] = field(default_factory=dict)
    salvage: bool = False
    controller: str | None = None
    scenario: str | None = None
    stream_above_bytes: int | None = None
    window_steps: int = 0


# Our names of the roles' topics: never a by-type candidate for another role.
_OUR_TOPICS = frozenset(r.default_topic for r in ROLES.values())

_WANT: dict[str, Want] = {
    TYPE_JOINT_STATE: Want(
        names=("name",),
        arrays={
            "position": ("position",),
            "velocity": ("velocity",),
            "effort": ("effort",),
        },
        required=(("position",),),
    ),
    TYPE_CONTROLLER_STATE: Want(
        names=("joint_names",),
        arrays={
            "reference_position": ("reference.positions", "desired.positions"),
            "reference_velocity": ("reference.velocities", "desired.velocities"),
            "feedback_position": ("feedback.positions", "actual.positions"),
            "error": ("error.positions",),
            "commanded_effort": ("output.effort",),
        },
        required=(
            ("reference.positions", "desired.positions"),
            ("error.positions", "feedback.positions", "actual.positions"),
        ),
    ),
}


# --- public data ----------------------------------------------------------------------


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
        settings: ``metadata["settings"]`` parsed from JSON ({} if absent).
        joint_names: joint order, as in ``/joint_states``.
        samples: tidy frame, columns :data:`SAMPLE_COLUMNS`, sorted by time then joint order:
            one row per ``/joint_states`` message and joint, with the ``/controller_state``
            of the same stamp. ``time_s`` counts from the first control-rate stamp.
        controller_states: tidy frame, columns :data:`CONTROLLER_STATE_COLUMNS`: every
            ``/controller_state`` message (its full rate, even when ``/joint_states`` is
            decimated), same order and time origin. ``true_position_rad`` /
            ``true_velocity_rad_s`` (in both frames) are the plant's true state from
            ``/ground_truth/joint_states`` where the recording has it (simulation), else null.
        has_ground_truth: the recording carries ``/ground_truth/joint_states``.
        planned: the planned trajectory, if recorded.
        robot_description: the URDF on ``/robot_description``, if recorded.
        topic_counts: messages per topic in the file.
        decoded_messages: messages decoded into ``samples`` (both control-rate topics).
        notes: non-fatal oddities (unparseable settings, dropped samples, salvage).
        salvaged: read with ``salvage`` from a damaged file: what follows the damage is lost.
        salvage_lost_pct: share of the recording the salvage could not read [%] (bytes of
            an MCAP file, messages of a ``.db3``; None when not salvaged or unknown).
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
        end_s: the last control-rate ``time_s`` of the recording [s]; None: from the frames.
        control_period_s: median ``/controller_state`` period [s]; None: from the frames.
    """

    source: Path
    mcap_path: Path
    sha256: str
    size_bytes: int
    metadata: dict[str, str]
    settings: dict[str, Any]
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

    @property
    def episode(self) -> str:
        return _episode_name(self.metadata, self.source)

    def meta(self, key: str, default: str = "n/a") -> str:
        """A metadata value, falling back to settings, else ``default``."""
        value = self.metadata.get(key)
        if value:
            return value
        sv = self.settings.get(key)
        if isinstance(sv, dict):
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
        return str(self.settings.get("status") or "ok")

    @property
    def reason(self) -> str:
        return str(self.settings.get("reason") or "")

    @property
    def motion_end_s(self) -> float | None:
        """When the reference stops moving [s] from the recording's start (``time_s`` = 0):
        settings.planner.trajectory_duration_s, else the last planned point's
        time_from_start, else None."""
        planner = self.settings.get("planner")
        if isinstance(planner, dict):
            value = planner.get("trajectory_duration_s")
            # a negative duration is no motion end (the settings contract flags it)
            if isinstance(value, int | float) and np.isfinite(value) and value >= 0:
                return float(value)
        if self.planned is not None and self.planned.times_s.size:
            return float(self.planned.times_s[-1])
        return None


def _episode_name(metadata: dict[str, str], source: Path) -> str:
    return metadata.get("episode") or source.name.removesuffix(".mcap")


class _Collector:
    """Receives the messages of every storage file of a recording and decodes the roles'
    candidates (every channel of a control-rate type; first message of the others)."""

    def __init__(self, topics: Mapping[str, str]) -> None:
        self.topics = dict(topics)
        self.types: dict[str, tuple[str, MsgTypes]] = {}  # topic -> (root type, types)
        self.decoders: dict[str, TopicDecoder] = {}
        self.singles: dict[str, bytes] = {}
        self.topic_counts: dict[str, int] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.path = Path()

    def fail(self, problem: str) -> RecordingError:
        return RecordingError(f"{self.path}: {problem}")

    def type_of(self, scan: McapScan | Db3Scan, channel: McapChannel) -> tuple[str, MsgTypes]:
        if channel.topic in self.types:
            return self.types[channel.topic]
        schema = scan.schemas.get(channel.schema_id)
        if schema is None:
            raise self.fail(f"channel {channel.topic} refers to a missing schema")
        if channel.encoding != "cdr" or schema.encoding != "ros2msg":
            raise self.fail(
                f"{channel.topic} is encoded as {channel.encoding}/{schema.encoding}; "
                "expected cdr/ros2msg (a ROS 2 recording)"
            )
        try:
            parsed = (
                root_type_name(schema.name),
                parse_msgdef(schema.name, schema.data.decode("utf-8")),
            )
        except (ValueError, UnicodeDecodeError) as err:
            raise self.fail(
                f"schema {schema.name} of {channel.topic} cannot be parsed ({err})"
            ) from err
        self.types[channel.topic] = parsed
        return parsed

    def _wanted(self, topic: str, type_name: str) -> bool:
        remapped = set(self.topics.values())
        for role_name, role in ROLES.items():
            if type_name != role.type:
                continue
            if role_name in self.topics:
                if topic == self.topics[role_name]:
                    return True
            elif topic not in remapped and (
                topic == role.default_topic or (role.by_type and topic not in _OUR_TOPICS)
            ):
                return True
        return False

    def on_messages(
        self,
        scan: McapScan | Db3Scan,
        channel: McapChannel,
        buf: bytes,
        starts: NDArray[np.int64],
    ) -> None:
        schema = scan.schemas.get(channel.schema_id)
        if schema is None or not self._wanted(channel.topic, root_type_name(schema.name)):
            return
        type_name, types = self.type_of(scan, channel)
        want = _WANT.get(type_name)
        if want is None:
            if channel.topic not in self.singles:
                s = int(starts[0])
                (length,) = struct.unpack_from("<Q", buf, s - 8)
                self.singles[channel.topic] = bytes(buf[s + MESSAGE_PREFIX : s + length])
            return
        dec = self.decoders.get(channel.topic)
        if dec is None:
            dec = self.decoders[channel.topic] = TopicDecoder(channel.topic, type_name, types, want)
        try:
            dec.add(buf, starts)
        except DecodeError as err:
            raise self.fail(str(err)) from err


def _deliver(
    scan: McapScan | Db3Scan,
    collector: _Collector,
    channel: McapChannel,
    buf: bytes,
    starts: NDArray[np.int64],
) -> None:
    try:
        collector.on_messages(scan, channel, buf, starts)
    except (RecordingError, SinkError):
        raise
    except Exception as err:  # a decoder bug or an input it did not foresee
        raise RecordingError(
            f"{scan.path}: cannot decode {channel.topic}: {type(err).__name__}: {err}"
        ) from err


class _McapFile(McapScan):
    def __init__(self, path: Path, collector: _Collector, *, salvage: bool) -> None:
        super().__init__(path, salvage=salvage)
        self.collector = collector

    def on_messages(self, channel: McapChannel, buf: bytes, starts: NDArray[np.int64]) -> None:
        _deliver(self, self.collector, channel, buf, starts)


class _Db3File(Db3Scan):
    def __init__(
        self, path: Path, collector: _Collector, *, salvage: bool, copy: Path | None
    ) -> None:
        super().__init__(path, salvage=salvage, copy=copy)
        self.collector = collector

    def on_messages(self, channel: McapChannel, buf: bytes, starts: NDArray[np.int64]) -> None:
        _deliver(self, self.collector, channel, buf, starts)


def _pick(role_name: str, collector: _Collector, present: Mapping[str, str]) -> str | None:
    """The topic serving ``role_name``: the remap, our name, or the one of its type."""
    role = ROLES[role_name]
    if role_name in collector.topics:
        topic = collector.topics[role_name]
        if topic not in present:
            shown = ", ".join(sorted(present)) or "none"
            raise collector.fail(
                f"--topic {role_name}={topic}: no such topic (topics present: {shown})"
            )
        if present[topic] != role.type:
            raise collector.fail(
                f"--topic {role_name}={topic}: {topic} is {present[topic]}, expected {role.type}"
            )
        return topic
    if present.get(role.default_topic) == role.type:
        return role.default_topic
    remapped = set(collector.topics.values()) | _OUR_TOPICS
    candidates = sorted(t for t, ty in present.items() if ty == role.type and t not in remapped)
    if not role.by_type or not candidates:
        return None
    if len(candidates) > 1:
        raise collector.fail(
            f"several {role.type} topics ({', '.join(candidates)}): pick one with "
            f"--topic {role_name}=/name"
        )
    return candidates[0]


def _planned(collector: _Collector, topic: str | None) -> PlannedTrajectory | None:
    data = collector.singles.get(topic or "")
    if topic is None or data is None:
        return None
    name, types = collector.types[topic]
    try:
        lay = cdr.walk(types, name, data)
    except (ValueError, struct.error) as err:
        raise collector.fail(f"corrupt: {topic} cannot be decoded ({err})") from err
    names = lay.texts.get("joint_names", ())
    joints = tuple(names) if isinstance(names, tuple) else ()
    points: list[str] = []
    while f"points[{len(points)}].time_from_start.sec" in lay.leaves:
        points.append(f"points[{len(points)}].")
    sec = leaf_rows(lay, data, [p + "time_from_start.sec" for p in points], 1)[:, 0]
    nsec = leaf_rows(lay, data, [p + "time_from_start.nanosec" for p in points], 1)[:, 0]
    return PlannedTrajectory(
        joint_names=joints,
        times_s=sec + nsec * 1e-9,
        positions=leaf_rows(lay, data, [p + "positions" for p in points], len(joints)),
        velocities=leaf_rows(lay, data, [p + "velocities" for p in points], len(joints)),
    )


def _urdf_root(urdf: str) -> ElementTree.Element | None:
    try:
        root = ElementTree.fromstring(urdf)
    except ElementTree.ParseError:
        return None
    return root if root.tag == "robot" else None


def urdf_robot_name(urdf: str) -> str | None:
    """The ``<robot name=...>`` of a URDF, None if it is not one."""
    root = _urdf_root(urdf)
    return root.get("name") if root is not None else None


def urdf_effort_limits(urdf: str) -> dict[str, float]:
    """``<limit effort=...>`` per joint of a URDF [N m] (joints without one left out)."""
    root = _urdf_root(urdf)
    limits: dict[str, float] = {}
    for joint in root.iter("joint") if root is not None else ():
        limit = joint.find("limit")
        name = joint.get("name")
        if limit is None or name is None:
            continue
        try:
            value = float(limit.get("effort", "nan"))
        except ValueError:
            continue
        if np.isfinite(value) and value > 0:
            limits[name] = value
    return limits


def _limits_note(urdf: str | None, joints: Sequence[str], topic: str | None) -> str:
    """Where a bag without our metadata gets its effort limits (saturation) from."""
    topic = topic or TOPIC_ROBOT_DESCRIPTION
    if urdf is None:
        return (
            f"no robot description ({topic}): effort limits unknown, saturation at the limit is "
            "n/a (built-in robots of the same name are not assumed)"
        )
    limits = urdf_effort_limits(urdf)
    shown = ", ".join(f"{j} {limits[j]:g}" for j in joints if j in limits)
    missing = [j for j in joints if j not in limits]
    return (
        f"effort limits from the bag's {topic} URDF"
        + (f" [N m]: {shown}" if shown else ": none declared")
        + (f"; none for {', '.join(missing)} (saturation at the limit n/a)" if missing else "")
    )


def _salvage_note(
    path: Path, s: Salvage, size: int, unread: Sequence[Path], unread_bytes: int
) -> tuple[str, float | None]:
    """The note on a salvaged file and the share of the recording lost [%] (None: unknown)."""
    later = (
        f"; the {len(unread)} later split file(s) ({', '.join(p.name for p in unread)}) "
        "were not read"
        if unread
        else ""
    )
    if s.read_messages is None:  # MCAP: bytes
        lost_bytes = s.lost_bytes + unread_bytes
        share = 100 * lost_bytes / max(size + unread_bytes, 1)
        return (
            f"salvaged: {path.name} is damaged at byte {s.at_byte} ({s.problem}); "
            f"{s.lost_bytes} bytes after it ({share:.1f} % of the recording) were not read" + later,
            share,
        )
    pct: float | None = None
    if s.lost_messages is None:
        lost_text = "an unknown number of message rows after it were lost"
        if s.lost_bytes:  # truncated: the share of the bytes its header states
            pct = 100 * s.lost_bytes / (size + s.lost_bytes)
            lost_text += (
                f" with the file's last {s.lost_bytes} bytes ({pct:.1f} % of the recording's bytes)"
            )
    else:
        pct = 100 * s.lost_messages / max(s.read_messages + s.lost_messages, 1)
        lost_text = (
            f"{s.lost_messages} of {s.read_messages + s.lost_messages} message rows "
            f"({pct:.1f} %) after it were lost"
        )
    return (
        f"salvaged: {path.name} is damaged ({s.problem}); {s.read_messages} message rows read "
        f"up to stamp {s.lost_after_ns} ns, {lost_text}" + later,
        None if unread else pct,
    )


def _robot_description(collector: _Collector, topic: str | None) -> str | None:
    data = collector.singles.get(topic or "")
    if topic is None or data is None:
        return None
    name, types = collector.types[topic]
    try:
        value = cdr.walk(types, name, data).texts.get("data")
    except (ValueError, struct.error) as err:
        raise collector.fail(f"corrupt: {topic} cannot be decoded ({err})") from err
    return value if isinstance(value, str) else None


def _match_stamps(
    js_t: NDArray[np.int64], cs_t: NDArray[np.int64], *, period_ns: float | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Row pairs (joint_states, controller_state) at the same instant (nearest, < half a period).

    ``period_ns``: the ``js_t`` period (default: the median step of ``js_t``); a windowed
    read passes the whole recording's, so a window pairs rows as the whole read does.
    """
    if js_t.shape == cs_t.shape and np.array_equal(js_t, cs_t):
        idx = np.arange(js_t.size)
        return idx, idx
    if cs_t.size == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    period = period_ns if period_ns is not None else stamp_period_ns(js_t)
    j = np.searchsorted(cs_t, js_t).clip(1, max(cs_t.size - 1, 1))
    left = (j - 1).clip(0, cs_t.size - 1)
    right = j.clip(0, cs_t.size - 1)
    pick = np.where(np.abs(cs_t[left] - js_t) <= np.abs(cs_t[right] - js_t), left, right)
    ok = np.abs(cs_t[pick] - js_t) <= period / 2
    return np.flatnonzero(ok), pick[ok]


def stamp_period_ns(stamps: NDArray[np.int64]) -> float:
    """Median step of sorted ``stamps`` [ns] (1.0 for fewer than two)."""
    return float(np.median(np.diff(stamps))) if stamps.size > 1 else 1.0


class SinkError(Exception):
    """Carries what a :class:`WindowSink` raised out of a windowed read, whose boundary
    would otherwise report it as a recording that cannot be decoded; :func:`read_recording`
    raises the sink's own exception (its ``__cause__``)."""


class WindowSink(Protocol):
    """Receives a long recording's exact frames, one window at a time, in time order.

    :func:`read_recording` calls :meth:`begin` once (after its first pass) with the
    recording as then known: empty frames, every other field set (``sample_count`` not
    yet), then :meth:`window` for each window: tidy frames of a contiguous stamp interval
    (the rows the whole read would have there). Only a windowed read calls it.
    """

    def begin(self, header: Recording) -> None: ...

    def window(self, samples: pl.DataFrame, controller_states: pl.DataFrame) -> None: ...


def read_recording(
    source: Path, options: ReadOptions | None = None, *, sink: WindowSink | None = None
) -> Recording:
    """Read one recording (rosbag2 directory or bare ``.mcap``) into a :class:`Recording`.

    Times (``time_s``) count from the recording's first control-rate stamp, so header
    stamps may be simulated (from 0) or wall clock alike; ``stamp_ns`` stays as recorded.
    NaN values and empty arrays (legal in ROS messages) become nulls: "not recorded".

    A recording larger than :data:`STREAM_ABOVE_BYTES` (``options.stream_above_bytes``) is
    read in two streaming passes (:mod:`pipeline.log.windowed`): its frames are decimated
    (``decimation`` > 1) and ``sink`` receives the exact frames window by window.

    Args:
        source: the recording.
        options: remaps, salvage and labels for bags we did not write (see
            :class:`ReadOptions`); with ``salvage`` the recording says what was lost.
        sink: receives a windowed read's windows (ignored when the recording is read whole).

    Raises:
        RecordingError: missing, empty, not MCAP, truncated, corrupt (CRC), lacking
            joint states / controller state messages or a field the report needs, an
            unknown role or topic in ``topics``; any other failure while decoding is
            wrapped into one, naming the file.
    """
    source = Path(source)
    options = options or ReadOptions()
    unknown = sorted(set(options.topics) - set(ROLES))
    if unknown:
        raise RecordingError(f"--topic {unknown[0]}=...: unknown role (roles: {', '.join(ROLES)})")
    try:
        files = storage_files(source)
        total = sum(p.stat().st_size for p in files)
    except OSError as err:
        raise RecordingError(f"{source}: cannot read ({err.strerror or err})") from err
    limit = STREAM_ABOVE_BYTES if options.stream_above_bytes is None else options.stream_above_bytes
    try:
        # a .db3 with a -wal is read from a copy: one for every pass, removed however
        # the read ends (Ctrl-C and SIGTERM included)
        with wal_copies(files) as copies:
            if total > limit:
                from pipeline.log.windowed import read_windowed

                return read_windowed(source, files, options, sink, copies=copies)
            return _read(source, files, options, copies=copies)
    except RecordingError:
        raise
    except SinkError as err:  # the caller's sink failed, not the recording
        assert err.__cause__ is not None
        raise err.__cause__ from None
    except Exception as err:  # the boundary: nothing else may escape a per-recording read
        raise RecordingError(
            f"{files[0]}: cannot decode the recording: {type(err).__name__}: {err}"
        ) from err


def _missing_array_notes(arrays: dict[str, F64], topic: str, fields: dict[str, str]) -> list[str]:
    """Notes for optional arrays that are empty (or NaN) in every message of ``topic``."""
    empty = {k for k in fields if (v := arrays.get(k)) is not None and v.size and np.isnan(v).all()}
    return _empty_array_notes(empty, topic, fields)


def _empty_array_notes(empty: set[str], topic: str, fields: dict[str, str]) -> list[str]:
    return [
        f"{topic} carries no {what} values (empty arrays): {what} metrics are n/a"
        for key, what in fields.items()
        if key in empty
    ]


# Optional /joint_states arrays whose absence the report notes.
_JS_OPTIONAL = {"velocity": "velocity", "effort": "effort"}


@dataclass
class _Scanned:
    """What scanning a recording's storage files gave besides the collector's messages."""

    size: int
    sha256: str
    present: dict[str, str]  # topic -> root type
    salvaged: list[tuple[Path, Salvage]]
    notes: list[str]  # the storage readers' notes
    unread: list[Path]  # split files after a salvaged one
    unread_bytes: int


def _scan(
    files: list[Path],
    collector: _Collector,
    *,
    salvage: bool,
    copies: Mapping[Path, Path] | None = None,
) -> _Scanned:
    """Stream every storage file into ``collector`` (stopping after a salvaged one).

    ``copies``: ``.db3`` files copied with their ``-wal`` (:func:`pipeline.log.db3.wal_copies`).
    """
    sha = hashlib.sha256()
    size = 0
    present: dict[str, str] = {}
    salvaged: list[tuple[Path, Salvage]] = []
    notes: list[str] = []
    unread: list[Path] = []
    unread_bytes = 0
    for path in files:
        collector.path = path
        scan: McapScan | Db3Scan
        if path.suffix == ".db3":
            scan = _Db3File(path, collector, salvage=salvage, copy=(copies or {}).get(path))
        else:
            scan = _McapFile(path, collector, salvage=salvage)
        scan.sha = sha
        scan.run()
        size += scan.size
        for c in scan.channels.values():
            schema = scan.schemas.get(c.schema_id)
            present[c.topic] = root_type_name(schema.name) if schema else "?"
        for topic, count in scan.topic_counts.items():
            collector.topic_counts[topic] = collector.topic_counts.get(topic, 0) + count
        collector.metadata.update(scan.metadata)
        notes += scan.notes
        if scan.salvaged is not None:
            salvaged.append((path, scan.salvaged))
            # later split files continue after the damage: not contiguous, not read
            unread = [p for p in files[files.index(path) + 1 :] if p.is_file()]
            unread_bytes = sum(p.stat().st_size for p in unread)
            break
    collector.path = files[0]
    return _Scanned(size, sha.hexdigest(), present, salvaged, notes, unread, unread_bytes)


@dataclass
class _Roles:
    """The chosen topics and joint lists of a recording."""

    chosen: dict[str, str | None]
    js_dec: TopicDecoder
    cs_dec: TopicDecoder
    js_group: Group
    cs_group: Group
    truth: Group | None
    names: tuple[str, ...]

    @property
    def js_cols(self) -> list[int] | None:
        """Columns of the joint-state arrays in controller order (None: already)."""
        cols = [self.js_group.names.index(n) for n in self.names]
        return None if cols == list(range(len(self.js_group.names))) else cols

    @property
    def gt_perm(self) -> list[int]:
        assert self.truth is not None
        return [self.truth.names.index(n) for n in self.names]


def _roles(
    collector: _Collector,
    present: dict[str, str],
    mcap_path: Path,
    salvaged: Sequence[tuple[Path, Salvage]] = (),
) -> _Roles:
    """Pick each role's topic and the joint lists to analyse (from the groups' counts)."""
    chosen = {name: _pick(name, collector, present) for name in ROLES}
    for name in ("joint_states", "controller_state"):
        picked = chosen[name]
        if picked is None or picked not in collector.decoders:
            for path, s in salvaged:  # the damage took every message of the role with it
                at = f" at byte {s.at_byte}" if s.at_byte >= 0 else ""
                raise RecordingError(
                    f"{path}: damaged{at} ({s.problem}); nothing of "
                    f"{picked or name} before the damage to salvage"
                )
            role = ROLES[name]
            what = f"no messages on {picked}" if picked else f"no {role.type} topic"
            shown = ", ".join(f"{t} ({ty})" for t, ty in sorted(present.items())) or "none"
            raise RecordingError(
                f"{mcap_path}: {what} for {name} (default {role.default_topic}; topics "
                f"present: {shown}); remap with --topic {name}=/name"
            )
    cs_dec = collector.decoders[str(chosen["controller_state"])]
    js_dec = collector.decoders[str(chosen["joint_states"])]
    cs_group = cs_dec.largest()
    assert cs_group is not None
    cs_names = cs_group.names
    # The joint-state publisher (of several, e.g. arm + gripper) that carries every joint
    # of the controller, the most frequent one if several do.
    covering = [g for g in js_dec.groups if set(cs_names) <= set(g.names)]
    if not covering:
        shown = "; ".join(", ".join(g.names) for g in js_dec.groups)
        raise RecordingError(
            f"{mcap_path}: no {js_dec.topic} message carries all joints of "
            f"{cs_dec.topic} ({', '.join(cs_names)}); joint lists seen: {shown}"
        )
    js_group = max(covering, key=lambda g: g.count)
    truth_dec = collector.decoders.get(chosen["ground_truth"] or "")
    truth = truth_dec.largest() if truth_dec is not None else None
    if truth is not None and truth.count and not set(cs_names) <= set(truth.names):
        raise RecordingError(
            f"{mcap_path}: joints differ between {TOPIC_GROUND_TRUTH} "
            f"({', '.join(truth.names)}) and {cs_dec.topic} ({', '.join(cs_names)})"
        )
    if truth is not None and not truth.count:
        truth = None
    return _Roles(chosen, js_dec, cs_dec, js_group, cs_group, truth, cs_names)


def _no_pairs(mcap_path: Path) -> RecordingError:
    return RecordingError(
        f"{mcap_path}: no {TOPIC_CONTROLLER_STATE} message shares a time stamp with "
        f"{TOPIC_JOINT_STATES}"
    )


def _read_notes(scanned: _Scanned, roles: _Roles) -> tuple[list[str], float | None]:
    """The notes every read starts with (the storage's, salvage, the joints analysed) and
    the share of the recording a salvage lost [%]."""
    notes: list[str] = list(scanned.notes)
    lost_pct: float | None = None
    for path, s in scanned.salvaged:
        note, lost_pct = _salvage_note(path, s, scanned.size, scanned.unread, scanned.unread_bytes)
        notes.append(note)
    if len(roles.js_dec.groups) > 1 or len(roles.js_group.names) > len(roles.names):
        notes.append(
            f"{roles.js_dec.topic}: analysing {', '.join(roles.names)} (the joints of "
            f"{roles.cs_dec.topic}) from {len(roles.js_dec.groups)} joint list(s)"
        )
    return notes, lost_pct


def _dropped_note(dropped: int) -> list[str]:
    return [f"{dropped} joint-state samples without a controller state were dropped"] * bool(
        dropped
    )


def _truth_note(unmatched: int, cs_topic: str) -> list[str]:
    return [
        f"{unmatched} {cs_topic} samples have no {TOPIC_GROUND_TRUTH} sample at their time"
    ] * bool(unmatched)


def _labels(
    collector: _Collector,
    source: Path,
    options: ReadOptions,
    chosen: dict[str, str | None],
    names: Sequence[str],
) -> tuple[dict[str, str], dict[str, Any], str | None, list[str], bool]:
    """Metadata (ours, else labels), settings, the URDF, the notes about them and whether
    the bag carries our metadata."""
    notes: list[str] = []
    raw_meta = dict(collector.metadata.get(METADATA_EPISODE, {}))
    ours = METADATA_EPISODE in collector.metadata
    labels = {"controller": options.controller, "scenario": options.scenario}
    if not ours:
        raw_meta = {
            "episode": source.name.removesuffix(".mcap"),
            "controller": source.name.removesuffix(".mcap"),
            "scenario": "external",
        }
    raw_meta |= {k: v for k, v in labels.items() if v}
    urdf = _robot_description(collector, chosen["robot_description"])
    if not ours and urdf is not None:
        robot = urdf_robot_name(urdf)
        if robot:
            raw_meta["robot"] = robot
    if not ours:
        notes.append(_limits_note(urdf, names, chosen["robot_description"]))
    settings: dict[str, Any] = {}
    if "settings" in raw_meta:
        try:
            parsed = json.loads(raw_meta["settings"])
            if isinstance(parsed, dict):
                settings = parsed
            else:
                notes.append(
                    f"'{METADATA_EPISODE}' settings is not a JSON object: settings are n/a"
                )
        except json.JSONDecodeError as err:
            notes.append(
                f"'{METADATA_EPISODE}' settings is not valid JSON ({err.msg} at char {err.pos}): "
                "settings are n/a"
            )
    elif not ours:
        notes.append(
            f"no '{METADATA_EPISODE}' metadata record (not recorded by armlab): episode "
            f"'{raw_meta['episode']}', controller '{raw_meta['controller']}' and scenario "
            f"'{raw_meta['scenario']}' from "
            + ("the command line" if any(labels.values()) else "the bag's name")
            + "; settings (gains, plant, planner, motion start) are n/a"
        )
    return raw_meta, settings, urdf, notes, ours


def _tidy(
    stamps: NDArray[np.int64],
    columns: dict[str, F64],
    *,
    names: tuple[str, ...],
    t0_ns: int,
    episode: str,
) -> pl.DataFrame:
    """A tidy frame: one row per stamp and joint, ``time_s`` from ``t0_ns``, NaN -> null."""
    n = len(names)
    m = stamps.size
    frame = pl.DataFrame(
        {
            "stamp_ns": np.repeat(stamps, n),
            "time_s": np.repeat((stamps - t0_ns).astype(np.float64) * 1e-9, n),
            "joint": pl.Series("joint", names, dtype=pl.String).gather(
                np.tile(np.arange(n, dtype=np.int64), m)
            ),
            **{k: np.ascontiguousarray(v).reshape(-1) for k, v in columns.items()},
        }
    )
    return frame.select(
        pl.lit(episode, dtype=pl.String).alias("episode"),
        pl.col("stamp_ns", "time_s", "joint"),
        pl.col(*columns).fill_nan(None),
    )


def _error_feedback(cs: dict[str, F64]) -> tuple[F64, F64]:
    """error = reference - feedback: whichever of the two the controller left out."""
    error = np.where(
        np.isnan(cs["error"]), cs["reference_position"] - cs["feedback_position"], cs["error"]
    )
    feedback = np.where(
        np.isnan(cs["feedback_position"]), cs["reference_position"] - error, cs["feedback_position"]
    )
    return error, feedback


def _truth_at(
    cs_t: NDArray[np.int64],
    gt: tuple[NDArray[np.int64], dict[str, F64]] | None,
    perm: list[int],
    like: F64,
    *,
    period_ns: float | None = None,
) -> tuple[F64, F64, NDArray[np.intp]]:
    """True position and velocity at each controller-state row (NaN where none), and the
    rows that have one."""
    pos = np.full_like(like, np.nan)
    vel = np.full_like(like, np.nan)
    if gt is None:
        return pos, vel, np.zeros(0, dtype=np.intp)
    gt_t, gt_a = gt
    rows_cs, rows_gt = _match_stamps(cs_t, gt_t, period_ns=period_ns)
    pos[rows_cs] = gt_a["position"][rows_gt][:, perm]
    vel[rows_cs] = gt_a["velocity"][rows_gt][:, perm]
    return pos, vel, rows_cs


def _read(
    source: Path, files: list[Path], options: ReadOptions, *, copies: Mapping[Path, Path]
) -> Recording:
    mcap_path = files[0]
    collector = _Collector(options.topics)
    scanned = _scan(files, collector, salvage=options.salvage, copies=copies)
    roles = _roles(collector, scanned.present, mcap_path, scanned.salvaged)
    js_t, js_all = roles.js_group.concat()
    cs_t, cs_a = roles.cs_group.concat()
    js_cols = roles.js_cols
    js_a = js_all if js_cols is None else {k: v[:, js_cols] for k, v in js_all.items()}
    names = roles.names
    js_topic, cs_topic = roles.js_dec.topic, roles.cs_dec.topic
    rows_js, rows_cs = _match_stamps(js_t, cs_t)
    if rows_js.size == 0:
        raise _no_pairs(mcap_path)
    notes, lost_pct = _read_notes(scanned, roles)
    notes += _dropped_note(js_t.size - rows_js.size)
    notes += _missing_array_notes(js_a, js_topic, _JS_OPTIONAL)
    raw_meta, settings, urdf, label_notes, ours = _labels(
        collector, source, options, roles.chosen, names
    )
    notes += label_notes

    # Relative times: wall-clock header stamps (1.7e9 s) would otherwise swamp float64
    # resolution and put the motion end (a duration from the start) 50 years early.
    t0_ns = int(min(js_t[0], cs_t[0]))
    episode = _episode_name(raw_meta, source)
    cs_all = cs_a
    error, feedback = _error_feedback(cs_all)
    truth = roles.truth
    truth_pos, truth_vel, rows_cs_gt = _truth_at(
        cs_t, truth.concat() if truth else None, roles.gt_perm if truth else [], error
    )
    if truth is not None:
        notes += _truth_note(cs_t.size - rows_cs_gt.size, cs_topic)
    every_cs = rows_cs.size == cs_t.size and bool(np.all(rows_cs == np.arange(cs_t.size)))
    every_js = rows_js.size == js_t.size and bool(np.all(rows_js == np.arange(js_t.size)))

    def at_cs(a: F64) -> F64:
        return a if every_cs else a[rows_cs]

    def at_js(a: F64) -> F64:
        return a if every_js else a[rows_js]

    cs_rows = {k: at_cs(v) for k, v in cs_all.items()}
    samples = _tidy(
        js_t if every_js else js_t[rows_js],
        {
            "position_rad": at_js(js_a["position"]),
            "velocity_rad_s": at_js(js_a["velocity"]),
            "effort_nm": at_js(js_a["effort"]),
            "reference_position_rad": cs_rows["reference_position"],
            "reference_velocity_rad_s": cs_rows["reference_velocity"],
            "error_rad": at_cs(error),
            "commanded_effort_nm": cs_rows["commanded_effort"],
            "true_position_rad": at_cs(truth_pos),
            "true_velocity_rad_s": at_cs(truth_vel),
        },
        names=names,
        t0_ns=t0_ns,
        episode=episode,
    )
    controller_states = _tidy(
        cs_t,
        {
            "reference_position_rad": cs_all["reference_position"],
            "reference_velocity_rad_s": cs_all["reference_velocity"],
            "feedback_position_rad": feedback,
            "error_rad": error,
            "commanded_effort_nm": cs_all["commanded_effort"],
            "true_position_rad": truth_pos,
            "true_velocity_rad_s": truth_vel,
        },
        names=names,
        t0_ns=t0_ns,
        episode=episode,
    )
    return Recording(
        source=source,
        mcap_path=mcap_path,
        sha256=scanned.sha256,
        size_bytes=scanned.size,
        metadata=raw_meta,
        settings=settings,
        joint_names=names,
        samples=samples,
        controller_states=controller_states,
        planned=_planned(collector, roles.chosen["planned_trajectory"]),
        robot_description=urdf,
        topic_counts=dict(collector.topic_counts),
        decoded_messages=roles.js_group.count
        + roles.cs_group.count
        + (truth.count if truth else 0),
        notes=tuple(notes),
        has_ground_truth=truth is not None,
        salvaged=bool(scanned.salvaged),
        salvage_lost_pct=lost_pct,
        armlab_metadata=ours,
    )
