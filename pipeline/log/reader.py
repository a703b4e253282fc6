"""Read recordings (rosbag2 directories or bare ``.mcap`` files) into Polars frames.

This is the report stage's only way into a recording, so it trusts nothing:
the MCAP records are parsed here (streamed record by record, one chunk in
memory at a time), every chunk CRC and the data-section and summary CRCs are
checked, and the file must end with a footer and the closing magic. Any failure is a
:class:`RecordingError` naming the file and the problem.

Decoding is schema-driven: the ros2msg schema embedded in the recording is
parsed, the first message of a channel is walked once to find where every
field sits (its *layout*), and all messages of that channel in a chunk that
have the same length and the same length prefixes / strings as that first one
are decoded together with numpy (a byte gather and a dtype view). Messages
that differ (a header.frame_id that changes length, joint names that change)
go through the per-message walker, which gives the same values, only slower.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
import polars as pl
import yaml
from numpy.typing import NDArray

from pipeline.constants import (
    METADATA_EPISODE,
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
    TOPIC_PLANNED_TRAJECTORY,
    TOPIC_ROBOT_DESCRIPTION,
)
from pipeline.errors import RecordingError

F64 = NDArray[np.float64]

MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER = 0x01
_OP_FOOTER = 0x02
_OP_SCHEMA = 0x03
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_MESSAGE_INDEX = 0x07
_OP_METADATA = 0x0C
_OP_DATA_END = 0x0F
# Message record prefix: channel_id u16, sequence u32, log_time u64, publish_time u64.
_MESSAGE_PREFIX = 22
_FOOTER_RECORD = 1 + 8 + 20
# Loose (unchunked) messages are batched into pseudo-chunks of this size.
_LOOSE_BATCH_BYTES = 4 << 20

REQUIRED_TOPICS = (TOPIC_JOINT_STATES, TOPIC_CONTROLLER_STATE)

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
        notes: non-fatal oddities (unparseable settings, dropped samples).
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
            if isinstance(value, int | float) and np.isfinite(value):
                return float(value)
        if self.planned is not None and self.planned.times_s.size:
            return float(self.planned.times_s[-1])
        return None


def _episode_name(metadata: dict[str, str], source: Path) -> str:
    return metadata.get("episode") or source.name.removesuffix(".mcap")


# --- finding recordings -----------------------------------------------------------------


def find_recordings(root: Path) -> list[Path]:
    """Every rosbag2 directory (has ``metadata.yaml``) and bare ``.mcap`` file under ``root``.

    Hidden files and folders (temporary names of a writer at work) are ignored.
    A ``root`` that is itself a recording is returned alone.
    """
    root = Path(root)
    if root.is_file():
        return [root]
    if (root / "metadata.yaml").is_file():
        return [root]
    found: list[Path] = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        here = Path(dirpath)
        if here != root and "metadata.yaml" in filenames:
            found.append(here)
            dirnames[:] = []
            continue
        found.extend(
            here / f for f in sorted(filenames) if f.endswith(".mcap") and not f.startswith(".")
        )
    return sorted(found)


def _mcap_file_of(source: Path) -> Path:
    if not source.exists():
        raise RecordingError(f"{source}: no such file or directory")
    if source.is_file():
        return source
    meta = source / "metadata.yaml"
    names: list[str] = []
    if meta.is_file():
        try:
            info = yaml.safe_load(meta.read_text(encoding="utf-8"))
            rel = info["rosbag2_bagfile_information"]["relative_file_paths"]
            names = [str(r) for r in rel]
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError) as err:
            raise RecordingError(
                f"{meta}: not a rosbag2 metadata file (expected "
                "rosbag2_bagfile_information.relative_file_paths)"
            ) from err
    else:
        names = sorted(p.name for p in source.glob("*.mcap"))
    if not names:
        raise RecordingError(f"{source}: no .mcap file in this rosbag2 directory")
    if len(names) > 1:
        raise RecordingError(
            f"{source}: split bags are not supported ({len(names)} files: {', '.join(names)})"
        )
    path = source / names[0]
    if not path.is_file():
        raise RecordingError(f"{path}: listed in metadata.yaml but missing")
    return path


# --- ros2msg schemas ---------------------------------------------------------------------

_PRIMITIVES: dict[str, str] = {
    "bool": "u1",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "int64": "i8",
    "uint64": "u8",
    "float32": "f4",
    "float64": "f8",
}
_TIME_TYPES = ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")
_SECTION_RE = re.compile(r"^={3,}\s*$", re.MULTILINE)
_ARRAY_RE = re.compile(r"^(?P<base>[^\[]+)(\[(?P<bound><=)?(?P<size>\d*)\])?$")


@dataclass(frozen=True)
class MsgField:
    """One field of a message type.

    Attributes:
        name: field name.
        base: primitive name (``float64``, ``string``) or full type (``pkg/msg/Type``).
        array: None for a single value, -1 for a sequence, N for a fixed array of N.
    """

    name: str
    base: str
    array: int | None


MsgTypes = dict[str, tuple[MsgField, ...]]


def _normalize_type(name: str, package: str) -> str:
    if name in _PRIMITIVES or name in ("string", "wstring"):
        return name
    if name.startswith("string<=") or name.startswith("wstring<="):
        return name.split("<=")[0]
    if name in ("time", "duration"):
        return f"builtin_interfaces/msg/{name.capitalize()}"
    parts = name.split("/")
    if len(parts) == 3:
        return name
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if name == "Header":
        return "std_msgs/msg/Header"
    return f"{package}/msg/{name}"


def _parse_fields(text: str, package: str) -> tuple[MsgField, ...]:
    fields: list[MsgField] = []
    for raw_line in text.splitlines():
        line = raw_line.split("#", 1)[0].strip()
        if not line:
            continue
        tokens = line.split()
        if len(tokens) < 2:
            raise ValueError(f"cannot parse line {raw_line!r}")
        type_token, name = tokens[0], tokens[1]
        if "=" in name or (len(tokens) > 2 and tokens[2].startswith("=")):
            continue  # a constant, not a field
        match = _ARRAY_RE.match(type_token)
        if match is None:
            raise ValueError(f"cannot parse type {type_token!r}")
        array: int | None = None
        if match.group(0) != match.group("base"):
            size = match.group("size")
            array = -1 if (match.group("bound") or not size) else int(size)
        fields.append(MsgField(name, _normalize_type(match.group("base"), package), array))
    return tuple(fields)


def root_type_name(schema_name: str) -> str:
    """The full name (``pkg/msg/Type``) a schema's root type is stored under.

    MCAP schema names come as ``sensor_msgs/msg/JointState`` (ROS 2) or
    ``sensor_msgs/JointState`` (older writers); both mean the same type.
    """
    return _normalize_type(schema_name, schema_name.split("/")[0])


def parse_msgdef(root_type: str, text: str) -> MsgTypes:
    """Parse a ros2msg schema (the root definition plus ``MSG: pkg/Type`` sections).

    Returns:
        Every type it defines by full name (``pkg/msg/Type``; the root under
        :func:`root_type_name`). ``Time`` and ``Duration`` are added when the schema
        leaves them out.
    """
    root = root_type_name(root_type)
    sections = _SECTION_RE.split(text)
    types: MsgTypes = {}
    for i, section in enumerate(sections):
        body = section.strip("\n")
        if i == 0:
            name = root
        else:
            first, _, body = body.partition("\n")
            if not first.startswith("MSG:"):
                raise ValueError(f"section {i} does not start with 'MSG: <type>'")
            name = _normalize_type(first.removeprefix("MSG:").strip(), "")
        types[name] = _parse_fields(body, name.split("/")[0])
    for t in _TIME_TYPES:
        types.setdefault(t, (MsgField("sec", "int32", None), MsgField("nanosec", "uint32", None)))
    for fields in types.values():
        for f in fields:
            builtin = f.base in _PRIMITIVES or f.base in ("string", "wstring")
            if not builtin and f.base not in types:
                raise ValueError(f"type {f.base} is used but not defined")
    return types


# --- CDR layout walking ----------------------------------------------------------------------


class _Walk:
    """Walks one CDR message, recording where each numeric leaf and string sits."""

    __slots__ = ("buf", "check", "end", "endian", "leaves", "pos", "texts", "types")

    def __init__(self, types: MsgTypes, buf: bytes | memoryview) -> None:
        if len(buf) < 4:
            raise ValueError("shorter than the CDR encapsulation header")
        kind = buf[1]
        if kind not in (0, 1):
            raise ValueError(f"unsupported CDR encapsulation kind {kind}")
        self.endian = "<" if kind == 1 else ">"
        self.types = types
        self.buf = buf
        self.end = len(buf)
        self.pos = 4
        self.leaves: dict[str, tuple[int, str, int]] = {}
        self.texts: dict[str, str | tuple[str, ...]] = {}
        # Byte ranges that must be identical for another message to share this layout.
        self.check: list[tuple[int, int]] = []

    def _align(self, size: int) -> None:
        a = min(size, 8)
        self.pos = 4 + ((self.pos - 4 + a - 1) // a) * a

    def _u32(self, structural: bool = True) -> int:
        self._align(4)
        if self.pos + 4 > self.end:
            raise ValueError("message ends inside a length field")
        (value,) = struct.unpack_from(self.endian + "I", self.buf, self.pos)
        if structural:
            self.check.append((self.pos, self.pos + 4))
        self.pos += 4
        return int(value)

    def _string(self) -> str:
        start = self.pos
        n = self._u32(structural=False)
        if self.pos + n > self.end:
            raise ValueError("message ends inside a string")
        raw = bytes(self.buf[self.pos : self.pos + n])
        self.pos += n
        self.check.append((self._aligned_start(start), self.pos))
        return raw.rstrip(b"\x00").decode("utf-8", errors="replace")

    def _aligned_start(self, start: int) -> int:
        return 4 + ((start - 4 + 3) // 4) * 4

    def walk(self, type_name: str, prefix: str = "") -> None:
        for f in self.types[type_name]:
            path = f"{prefix}{f.name}"
            count = 1 if f.array is None else (self._u32() if f.array < 0 else f.array)
            if f.base in _PRIMITIVES:
                dtype = _PRIMITIVES[f.base]
                size = int(dtype[1])
                if count:
                    self._align(size)
                if self.pos + size * count > self.end:
                    raise ValueError(f"message ends inside field {path}")
                self.leaves[path] = (self.pos, self.endian + dtype, count)
                self.pos += size * count
            elif f.base in ("string", "wstring"):
                if f.base == "wstring":
                    raise ValueError(f"wstring field {path} is not supported")
                values = tuple(self._string() for _ in range(count))
                self.texts[path] = values[0] if f.array is None else values
            elif f.array is None:
                self.walk(f.base, f"{path}.")
            else:
                for k in range(count):
                    self.walk(f.base, f"{path}[{k}].")


@dataclass(frozen=True)
class MessageLayout:
    """Where each field of one message sits; shared by same-shaped messages.

    Attributes:
        size: message length [bytes] (CDR header included).
        leaves: path -> (byte offset, numpy dtype string, element count).
        texts: path -> string (or tuple of strings for string arrays).
        check_cols: byte offsets (length prefixes, strings) that must match.
        check_bytes: this message's bytes at ``check_cols``.
    """

    size: int
    leaves: dict[str, tuple[int, str, int]]
    texts: dict[str, str | tuple[str, ...]]
    check_cols: NDArray[np.intp]
    check_bytes: NDArray[np.uint8]

    def values(self, data: bytes | memoryview, path: str) -> NDArray[Any]:
        """The array at ``path`` in ``data`` (a message with this layout)."""
        off, dtype, count = self.leaves[path]
        return np.frombuffer(data, dtype=dtype, count=count, offset=off)


def message_layout(types: MsgTypes, root: str, data: bytes | memoryview) -> MessageLayout:
    """Walk one CDR message of type ``root`` and return its layout.

    Raises:
        ValueError: the bytes do not fit the type (truncated or corrupt).
    """
    if root not in types:
        root = root_type_name(root)
        if root not in types:
            raise ValueError(f"type {root} is not defined by the schema")
    w = _Walk(types, data)
    w.walk(root)
    if w.pos > w.end:
        raise ValueError("message shorter than its fields")
    cols = (
        np.concatenate([np.arange(a, b, dtype=np.intp) for a, b in w.check])
        if w.check
        else np.zeros(0, dtype=np.intp)
    )
    raw = np.frombuffer(data, dtype=np.uint8)
    return MessageLayout(
        size=len(data),
        leaves=w.leaves,
        texts=w.texts,
        check_cols=cols,
        check_bytes=raw[cols].copy(),
    )


# --- the MCAP stream --------------------------------------------------------------------------


@dataclass
class _Channel:
    id: int
    topic: str
    schema_id: int
    encoding: str


@dataclass(frozen=True)
class _Want:
    """Fields to decode from a control-rate topic (first alias present wins).

    ``required``: groups of field paths; the schema must have at least one path of
    each group (besides ``header.stamp``), else the recording is refused.
    """

    names: tuple[str, ...]
    arrays: dict[str, tuple[str, ...]]
    required: tuple[tuple[str, ...], ...] = ()


_JOINT_STATE_WANT = _Want(
    names=("name",),
    arrays={
        "position": ("position",),
        "velocity": ("velocity",),
        "effort": ("effort",),
    },
    required=(("position",),),
)
_WANT: dict[str, _Want] = {
    TOPIC_JOINT_STATES: _JOINT_STATE_WANT,
    TOPIC_GROUND_TRUTH: _JOINT_STATE_WANT,
    TOPIC_CONTROLLER_STATE: _Want(
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
_STAMP_SEC = "header.stamp.sec"
_STAMP_NSEC = "header.stamp.nanosec"


@dataclass
class _TopicData:
    """Decoded arrays of one control-rate topic, accumulated chunk by chunk."""

    topic: str
    type_name: str
    types: MsgTypes
    want: _Want
    layout: MessageLayout | None = None
    names: tuple[str, ...] | None = None
    stamps: list[NDArray[np.int64]] = field(default_factory=list)
    arrays: dict[str, list[F64]] = field(default_factory=dict)
    count: int = 0


class _McapScan:
    """Streams one MCAP file: validates it and decodes the topics the report needs."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, _Channel] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.topic_counts: dict[str, int] = {}
        self.topic_data: dict[int, _TopicData | None] = {}
        self.singles: dict[str, tuple[int, bytes]] = {}
        self.sha = hashlib.sha256()
        self.size = 0
        # The chunk read last and its message indexes, decoded once the indexes are in.
        self._pending: tuple[bytes, int] | None = None
        self._index: dict[int, NDArray[np.uint64]] = {}

    # ---- errors
    def _fail(self, problem: str) -> RecordingError:
        return RecordingError(f"{self.path}: {problem}")

    # ---- the record loop
    def run(self) -> None:
        try:
            self.size = self.path.stat().st_size
            fh = open(self.path, "rb")  # noqa: SIM115 - closed in finally below
        except OSError as err:
            raise self._fail(f"cannot read ({err.strerror})") from err
        try:
            self._run(fh)
        finally:
            fh.close()

    def _read(self, fh: IO[bytes], n: int) -> bytes:
        data = fh.read(n)
        self.sha.update(data)
        return data

    def _run(self, fh: IO[bytes]) -> None:
        if self.size == 0:
            raise self._fail("empty file (0 bytes); expected an MCAP recording")
        magic = self._read(fh, 8)
        if magic != MCAP_MAGIC:
            raise self._fail("not an MCAP file (the first bytes are not the MCAP magic)")
        crc = zlib.crc32(magic)
        pos = 8
        loose = bytearray()
        while True:
            head = self._read(fh, 9)
            if len(head) < 9:
                raise self._fail(
                    f"truncated: the file ends at byte {self.size} before the data section "
                    "is closed (no DataEnd record, no footer)"
                )
            op = head[0]
            (length,) = struct.unpack_from("<Q", head, 1)
            if pos + 9 + length > self.size:
                raise self._fail(
                    f"truncated: record at byte {pos} claims {length} bytes but the file "
                    f"ends at byte {self.size}"
                )
            if op != _OP_MESSAGE_INDEX:
                self._flush()
            if op == _OP_DATA_END:
                body = self._read(fh, length)
                (expected,) = struct.unpack_from("<I", body, 0) if length >= 4 else (0,)
                if expected and expected != crc:
                    raise self._fail(
                        f"corrupt: data section CRC mismatch (recorded {expected:#010x}, "
                        f"computed {crc:#010x})"
                    )
                pos += 9 + length
                break
            body = self._read(fh, length)
            crc = zlib.crc32(body, zlib.crc32(head, crc))
            if op == _OP_CHUNK:
                self._pending = (self._chunk(body, pos), pos)
            elif op == _OP_MESSAGE_INDEX:
                self._message_index(body, pos)
            elif op == _OP_MESSAGE:
                loose += head + body
                if len(loose) >= _LOOSE_BATCH_BYTES:
                    self._records(bytes(loose), pos)
                    loose.clear()
            elif op in (_OP_SCHEMA, _OP_CHANNEL):
                self._records(head + body, pos)
            elif op == _OP_METADATA:
                self._metadata(body, pos)
            elif op == _OP_FOOTER:
                raise self._fail(f"corrupt: footer at byte {pos} before the DataEnd record")
            pos += 9 + length
        if loose:
            self._records(bytes(loose), pos)
        self._finish_file(fh, pos)

    def _finish_file(self, fh: IO[bytes], pos: int) -> None:
        """Check the end of the file: footer + magic, and the summary CRC if recorded.

        The summary itself is not needed here, but a damaged one misleads other tools.
        It holds indexes and statistics only (a few bytes per chunk), so it is read whole.
        """
        rest = self._read(fh, self.size - pos)
        if len(rest) < _FOOTER_RECORD + 8:
            raise self._fail(f"truncated: no footer after the data section (ends at byte {pos})")
        footer = rest[-(_FOOTER_RECORD + 8) :]
        if footer[-8:] != MCAP_MAGIC or footer[0] != _OP_FOOTER:
            raise self._fail("truncated or corrupt: the file does not end with a footer and magic")
        start, _, expected = struct.unpack_from("<QQI", footer, 9)
        if not expected or start < pos:
            return  # no summary, or no CRC recorded for it
        covered = rest[start - pos : len(rest) - 8 - 4]  # up to the footer's CRC field
        crc = zlib.crc32(covered)
        if crc != expected:
            raise self._fail(
                f"corrupt: summary section CRC mismatch (recorded {expected:#010x}, "
                f"computed {crc:#010x})"
            )

    # ---- record bodies
    @staticmethod
    def _str(body: bytes, off: int) -> tuple[str, int]:
        (n,) = struct.unpack_from("<I", body, off)
        end = off + 4 + n
        if end > len(body):
            raise ValueError("string runs past its record")
        return body[off + 4 : end].decode("utf-8"), end

    def _metadata(self, body: bytes, pos: int) -> None:
        try:
            name, off = self._str(body, 0)
            (nbytes,) = struct.unpack_from("<I", body, off)
            off += 4
            end = off + nbytes
            values: dict[str, str] = {}
            while off < end:
                key, off = self._str(body, off)
                value, off = self._str(body, off)
                values[key] = value
        except (struct.error, ValueError, UnicodeDecodeError) as err:
            raise self._fail(f"corrupt: metadata record at byte {pos} ({err})") from err
        self.metadata[name] = values

    def _chunk(self, body: bytes, pos: int) -> bytes:
        try:
            _, _, usize, ucrc = struct.unpack_from("<QQQI", body, 0)
            compression, off = self._str(body, 28)
            (clen,) = struct.unpack_from("<Q", body, off)
            off += 8
        except (struct.error, ValueError, UnicodeDecodeError) as err:
            raise self._fail(f"corrupt: chunk header at byte {pos} ({err})") from err
        if off + clen > len(body):
            raise self._fail(f"corrupt: chunk at byte {pos} is shorter than it claims")
        raw = body[off : off + clen]
        try:
            if compression == "zstd":
                import zstandard

                data = zstandard.ZstdDecompressor().decompress(raw, max_output_size=usize)
            elif compression == "lz4":
                import lz4.frame  # type: ignore[import-untyped]

                data = lz4.frame.decompress(raw)
            elif compression == "":
                data = raw
            else:
                raise self._fail(
                    f"chunk at byte {pos} uses unsupported compression '{compression}' "
                    "(expected zstd, lz4 or none)"
                )
        except RecordingError:
            raise
        except Exception as err:  # zstd / lz4 raise their own error types
            raise self._fail(
                f"corrupt: chunk at byte {pos} cannot be decompressed ({compression}: {err})"
            ) from err
        if len(data) != usize:
            raise self._fail(
                f"corrupt: chunk at byte {pos} decompresses to {len(data)} bytes, expected {usize}"
            )
        if ucrc:
            got = zlib.crc32(data)
            if got != ucrc:
                raise self._fail(
                    f"corrupt: chunk at byte {pos} fails its CRC check "
                    f"(recorded {ucrc:#010x}, computed {got:#010x})"
                )
        return bytes(data)

    def _message_index(self, body: bytes, pos: int) -> None:
        if self._pending is None:
            return
        try:
            (cid, nbytes) = struct.unpack_from("<HI", body, 0)
            if 6 + nbytes > len(body) or nbytes % 16:
                raise ValueError("entries overrun the record")
        except (struct.error, ValueError) as err:
            raise self._fail(f"corrupt: message index at byte {pos} ({err})") from err
        entries = np.frombuffer(body, dtype="<u8", count=nbytes // 8, offset=6)
        self._index[cid] = entries[1::2]

    def _flush(self) -> None:
        """Decode the chunk read last, now that its message indexes (if any) are known."""
        if self._pending is None:
            return
        data, pos = self._pending
        index, self._index, self._pending = self._index, {}, None
        positions = self._indexed_positions(data, index) if index else None
        self._records(data, pos, positions)

    def _indexed_positions(
        self, buf: bytes, index: dict[int, NDArray[np.uint64]]
    ) -> dict[int, NDArray[np.int64]] | None:
        """Message starts per channel from the chunk's message indexes, if they provably
        tile the whole chunk with message records; None (walk instead) otherwise."""
        if any(cid not in self.channels for cid in index):
            return None
        u8 = np.frombuffer(buf, dtype=np.uint8)
        offsets = np.concatenate(list(index.values())).astype(np.int64)
        if offsets.size == 0 or int(offsets.max()) + 9 + _MESSAGE_PREFIX > u8.size:
            return None
        order = np.sort(offsets)
        lengths = _gather_u64(u8, order + 1).astype(np.int64)
        ends = order + 9 + lengths
        if order[0] != 0 or ends[-1] != u8.size or not np.array_equal(ends[:-1], order[1:]):
            return None
        if not (u8[order] == _OP_MESSAGE).all():
            return None
        out: dict[int, NDArray[np.int64]] = {}
        for cid, offs in index.items():
            starts = np.sort(offs.astype(np.int64)) + 9
            ids = _rows(u8, starts, 2).view("<u2").reshape(-1)
            if not (ids == cid).all():
                return None
            out[cid] = starts
        return out

    def _records(
        self, buf: bytes, pos: int, indexed: dict[int, NDArray[np.int64]] | None = None
    ) -> None:
        """Find the message records of a chunk (or a batch of loose records) and decode."""
        if indexed is not None:
            self._decode_positions(buf, pos, indexed)
            return
        positions: dict[int, list[int]] = {}
        n = len(buf)
        off = 0
        unpack = struct.unpack_from
        try:
            while off < n:
                op = buf[off]
                (length,) = unpack("<Q", buf, off + 1)
                start = off + 9
                if op == _OP_MESSAGE:
                    (cid,) = unpack("<H", buf, start)
                    lst = positions.get(cid)
                    if lst is None:
                        lst = positions[cid] = []
                    lst.append(start)
                elif op == _OP_SCHEMA:
                    self._schema(buf[start : start + length])
                elif op == _OP_CHANNEL:
                    self._channel(buf[start : start + length])
                off = start + length
        except (struct.error, ValueError, UnicodeDecodeError) as err:
            raise self._fail(f"corrupt: bad record inside the chunk at byte {pos} ({err})") from err
        if off != n:
            raise self._fail(f"corrupt: records overrun the chunk at byte {pos}")
        self._decode_positions(
            buf, pos, {cid: np.asarray(v, dtype=np.int64) for cid, v in positions.items()}
        )

    def _decode_positions(
        self, buf: bytes, pos: int, positions: dict[int, NDArray[np.int64]]
    ) -> None:
        u8 = np.frombuffer(buf, dtype=np.uint8)
        unpack = struct.unpack_from
        for cid, starts in positions.items():
            channel = self.channels.get(cid)
            if channel is None:
                raise self._fail(f"corrupt: message on unknown channel {cid} (chunk at byte {pos})")
            self.topic_counts[channel.topic] = self.topic_counts.get(channel.topic, 0) + len(starts)
            target = self._target(channel)
            if target is not None:
                try:
                    self._decode(target, buf, u8, starts)
                except RecordingError:
                    raise
                except Exception as err:  # a decoder bug or an input it did not foresee
                    raise self._fail(
                        f"cannot decode {channel.topic}: {type(err).__name__}: {err}"
                    ) from err
            elif (
                channel.topic in (TOPIC_PLANNED_TRAJECTORY, TOPIC_ROBOT_DESCRIPTION)
                and channel.topic not in self.singles
            ):
                s = int(starts[0])
                (length,) = unpack("<Q", buf, s - 8)
                data = buf[s + _MESSAGE_PREFIX : s + length]
                self.singles[channel.topic] = (cid, data)

    def _schema(self, body: bytes) -> None:
        (sid,) = struct.unpack_from("<H", body, 0)
        name, off = self._str(body, 2)
        encoding, off = self._str(body, off)
        (n,) = struct.unpack_from("<I", body, off)
        self.schemas[sid] = (name, encoding, body[off + 4 : off + 4 + n])

    def _channel(self, body: bytes) -> None:
        cid, sid = struct.unpack_from("<HH", body, 0)
        topic, off = self._str(body, 4)
        encoding, off = self._str(body, off)
        self.channels[cid] = _Channel(cid, topic, sid, encoding)

    def types_of(self, channel: _Channel) -> tuple[str, MsgTypes]:
        schema = self.schemas.get(channel.schema_id)
        if schema is None:
            raise self._fail(f"channel {channel.topic} refers to a missing schema")
        name, encoding, data = schema
        if channel.encoding != "cdr" or encoding != "ros2msg":
            raise self._fail(
                f"{channel.topic} is encoded as {channel.encoding}/{encoding}; "
                "expected cdr/ros2msg (a ROS 2 recording)"
            )
        try:
            return root_type_name(name), parse_msgdef(name, data.decode("utf-8"))
        except (ValueError, UnicodeDecodeError) as err:
            raise self._fail(f"schema {name} of {channel.topic} cannot be parsed ({err})") from err

    def _target(self, channel: _Channel) -> _TopicData | None:
        if channel.id in self.topic_data:
            return self.topic_data[channel.id]
        want = _WANT.get(channel.topic)
        target = None
        if want is not None:
            name, types = self.types_of(channel)
            target = _TopicData(channel.topic, name, types, want)
        self.topic_data[channel.id] = target
        return target

    # ---- decoding
    def _decode(
        self, td: _TopicData, buf: bytes, u8: NDArray[np.uint8], starts: NDArray[np.int64]
    ) -> None:
        lengths = _gather_u64(u8, starts - 8)
        data_start = starts + _MESSAGE_PREFIX
        data_len = lengths.astype(np.int64) - _MESSAGE_PREFIX
        if td.layout is None:
            td.layout = self._layout(td, buf, int(data_start[0]), int(data_len[0]))
            self._check_fields(td, td.layout)
            td.names = self._names(td, td.layout)
        layout = td.layout
        fast = data_len == layout.size
        matrix = None
        if fast.any():
            matrix = _rows(u8, data_start[fast], layout.size)
            same = (matrix[:, layout.check_cols] == layout.check_bytes[None, :]).all(axis=1)
            if not same.all():
                where = np.flatnonzero(fast)
                fast[where[~same]] = False
                matrix = matrix[same]
        n_fast = int(fast.sum())
        n = starts.size
        stamps = np.empty(n, dtype=np.int64)
        out = {key: np.empty((n, len(td.names or ())), dtype=np.float64) for key in td.want.arrays}
        if n_fast:
            assert matrix is not None
            stamps[fast] = _stamp_ns(layout, matrix)
            for key, aliases in td.want.arrays.items():
                out[key][fast] = _leaf_matrix(layout, matrix, aliases, td, self)
        for i in np.flatnonzero(~fast):
            s = int(data_start[i])
            data = buf[s : s + int(data_len[i])]
            one = self._layout(td, data, 0, len(data))
            if self._names(td, one) != td.names:
                raise self._fail(
                    f"joint names on {td.topic} change between messages "
                    f"({list(td.names or ())} then {list(self._names(td, one))})"
                )
            row = np.frombuffer(data, dtype=np.uint8)[None, :]
            stamps[i] = _stamp_ns(one, row)[0]
            for key, aliases in td.want.arrays.items():
                out[key][i] = _leaf_matrix(one, row, aliases, td, self)[0]
        td.stamps.append(stamps)
        for key, arr in out.items():
            td.arrays.setdefault(key, []).append(arr)
        td.count += n

    def _layout(self, td: _TopicData, buf: bytes, start: int, length: int) -> MessageLayout:
        data = buf[start : start + length] if (start or length != len(buf)) else buf
        try:
            return message_layout(td.types, td.type_name, data)
        except (ValueError, struct.error) as err:
            raise self._fail(
                f"corrupt: a message on {td.topic} cannot be decoded as {td.type_name} ({err})"
            ) from err

    def _check_fields(self, td: _TopicData, layout: MessageLayout) -> None:
        """Refuse a schema that lacks a field the report cannot do without."""
        missing = [p for p in (_STAMP_SEC, _STAMP_NSEC) if p not in layout.leaves]
        missing += [
            " or ".join(group)
            for group in td.want.required
            if not any(p in layout.leaves for p in group)
        ]
        if missing:
            raise self._fail(
                f"{td.topic} ({td.type_name}) has no field {', '.join(missing)}; "
                "cannot read it as a control-rate topic"
            )

    def _names(self, td: _TopicData, layout: MessageLayout) -> tuple[str, ...]:
        for path in td.want.names:
            value = layout.texts.get(path)
            if isinstance(value, tuple):
                return value
        raise self._fail(
            f"{td.topic} ({td.type_name}) has no joint-name field ({' or '.join(td.want.names)})"
        )


def _rows(u8: NDArray[np.uint8], starts: NDArray[np.int64], size: int) -> NDArray[np.uint8]:
    """Copy ``size`` bytes at each start into an (N, size) matrix.

    Rows of a read-only strided view are gathered whole (one memcpy each), which
    is some 40x faster than gathering every byte with its own index.
    """
    windows = np.lib.stride_tricks.as_strided(
        u8, shape=(u8.size - size + 1, size), strides=(1, 1), writeable=False
    )
    return windows[starts]


def _gather_u64(u8: NDArray[np.uint8], offsets: NDArray[np.int64]) -> NDArray[np.uint64]:
    return _rows(u8, offsets, 8).view("<u8").reshape(-1)


def _column_view(layout: MessageLayout, matrix: NDArray[np.uint8], path: str) -> NDArray[Any]:
    off, dtype, count = layout.leaves[path]
    size = int(dtype[2])
    block = np.ascontiguousarray(matrix[:, off : off + size * count])
    return block.view(dtype).reshape(matrix.shape[0], count)


def _stamp_ns(layout: MessageLayout, matrix: NDArray[np.uint8]) -> NDArray[np.int64]:
    sec = _column_view(layout, matrix, _STAMP_SEC)[:, 0].astype(np.int64)
    nsec = _column_view(layout, matrix, _STAMP_NSEC)[:, 0].astype(np.int64)
    return sec * 1_000_000_000 + nsec


def _leaf_matrix(
    layout: MessageLayout,
    matrix: NDArray[np.uint8],
    aliases: tuple[str, ...],
    td: _TopicData,
    scan: _McapScan,
) -> F64:
    n_joints = len(td.names or ())
    for path in aliases:
        if path in layout.leaves:
            _, _, count = layout.leaves[path]
            if count == 0:
                continue
            if count != n_joints:
                raise scan._fail(f"{td.topic}: {path} has {count} values for {n_joints} joints")
            return _column_view(layout, matrix, path).astype(np.float64)
    # An empty or absent optional array (e.g. no commanded effort): NaN, not a crash.
    return np.full((matrix.shape[0], n_joints), np.nan)


# --- building the recording ---------------------------------------------------------------


def _concat(td: _TopicData) -> tuple[NDArray[np.int64], dict[str, F64]]:
    stamps = np.concatenate(td.stamps)
    arrays = {k: np.concatenate(v) for k, v in td.arrays.items()}
    if stamps.size > 1 and not (np.diff(stamps) > 0).all():
        order = np.argsort(stamps, kind="stable")
        stamps = stamps[order]
        arrays = {k: v[order] for k, v in arrays.items()}
    return stamps, arrays


_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"
_POINT = "trajectory_msgs/msg/JointTrajectoryPoint"
_POINT_SHAPE = (
    ("positions", "float64", -1),
    ("velocities", "float64", -1),
    ("accelerations", "float64", -1),
    ("effort", "float64", -1),
    ("time_from_start", "builtin_interfaces/msg/Duration", None),
)


def _trajectory_walk(data: bytes) -> tuple[tuple[str, ...], list[float], list[F64], list[F64]]:
    """Decode a JointTrajectory directly: the generic walker costs ~10 us per point.

    Only used when the schema has the standard field order (checked by the caller).
    """
    if len(data) < 4 or data[1] not in (0, 1):
        raise ValueError("bad CDR encapsulation header")
    e = "<" if data[1] == 1 else ">"
    u32 = struct.Struct(e + "I").unpack_from
    dur = struct.Struct(e + "iI").unpack_from
    f8 = np.dtype(e + "f8")
    pos = 4

    def align(p: int, a: int) -> int:
        return 4 + ((p - 4 + a - 1) // a) * a

    def string(p: int) -> tuple[str, int]:
        p = align(p, 4)
        (n,) = u32(data, p)
        if p + 4 + n > len(data):
            raise ValueError("string runs past the message")
        return data[p + 4 : p + 4 + n].rstrip(b"\x00").decode("utf-8", "replace"), p + 4 + n

    pos = align(pos, 4) + 8  # header.stamp
    _, pos = string(pos)  # header.frame_id
    pos = align(pos, 4)
    (count,) = u32(data, pos)
    pos += 4
    names = []
    for _ in range(count):
        name, pos = string(pos)
        names.append(name)
    pos = align(pos, 4)
    (n_points,) = u32(data, pos)
    pos += 4
    times: list[float] = []
    arrays: list[list[F64]] = [[], []]
    for _ in range(n_points):
        for k in range(4):
            pos = align(pos, 4)
            (m,) = u32(data, pos)
            pos += 4
            if m:
                pos = align(pos, 8)
            values = np.frombuffer(data, dtype=f8, count=m, offset=pos)
            pos += 8 * m
            if k < 2:
                arrays[k].append(values)
        pos = align(pos, 4)
        sec, nsec = dur(data, pos)
        pos += 8
        times.append(sec + nsec * 1e-9)
    return tuple(names), times, arrays[0], arrays[1]


def _planned(scan: _McapScan) -> PlannedTrajectory | None:
    entry = scan.singles.get(TOPIC_PLANNED_TRAJECTORY)
    if entry is None:
        return None
    cid, data = entry
    name, types = scan.types_of(scan.channels[cid])
    standard = [(f.name, f.base, f.array) for f in types.get(_POINT, ())] == list(_POINT_SHAPE)
    standard = standard and [f.name for f in types.get(name, ())] == [
        "header",
        "joint_names",
        "points",
    ]
    try:
        if name == _TRAJECTORY and standard:
            joints, times, pos, vel = _trajectory_walk(data)
        else:
            joints, times, pos, vel = _trajectory_generic(types, name, data)
    except (ValueError, struct.error, KeyError) as err:
        raise scan._fail(f"corrupt: {TOPIC_PLANNED_TRAJECTORY} cannot be decoded ({err})") from err
    n = len(joints)
    shape = (len(times), n)
    return PlannedTrajectory(
        joint_names=joints,
        times_s=np.asarray(times, dtype=float),
        positions=np.asarray(
            [q if q.size == n else np.full(n, np.nan) for q in pos], dtype=float
        ).reshape(shape),
        velocities=np.asarray(
            [v if v.size == n else np.full(n, np.nan) for v in vel], dtype=float
        ).reshape(shape),
    )


def _trajectory_generic(
    types: MsgTypes, name: str, data: bytes
) -> tuple[tuple[str, ...], list[float], list[F64], list[F64]]:
    lay = message_layout(types, name, data)
    names = lay.texts.get("joint_names", ())
    joints = tuple(names) if isinstance(names, tuple) else ()
    times, pos, vel = [], [], []
    k = 0
    while f"points[{k}].positions" in lay.leaves:
        p = f"points[{k}]."
        sec = float(lay.values(data, p + "time_from_start.sec")[0])
        nsec = float(lay.values(data, p + "time_from_start.nanosec")[0])
        times.append(sec + nsec * 1e-9)
        pos.append(lay.values(data, p + "positions").astype(float))
        vel.append(lay.values(data, p + "velocities").astype(float))
        k += 1
    return joints, times, pos, vel


def _robot_description(scan: _McapScan) -> str | None:
    entry = scan.singles.get(TOPIC_ROBOT_DESCRIPTION)
    if entry is None:
        return None
    cid, data = entry
    name, types = scan.types_of(scan.channels[cid])
    try:
        value = message_layout(types, name, data).texts.get("data")
    except (ValueError, struct.error) as err:
        raise scan._fail(f"corrupt: {TOPIC_ROBOT_DESCRIPTION} cannot be decoded ({err})") from err
    return value if isinstance(value, str) else None


def _match_stamps(
    js_t: NDArray[np.int64], cs_t: NDArray[np.int64]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Row pairs (joint_states, controller_state) at the same instant (nearest, < half a period)."""
    if js_t.shape == cs_t.shape and np.array_equal(js_t, cs_t):
        idx = np.arange(js_t.size)
        return idx, idx
    period = float(np.median(np.diff(js_t))) if js_t.size > 1 else 1.0
    j = np.searchsorted(cs_t, js_t).clip(1, max(cs_t.size - 1, 1))
    left = (j - 1).clip(0, cs_t.size - 1)
    right = j.clip(0, cs_t.size - 1)
    pick = np.where(np.abs(cs_t[left] - js_t) <= np.abs(cs_t[right] - js_t), left, right)
    ok = np.abs(cs_t[pick] - js_t) <= period / 2
    return np.flatnonzero(ok), pick[ok]


def read_recording(source: Path) -> Recording:
    """Read one recording (rosbag2 directory or bare ``.mcap``) into a :class:`Recording`.

    Times (``time_s``) count from the recording's first control-rate stamp, so header
    stamps may be simulated (from 0) or wall clock alike; ``stamp_ns`` stays as recorded.
    NaN values and empty arrays (legal in ROS messages) become nulls: "not recorded".

    Raises:
        RecordingError: missing, empty, not MCAP, truncated, corrupt (CRC), lacking
            ``/joint_states`` / ``/controller_state`` messages or a field the report
            needs; any other failure while decoding is wrapped into one, naming the file.
    """
    source = Path(source)
    try:
        mcap_path = _mcap_file_of(source)
    except OSError as err:
        raise RecordingError(f"{source}: cannot read ({err.strerror or err})") from err
    try:
        return _read(source, mcap_path)
    except RecordingError:
        raise
    except Exception as err:  # the boundary: nothing else may escape a per-recording read
        raise RecordingError(
            f"{mcap_path}: cannot decode the recording: {type(err).__name__}: {err}"
        ) from err


def _missing_array_notes(arrays: dict[str, F64], topic: str, fields: dict[str, str]) -> list[str]:
    """Notes for optional arrays that are empty (or NaN) in every message of ``topic``."""
    notes = []
    for key, what in fields.items():
        values = arrays.get(key)
        if values is not None and values.size and np.isnan(values).all():
            notes.append(f"{topic} carries no {what} values (empty arrays): {what} metrics are n/a")
    return notes


def _read(source: Path, mcap_path: Path) -> Recording:
    scan = _McapScan(mcap_path)
    scan.run()
    present = {c.topic for c in scan.channels.values()}
    for topic in REQUIRED_TOPICS:
        if scan.topic_counts.get(topic, 0) == 0:
            what = "no messages on" if topic in present else "lacks the topic"
            shown = ", ".join(sorted(present)) or "none"
            raise RecordingError(f"{mcap_path}: {what} {topic} (topics present: {shown})")
    by_topic = {td.topic: td for td in scan.topic_data.values() if td is not None}
    js, cs = by_topic[TOPIC_JOINT_STATES], by_topic[TOPIC_CONTROLLER_STATE]
    js_t, js_a = _concat(js)
    cs_t, cs_a = _concat(cs)
    names = tuple(js.names or ())
    cs_names = tuple(cs.names or ())
    if sorted(names) != sorted(cs_names):
        raise RecordingError(
            f"{mcap_path}: joints differ between {TOPIC_JOINT_STATES} ({', '.join(names)}) "
            f"and {TOPIC_CONTROLLER_STATE} ({', '.join(cs_names)})"
        )
    perm = [cs_names.index(n) for n in names]
    rows_js, rows_cs = _match_stamps(js_t, cs_t)
    if rows_js.size == 0:
        raise RecordingError(
            f"{mcap_path}: no {TOPIC_CONTROLLER_STATE} message shares a time stamp with "
            f"{TOPIC_JOINT_STATES}"
        )
    notes: list[str] = []
    dropped = js_t.size - rows_js.size
    if dropped:
        notes.append(f"{dropped} joint-state samples without a controller state were dropped")
    notes += _missing_array_notes(
        js_a, TOPIC_JOINT_STATES, {"velocity": "velocity", "effort": "effort"}
    )

    raw_meta = scan.metadata.get(METADATA_EPISODE, {})
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
    elif METADATA_EPISODE not in scan.metadata:
        notes.append(
            f"no '{METADATA_EPISODE}' metadata record: episode name from the file name, "
            "settings n/a"
        )

    # Relative times: wall-clock header stamps (1.7e9 s) would otherwise swamp float64
    # resolution and put the motion end (a duration from the start) 50 years early.
    t0_ns = int(min(js_t[0], cs_t[0]))
    n = len(names)
    episode = _episode_name(raw_meta, source)

    def flat(a: F64) -> F64:
        return np.ascontiguousarray(a).reshape(-1)

    def tidy(stamps: NDArray[np.int64], columns: dict[str, F64]) -> pl.DataFrame:
        m = stamps.size
        frame = pl.DataFrame(
            {
                "stamp_ns": np.repeat(stamps, n),
                "time_s": np.repeat((stamps - t0_ns).astype(np.float64) * 1e-9, n),
                "joint": pl.Series("joint", names, dtype=pl.String).gather(
                    np.tile(np.arange(n, dtype=np.int64), m)
                ),
                **{k: flat(v) for k, v in columns.items()},
            }
        )
        return frame.select(
            pl.lit(episode, dtype=pl.String).alias("episode"),
            pl.col("stamp_ns", "time_s", "joint"),
            pl.col(*columns).fill_nan(None),
        )

    cs_all = {k: v[:, perm] for k, v in cs_a.items()}
    # error = reference - feedback: whichever of the two the controller left out.
    error = np.where(
        np.isnan(cs_all["error"]),
        cs_all["reference_position"] - cs_all["feedback_position"],
        cs_all["error"],
    )
    feedback = np.where(
        np.isnan(cs_all["feedback_position"]),
        cs_all["reference_position"] - error,
        cs_all["feedback_position"],
    )
    truth_pos = np.full_like(cs_all["reference_position"], np.nan)
    truth_vel = np.full_like(cs_all["reference_position"], np.nan)
    truth = by_topic.get(TOPIC_GROUND_TRUTH)
    if truth is not None and truth.count:
        gt_t, gt_a = _concat(truth)
        gt_names = tuple(truth.names or ())
        if sorted(gt_names) != sorted(names):
            raise RecordingError(
                f"{mcap_path}: joints differ between {TOPIC_GROUND_TRUTH} "
                f"({', '.join(gt_names)}) and {TOPIC_JOINT_STATES} ({', '.join(names)})"
            )
        gt_perm = [gt_names.index(n) for n in names]
        rows_cs_gt, rows_gt = _match_stamps(cs_t, gt_t)
        truth_pos[rows_cs_gt] = gt_a["position"][rows_gt][:, gt_perm]
        truth_vel[rows_cs_gt] = gt_a["velocity"][rows_gt][:, gt_perm]
        if rows_cs_gt.size < cs_t.size:
            notes.append(
                f"{cs_t.size - rows_cs_gt.size} {TOPIC_CONTROLLER_STATE} samples have no "
                f"{TOPIC_GROUND_TRUTH} sample at their time"
            )
    cs_rows = {k: v[rows_cs] for k, v in cs_all.items()}
    samples = tidy(
        js_t[rows_js],
        {
            "position_rad": js_a["position"][rows_js],
            "velocity_rad_s": js_a["velocity"][rows_js],
            "effort_nm": js_a["effort"][rows_js],
            "reference_position_rad": cs_rows["reference_position"],
            "reference_velocity_rad_s": cs_rows["reference_velocity"],
            "error_rad": error[rows_cs],
            "commanded_effort_nm": cs_rows["commanded_effort"],
            "true_position_rad": truth_pos[rows_cs],
            "true_velocity_rad_s": truth_vel[rows_cs],
        },
    )
    controller_states = tidy(
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
    )
    return Recording(
        source=source,
        mcap_path=mcap_path,
        sha256=scan.sha.hexdigest(),
        size_bytes=scan.size,
        metadata=raw_meta,
        settings=settings,
        joint_names=names,
        samples=samples,
        controller_states=controller_states,
        planned=_planned(scan),
        robot_description=_robot_description(scan),
        topic_counts=dict(scan.topic_counts),
        decoded_messages=js.count + cs.count + (truth.count if truth is not None else 0),
        notes=tuple(notes),
        has_ground_truth=truth is not None and truth.count > 0,
    )
