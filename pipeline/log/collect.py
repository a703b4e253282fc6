"""Collecting a recording's messages: stream its storage files, decode the candidates of
each role (:data:`pipeline.log.topics.ROLES`) and pick the topic and joint lists that serve
each one.

Topics are found by role: the joint states (``sensor_msgs/msg/JointState``), the controller
state (``control_msgs/msg/JointTrajectoryControllerState``, Jazzy's reference/feedback or
Humble's desired/actual, detected from the schema), the planned trajectory and the robot
description. A role takes the topic named by a remap (``topics={"controller_state":
"/arm_controller/controller_state"}``), else our topic name, else the one topic of its type.

Shared by the whole read (:mod:`pipeline.log.whole`) and the windowed one
(:mod:`pipeline.log.windowed`), whose passes are :class:`Collector` subclasses.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import RecordingError
from pipeline.log import cdr
from pipeline.log.db3 import Db3Scan
from pipeline.log.decode import DecodeError, Group, TopicDecoder, leaf_rows
from pipeline.log.mcap import MESSAGE_PREFIX, McapChannel, McapScan, Salvage
from pipeline.log.msgdef import MsgTypes, parse_msgdef, root_type_name
from pipeline.log.recording import PlannedTrajectory, SinkError
from pipeline.log.rosbag2 import declared_counts
from pipeline.log.topics import OUR_TOPICS, PAIRED, ROLES, WANT

__all__ = [
    "WANT",
    "Collector",
    "Declared",
    "Roles",
    "Scanned",
    "decode_planned",
    "pick_roles",
    "planned_trajectory",
    "robot_description",
    "scan_storage",
]


class Collector:
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
                topic == role.name or (role.by_type and topic not in OUR_TOPICS)
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
        want = WANT.get(type_name)
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
    collector: Collector,
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
    def __init__(self, path: Path, collector: Collector, *, salvage: bool) -> None:
        super().__init__(path, salvage=salvage)
        self.collector = collector

    def on_messages(self, channel: McapChannel, buf: bytes, starts: NDArray[np.int64]) -> None:
        _deliver(self, self.collector, channel, buf, starts)


class _Db3File(Db3Scan):
    def __init__(
        self, path: Path, collector: Collector, *, salvage: bool, copy: Path | None
    ) -> None:
        super().__init__(path, salvage=salvage, copy=copy)
        self.collector = collector

    def on_messages(self, channel: McapChannel, buf: bytes, starts: NDArray[np.int64]) -> None:
        _deliver(self, self.collector, channel, buf, starts)


def _pick(role_name: str, collector: Collector, present: Mapping[str, str]) -> str | None:
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
    if present.get(role.name) == role.type:
        return role.name
    remapped = set(collector.topics.values()) | OUR_TOPICS
    candidates = sorted(t for t, ty in present.items() if ty == role.type and t not in remapped)
    if not role.by_type or not candidates:
        return None
    if len(candidates) > 1:
        raise collector.fail(
            f"several {role.type} topics ({', '.join(candidates)}): pick one with "
            f"--topic {role_name}=/name"
        )
    return candidates[0]


def planned_trajectory(collector: Collector, topic: str | None) -> PlannedTrajectory | None:
    data = collector.singles.get(topic or "")
    if topic is None or data is None:
        return None
    name, types = collector.types[topic]
    try:
        return decode_planned(types, name, data)
    except (ValueError, struct.error) as err:
        raise collector.fail(f"corrupt: {topic} cannot be decoded ({err})") from err


def decode_planned(types: MsgTypes, name: str, data: bytes) -> PlannedTrajectory:
    """The planned trajectory of one ``trajectory_msgs/JointTrajectory`` message.

    Raises:
        ValueError, struct.error: the message cannot be decoded.
    """
    lay = cdr.walk(types, name, data)
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


def robot_description(collector: Collector, topic: str | None) -> str | None:
    data = collector.singles.get(topic or "")
    if topic is None or data is None:
        return None
    name, types = collector.types[topic]
    try:
        value = cdr.walk(types, name, data).texts.get("data")
    except (ValueError, struct.error) as err:
        raise collector.fail(f"corrupt: {topic} cannot be decoded ({err})") from err
    return value if isinstance(value, str) else None


@dataclass(frozen=True)
class Declared:
    """The messages per topic a recording declares it holds.

    Attributes:
        file: the file that declares them (``metadata.yaml``, or an MCAP file).
        what: how the notes name the declaration ("metadata.yaml", "its Statistics record").
        counts: messages per topic.
    """

    file: Path
    what: str
    counts: dict[str, int]

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def short(self, found: Mapping[str, int]) -> dict[str, tuple[int, int]]:
        """Topics with fewer messages found than declared: (declared, found)."""
        return {
            t: (n, found.get(t, 0)) for t, n in sorted(self.counts.items()) if found.get(t, 0) < n
        }


@dataclass
class Scanned:
    """What scanning a recording's storage files gave besides the collector's messages.

    ``declared``: the counts the recording declares (its ``metadata.yaml``, else a lone
    MCAP file's Statistics record), None if it declares none; ``shortfall``: a declaration
    the messages found fall short of (read with ``salvage``; refused without).
    """

    size: int
    sha256: str
    present: dict[str, str]  # topic -> root type
    salvaged: list[tuple[Path, Salvage]]
    notes: list[str]  # the storage readers' notes
    unread: list[Path]  # split files after a salvaged one
    unread_bytes: int
    found: dict[str, int] = field(default_factory=dict)  # messages per topic
    declared: Declared | None = None
    shortfall: Declared | None = None
    shortfall_found: dict[str, int] = field(default_factory=dict)  # in its scope

    @property
    def damaged(self) -> bool:
        """Read with ``salvage`` from a damaged recording, or one missing declared messages."""
        return bool(self.salvaged) or self.shortfall is not None


def scan_storage(
    files: list[Path],
    collector: Collector,
    *,
    salvage: bool,
    copies: Mapping[Path, Path] | None = None,
    source: Path | None = None,
) -> Scanned:
    """Stream every storage file into ``collector`` (stopping after a salvaged one).

    ``copies``: ``.db3`` files copied with their ``-wal`` (:func:`pipeline.log.db3.wal_copies`).
    ``source``: the recording, to check the messages found against the counts it declares
    (its ``metadata.yaml``, each MCAP file's Statistics record); None: not checked.

    Raises:
        RecordingError: besides damage, fewer messages than declared, without ``salvage``.
    """
    sha = hashlib.sha256()
    size = 0
    present: dict[str, str] = {}
    salvaged: list[tuple[Path, Salvage]] = []
    notes: list[str] = []
    unread: list[Path] = []
    unread_bytes = 0
    per_file: list[tuple[Declared, dict[str, int]]] = []
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
        if scan.declared_counts is not None:
            stats = Declared(path, "its Statistics record", scan.declared_counts)
            per_file.append((stats, dict(scan.topic_counts)))
        notes += scan.notes
        if scan.salvaged is not None:
            salvaged.append((path, scan.salvaged))
            # later split files continue after the damage: not contiguous, not read
            unread = [p for p in files[files.index(path) + 1 :] if p.is_file()]
            unread_bytes = sum(p.stat().st_size for p in unread)
            break
    collector.path = files[0]
    found = dict(collector.topic_counts)
    scanned = Scanned(size, sha.hexdigest(), present, salvaged, notes, unread, unread_bytes, found)
    if source is None:
        return scanned
    in_yaml = declared_counts(source) if source.is_dir() else None
    checks = list(per_file)
    if in_yaml:  # the whole bag's: checked first
        checks.insert(0, (Declared(source / "metadata.yaml", "metadata.yaml", in_yaml), found))
    if checks and (in_yaml or len(files) == 1):
        scanned.declared = checks[0][0]
    if salvaged:  # damaged: the salvage note says what was lost against the declaration
        return scanned
    hit = next(((d, got) for d, got in checks if d.short(got)), None)
    if hit is not None:
        if not salvage:
            raise _shortfall_error(*hit)
        scanned.shortfall, scanned.shortfall_found = hit
    return scanned


def _shortfall_error(declared: Declared, found: Mapping[str, int]) -> RecordingError:
    short = declared.short(found)
    topic, (n, got) = next(iter(short.items()))
    others = f" (and {len(short) - 1} other topic(s))" if len(short) > 1 else ""
    return RecordingError(
        f"{declared.file}: {declared.what} declares {n} messages on {topic}, the recording "
        f"holds {got}{others}: messages were removed or lost; --salvage reads the messages "
        "that are there"
    )


@dataclass
class Roles:
    """The chosen topics and joint lists of a recording."""

    chosen: dict[str, str | None]
    js_dec: TopicDecoder
    cs_dec: TopicDecoder
    js_group: Group
    cs_group: Group
    paired: dict[str, Group]  # role -> its joint list read (:data:`PAIRED`; present ones)
    names: tuple[str, ...]

    @property
    def js_cols(self) -> list[int] | None:
        """Columns of the joint-state arrays in controller order (None: already)."""
        cols = [self.js_group.names.index(n) for n in self.names]
        return None if cols == list(range(len(self.js_group.names))) else cols

    def perm(self, role: str) -> list[int]:
        """A paired role's columns in controller joint order."""
        return [self.paired[role].names.index(n) for n in self.names]


def pick_roles(
    collector: Collector,
    present: dict[str, str],
    mcap_path: Path,
    salvaged: Sequence[tuple[Path, Salvage]] = (),
    *,
    joint_states_only: bool = False,
) -> Roles:
    """Pick each role's topic and the joint lists to analyse (from the groups' counts).

    With ``joint_states_only`` a recording without controller state is read from its joint
    states alone: the controller-state role is the joint-state topic itself (its joints are
    the most frequent joint list's; the reader fills the controller columns with nulls).
    """
    chosen = {name: _pick(name, collector, present) for name in ROLES}
    cs_missing = chosen["controller_state"] is None or (
        str(chosen["controller_state"]) not in collector.decoders
    )
    js_only = joint_states_only and cs_missing and not salvaged
    for name in ("joint_states",) if js_only else ("joint_states", "controller_state"):
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
            # joint states and no reference: a log to identify from, not to track against
            log_only = name == "controller_state" and chosen["joint_states"] in collector.decoders
            raise RecordingError(
                f"{mcap_path}: {what} for {name} (default {role.name}; topics "
                f"present: {shown}); remap with --topic {name}=/name"
                + (
                    "; a log of joint states alone has no reference to measure tracking "
                    "against: `pipeline identify fit` reads it (docs/identify.md)"
                    if log_only
                    else ""
                )
            )
    js_dec = collector.decoders[str(chosen["joint_states"])]
    if js_only:
        chosen["controller_state"] = None
    cs_dec = js_dec if js_only else collector.decoders[str(chosen["controller_state"])]
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
    paired: dict[str, Group] = {}
    for name, row in PAIRED.items():
        dec = collector.decoders.get(chosen[name] or "")
        group = dec.largest() if dec is not None else None
        if group is None or not group.count:
            continue
        if not set(cs_names) <= set(group.names):
            raise RecordingError(
                f"{mcap_path}: joints differ between {row.name} "
                f"({', '.join(group.names)}) and {cs_dec.topic} ({', '.join(cs_names)})"
            )
        paired[name] = group
    return Roles(chosen, js_dec, cs_dec, js_group, cs_group, paired, cs_names)
