"""Write one episode as a rosbag2 directory: ``metadata.yaml`` + one MCAP file (ROS 2 profile).

Layout (what ``ros2 bag record -s mcap`` produces, so ``ros2 bag info/play``, Foxglove,
PlotJuggler, ``rosbags`` and ``mcap_ros2`` open it)::

    <bag_dir>/metadata.yaml       rosbag2 metadata, version 8, custom_data = episode settings
    <bag_dir>/<name>_0.mcap       profile "ros2", ros2msg schemas, CDR messages, zstd chunks

We write the MCAP records ourselves instead of going through ``mcap.writer.Writer``: its
``add_message`` builds a dataclass and several ``struct.pack`` calls per message (see
``benches/log_encode.py``), which alone exceeds the logging budget of a 1 kHz episode. Here
all messages of a topic are encoded at once (:mod:`pipeline.log.cdr`), their 31-byte message
record headers are filled with numpy, and a chunk is one ``bytes.join`` of slices. The file is
a complete, indexed MCAP: chunk CRCs, message indexes, chunk/metadata indexes, statistics,
summary offsets, data-section and summary CRCs, validated in tests by the ``mcap`` reader.

Metadata version 8 (Iron's layout: QoS profiles as a YAML string with enum numbers,
``type_description_hash``, ``custom_data``, ``ros_distro``) is the newest one that every LTS
reader accepts: Humble reads the QoS string and ignores the keys it does not know, Jazzy
reads version 8 alongside its own version 9 (where QoS became a YAML list Humble cannot read).

Crash safety: the directory is built under ``.<name>.partial-<pid>`` next to the final name,
fsynced, then renamed into place, so a killed run never leaves a partial bag under a final name
(readers skip dot-directories, and the next write of that name removes stale partial
directories of dead processes). With ``force`` the old bag is swapped out atomically
(``renameat2(RENAME_EXCHANGE)`` where the kernel and file system support it) and then deleted.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import itertools
import json
import math
import os
import re
import shutil
import struct
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Literal

import numpy as np
import yaml
import zstandard
from numpy.typing import NDArray

from pipeline.constants import (
    METADATA_EPISODE,
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
    TOPIC_PLANNED_TRAJECTORY,
    TOPIC_ROBOT_DESCRIPTION,
    TOPIC_TF,
    TYPE_CONTROLLER_STATE,
    TYPE_JOINT_STATE,
    TYPE_JOINT_TRAJECTORY,
    TYPE_STRING,
    TYPE_TF,
)
from pipeline.errors import RecordingError
from pipeline.log import cdr
from pipeline.log.schemas import (
    MESSAGE_ENCODING,
    QOS_LATCHED,
    QOS_STREAM,
    QOS_TF,
    ROS_DISTRO,
    SCHEMA_ENCODING,
    TYPE_HASHES,
    Qos,
    full_definition,
)
from pipeline.model import transforms
from pipeline.model.frames import tf_edges
from pipeline.robots.spec import RobotSpec
from pipeline.sim.result import EpisodeResult, TrajectorySamples

METADATA_FILE = "metadata.yaml"
METADATA_VERSION = 8
REQUIRED_METADATA_KEYS = ("episode", "scenario", "controller", "robot", "seed", "settings")

MCAP_MAGIC = b"\x89MCAP0\r\n"
MCAP_PROFILE = "ros2"
# Constant on purpose: no version or host in the file, so equal inputs give equal bytes.
MCAP_LIBRARY = "armlab-pipeline"

# ~256 KiB of uncompressed records per chunk: at 1 kHz with full logging (about 1 KiB of
# JointState + controller state per step for 6 joints) that is ~0.25 s of sim time, so a reader
# seeking to an instant decompresses little and a damaged chunk loses little, while zstd still
# sees enough repetition (joint names, templates) to compress ~10x.
CHUNK_BYTES = 256 * 1024
# zstd rather than lz4: both are in the MCAP spec and every reader (mcap, rosbag2, Foxglove,
# rosbags); zstd compresses these repetitive CDR records much better and at level 1 still runs
# at several hundred MB/s. Output is deterministic for a given zstd version and level.
ZSTD_LEVEL = 1

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_MESSAGE_INDEX, _OP_CHUNK_INDEX, _OP_STATISTICS, _OP_METADATA = 7, 8, 11, 12
_OP_METADATA_INDEX, _OP_SUMMARY_OFFSET, _OP_DATA_END = 13, 14, 15

# Message record header: opcode, record length, channel id, sequence, log time, publish time.
_MESSAGE_HEADER = np.dtype(
    [
        ("opcode", "u1"),
        ("length", "<u8"),
        ("channel_id", "<u2"),
        ("sequence", "<u4"),
        ("log_time", "<u8"),
        ("publish_time", "<u8"),
    ]
)
assert _MESSAGE_HEADER.itemsize == 31


@dataclass(frozen=True)
class Topic:
    """A recorded topic: name, ROS type and the QoS its publisher offered."""

    name: str
    type: str
    qos: Qos


# Order = channel ids 1.. and the order of messages that share a log time.
TOPICS: tuple[Topic, ...] = (
    Topic(TOPIC_ROBOT_DESCRIPTION, TYPE_STRING, QOS_LATCHED),
    Topic(TOPIC_PLANNED_TRAJECTORY, TYPE_JOINT_TRAJECTORY, QOS_LATCHED),
    Topic(TOPIC_JOINT_STATES, TYPE_JOINT_STATE, QOS_STREAM),
    Topic(TOPIC_CONTROLLER_STATE, TYPE_CONTROLLER_STATE, QOS_STREAM),
    Topic(TOPIC_TF, TYPE_TF, QOS_TF),
    Topic(TOPIC_GROUND_TRUTH, TYPE_JOINT_STATE, QOS_STREAM),
)


@dataclass(frozen=True)
class MessageBlock:
    """Messages of one topic: row k of ``payload`` (CDR bytes) is logged at ``log_time_ns[k]``."""

    topic: str
    log_time_ns: NDArray[np.int64]
    payload: NDArray[np.uint8]


@dataclass(frozen=True)
class BagSummary:
    """What :func:`write_episode_bag` wrote.

    Attributes:
        path: the bag directory.
        mcap_path: its MCAP file.
        message_counts: messages per topic.
        size_bytes: bytes of the MCAP file plus metadata.yaml.
        start_ns: first log time [ns] (simulated time).
        duration_ns: last minus first log time [ns].
    """

    path: Path
    mcap_path: Path
    message_counts: Mapping[str, int]
    size_bytes: int
    start_ns: int
    duration_ns: int


# --- public entry point -------------------------------------------------------------------


def write_episode_bag(
    bag_dir: Path,
    *,
    spec: RobotSpec,
    result: EpisodeResult,
    planned: TrajectorySamples,
    metadata: Mapping[str, str],
    motion_start_ns: int = 0,
    joint_state_decimation: int = 1,
    tf_rate_hz: float = 50.0,
    tf_source: Literal["measured", "true"] = "measured",
    force: bool = False,
) -> BagSummary:
    """Record an episode as a rosbag2 directory (MCAP storage), atomically.

    Args:
        bag_dir: directory to create; its parent is created if missing.
        spec: the robot (URDF for /robot_description, frames for /tf).
        result: the episode; its ``stamp_ns`` become log times and header stamps.
        planned: the planned trajectory, published once on /planned_trajectory, its header
            stamped ``motion_start_ns`` after the first stamp (when the motion starts).
        motion_start_ns: the pre-roll: time from the first stamp to the motion start [ns].
        metadata: episode settings as strings; must hold REQUIRED_METADATA_KEYS, and
            "settings" must be JSON. Stored as the MCAP metadata record "armlab.episode" and
            as metadata.yaml ``custom_data``.
        joint_state_decimation: publish /joint_states every k-th control step.
        tf_rate_hz: /tf publication rate [Hz] (sampled from the control steps).
        tf_source: joint positions /tf is computed from: "measured" (as
            robot_state_publisher would from /joint_states) or "true" (noise-free plant).
        force: replace an existing recording at ``bag_dir``.

    Raises:
        RecordingError: ``bag_dir`` exists without ``force``, or inputs are inconsistent.
    """
    bag_dir = Path(bag_dir)
    if os.path.lexists(bag_dir) and not force:
        raise RecordingError(f"{bag_dir}: recording already exists; use --force to overwrite it")
    meta = _check_metadata(metadata)
    blocks = encode_episode(
        spec,
        result,
        planned,
        motion_start_ns=motion_start_ns,
        joint_state_decimation=joint_state_decimation,
        tf_rate_hz=tf_rate_hz,
        tf_source=tf_source,
    )
    return _write_bag_dir(bag_dir, blocks, meta, force=force)


# --- episode -> messages ------------------------------------------------------------------


def encode_episode(
    spec: RobotSpec,
    result: EpisodeResult,
    planned: TrajectorySamples,
    *,
    motion_start_ns: int = 0,
    joint_state_decimation: int = 1,
    tf_rate_hz: float = 50.0,
    tf_source: Literal["measured", "true"] = "measured",
) -> list[MessageBlock]:
    """All messages of an episode, CDR-encoded, one block per topic in :data:`TOPICS` order.

    Log times and header stamps are the simulated ``result.stamp_ns``; /robot_description
    and /planned_trajectory are logged once at the first stamp. /controller_state fills every
    field of the Jazzy message: ``reference`` = q_ref, qd_ref, qdd_ref; ``feedback`` = measured
    q, qd; ``error`` = reference - feedback (positions, velocities); ``output.effort`` = the
    commanded effort; each point's ``time_from_start`` = time since the episode start (where
    the planned trajectory starts); unused sequences and the ``multi_dof_*`` fields are empty.
    /joint_states carries the measured q, qd and the applied effort ``tau_nm``;
    /ground_truth/joint_states the plant's true q, qd (no sensor noise) and the same
    effort, at every control step (the report's tracking metrics use it).
    """
    stamps, arrays = _check_result(spec, result)
    if not isinstance(joint_state_decimation, int | np.integer) or joint_state_decimation < 1:
        raise RecordingError(
            f"joint_state_decimation: {joint_state_decimation!r}, expected an integer >= 1"
        )
    if not (math.isfinite(tf_rate_hz) and tf_rate_hz > 0):
        raise RecordingError(f"tf_rate_hz: {tf_rate_hz!r}, expected a positive rate [Hz]")
    if tf_source not in ("measured", "true"):
        raise RecordingError(f"tf_source: {tf_source!r}, expected 'measured' or 'true'")
    # Imported here: the URDF module pulls in Pinocchio, which readers of pipeline.log skip.
    from pipeline.model.urdf import build_urdf

    names = spec.joint_names
    t0 = int(stamps[0]) if stamps.size else 0
    t0_arr = np.array([t0], dtype=np.int64)

    def one(topic: str, payload: bytes) -> MessageBlock:
        return MessageBlock(topic, t0_arr, np.frombuffer(payload, np.uint8).reshape(1, -1))

    blocks = [
        one(TOPIC_ROBOT_DESCRIPTION, cdr.encode_string(build_urdf(spec))),
        one(TOPIC_PLANNED_TRAJECTORY, _encode_planned(names, t0 + int(motion_start_ns), planned)),
    ]

    js = slice(None, None, int(joint_state_decimation))
    blocks.append(
        MessageBlock(
            TOPIC_JOINT_STATES,
            stamps[js],
            cdr.encode_joint_states(
                names,
                stamps[js],
                position=arrays["q"][js],
                velocity=arrays["qd"][js],
                effort=arrays["tau_nm"][js],
            ),
        )
    )

    q, qd, q_ref, qd_ref = arrays["q"], arrays["qd"], arrays["q_ref"], arrays["qd_ref"]
    blocks.append(
        MessageBlock(
            TOPIC_CONTROLLER_STATE,
            stamps,
            cdr.encode_controller_states(
                names,
                stamps,
                reference=(q_ref, qd_ref, arrays["qdd_ref"]),
                feedback=(q, qd),
                error=(q_ref - q, qd_ref - qd),
                output_effort=arrays["tau_cmd_nm"],
                time_from_start_ns=stamps - t0,
            ),
        )
    )

    blocks_truth = MessageBlock(
        TOPIC_GROUND_TRUTH,
        stamps,
        cdr.encode_joint_states(
            names,
            stamps,
            position=arrays["q_true"],
            velocity=arrays["qd_true"],
            effort=arrays["tau_nm"],
        ),
    )

    idx = tf_sample_indices(stamps, tf_rate_hz)
    q_tf = (arrays["q"] if tf_source == "measured" else arrays["q_true"])[idx]
    frames, translation, rotation = tf_poses(spec, q_tf)
    blocks.append(
        MessageBlock(
            TOPIC_TF,
            stamps[idx],
            cdr.encode_tf(frames, stamps[idx], translation=translation, rotation_xyzw=rotation),
        )
    )
    blocks.append(blocks_truth)
    return blocks


def tf_sample_indices(stamp_ns: NDArray[np.int64], rate_hz: float) -> NDArray[np.intp]:
    """Control steps at which /tf is published: the first step at or after each tick of a
    ``rate_hz`` clock started at the first stamp (every step if the control rate is lower)."""
    if stamp_ns.size == 0:
        return np.zeros(0, dtype=np.intp)
    period_ns = max(1, round(1e9 / rate_hz))
    ticks = np.arange(int(stamp_ns[0]), int(stamp_ns[-1]) + 1, period_ns, dtype=np.int64)
    return np.unique(np.searchsorted(stamp_ns, ticks, side="left"))


def tf_poses(
    spec: RobotSpec, q: NDArray[np.float64]
) -> tuple[list[tuple[str, str]], NDArray[np.float64], NDArray[np.float64]]:
    """URDF link transforms for M joint configurations, vectorized.

    Every revolute edge of :func:`pipeline.model.frames.tf_edges` is a constant transform
    followed by Rz(q_i) (the flange edge is constant), so the translation is constant and the
    rotation quaternion is the constant one times (cos(q/2), 0, 0, sin(q/2)). The factorization
    is checked against ``tf_edges`` at a probe configuration.

    Returns:
        (parent, child) frame pairs; (M, E, 3) translations [m]; (M, E, 4) quaternions
        (x, y, z, w) with w >= 0.
    """
    dof = spec.dof
    base = tf_edges(spec, np.zeros(dof))
    probe_q = np.linspace(0.3, 1.3, dof)
    for i, (edge0, edge) in enumerate(zip(base, tf_edges(spec, probe_q), strict=True)):
        joint = transforms.rot_z(probe_q[i]) if i < dof else np.eye(4)
        if not np.allclose(edge0.parent_T_child @ joint, edge.parent_T_child, atol=1e-12):
            raise AssertionError("tf_edges is no longer constant @ Rz(q_i); update tf_poses")
    frames = [(e.parent, e.child) for e in base]
    m, edges = q.shape[0], len(base)
    translation = np.empty((m, edges, 3))
    quat_wxyz = np.empty((m, edges, 4))
    for i, edge in enumerate(base):
        translation[:, i, :] = edge.parent_T_child[:3, 3]
        w1, x1, y1, z1 = transforms.quat_wxyz(edge.parent_T_child[:3, :3])
        if i < dof:
            c, s = np.cos(0.5 * q[:, i]), np.sin(0.5 * q[:, i])
            quat_wxyz[:, i] = np.stack(
                [w1 * c - z1 * s, x1 * c + y1 * s, y1 * c - x1 * s, z1 * c + w1 * s], axis=1
            )
        else:
            quat_wxyz[:, i] = (w1, x1, y1, z1)
    quat_wxyz *= np.where(quat_wxyz[..., :1] < 0, -1.0, 1.0)
    return frames, translation, quat_wxyz[..., [1, 2, 3, 0]]


def _encode_planned(names: tuple[str, ...], t0_ns: int, planned: TrajectorySamples) -> bytes:
    n = len(names)
    times = np.asarray(planned.times_s, dtype=float).reshape(-1)
    k = times.size
    for field in ("positions", "velocities", "accelerations"):
        shape = np.shape(getattr(planned, field))
        if shape != (k, n):
            raise RecordingError(f"planned.{field}: shape {shape}, expected {(k, n)}")
    if k == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) < 0) or times[0] < 0:
        raise RecordingError("planned.times_s: expected >= 1 finite, non-decreasing times >= 0")
    return cdr.encode_joint_trajectory(
        names,
        t0_ns,
        time_from_start_ns=np.round(times * 1e9).astype(np.int64),
        positions=planned.positions,
        velocities=planned.velocities,
        accelerations=planned.accelerations,
    )


def _check_result(
    spec: RobotSpec, result: EpisodeResult
) -> tuple[NDArray[np.int64], dict[str, NDArray[np.float64]]]:
    if tuple(result.joint_names) != spec.joint_names:
        raise RecordingError(
            f"result.joint_names {list(result.joint_names)} differ from robot "
            f"{spec.name!r} joints {list(spec.joint_names)}"
        )
    stamps = np.asarray(result.stamp_ns)
    if stamps.ndim != 1 or not np.issubdtype(stamps.dtype, np.integer):
        raise RecordingError(f"result.stamp_ns: expected (N,) integers, got {stamps.dtype}")
    stamps = stamps.astype(np.int64)
    if stamps.size and (stamps[0] < 0 or np.any(np.diff(stamps) <= 0)):
        raise RecordingError("result.stamp_ns: expected strictly increasing times >= 0 [ns]")
    shape = (stamps.size, spec.dof)
    arrays = {}
    for field in ("q", "qd", "q_true", "qd_true", "q_ref", "qd_ref", "qdd_ref"):
        arrays[field] = np.asarray(getattr(result, field), dtype=np.float64)
    arrays["tau_cmd_nm"] = np.asarray(result.tau_cmd_nm, dtype=np.float64)
    arrays["tau_nm"] = np.asarray(result.tau_nm, dtype=np.float64)
    for field, arr in arrays.items():
        if arr.shape != shape:
            raise RecordingError(f"result.{field}: shape {arr.shape}, expected {shape}")
    return stamps, arrays


def _check_metadata(metadata: Mapping[str, str]) -> dict[str, str]:
    bad = [k for k, v in metadata.items() if not (isinstance(k, str) and isinstance(v, str))]
    if bad:
        raise RecordingError(f"metadata: keys and values must be strings (not at {bad})")
    missing = [k for k in REQUIRED_METADATA_KEYS if k not in metadata]
    if missing:
        raise RecordingError(
            f"metadata: missing {missing}; required keys: {list(REQUIRED_METADATA_KEYS)}"
        )
    try:
        json.loads(metadata["settings"])
    except ValueError as err:
        raise RecordingError(f"metadata['settings']: not valid JSON ({err})") from err
    return {k: metadata[k] for k in sorted(metadata)}


# --- MCAP ---------------------------------------------------------------------------------


def _str(text: str) -> bytes:
    data = text.encode("utf-8")
    return struct.pack("<I", len(data)) + data


def _map(items: Mapping[str, str]) -> bytes:
    body = b"".join(_str(k) + _str(v) for k, v in items.items())
    return struct.pack("<I", len(body)) + body


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


class _Output:
    """A binary stream that tracks its position and the CRC32 of everything written."""

    def __init__(self, stream: BinaryIO) -> None:
        self.stream = stream
        self.pos = 0
        self.crc = 0

    def write(self, data: bytes) -> None:
        self.stream.write(data)
        self.crc = zlib.crc32(data, self.crc)
        self.pos += len(data)


@dataclass(frozen=True)
class McapStats:
    """Per-topic message counts and the log-time range of an MCAP file [ns]."""

    message_counts: dict[str, int]
    start_ns: int
    end_ns: int


def write_mcap(
    stream: BinaryIO,
    blocks: Sequence[MessageBlock],
    *,
    metadata: Mapping[str, str],
    chunk_bytes: int = CHUNK_BYTES,
) -> McapStats:
    """Write a complete, indexed ROS 2 MCAP file of ``blocks`` (topics of :data:`TOPICS`).

    Messages are stored in log-time order (ties in :data:`TOPICS` order); a chunk holds the
    messages whose record starts within its ``chunk_bytes`` window of the record stream.
    """
    topics = [t for t in TOPICS if any(b.topic == t.name for b in blocks)]
    channel_of = {t.name: i + 1 for i, t in enumerate(topics)}
    schema_of = {name: i + 1 for i, name in enumerate(dict.fromkeys(t.type for t in topics))}
    rank = {t.name: i for i, t in enumerate(TOPICS)}
    blocks = sorted(blocks, key=lambda b: rank[b.topic])

    out = _Output(stream)
    out.write(MCAP_MAGIC)
    out.write(_record(_OP_HEADER, _str(MCAP_PROFILE) + _str(MCAP_LIBRARY)))

    schema_records = [
        _record(
            _OP_SCHEMA,
            struct.pack("<H", sid)
            + _str(type_name)
            + _str(SCHEMA_ENCODING)
            + _str_bytes(full_definition(type_name).encode()),
        )
        for type_name, sid in schema_of.items()
    ]
    channel_records = [
        _record(
            _OP_CHANNEL,
            struct.pack("<HH", channel_of[t.name], schema_of[t.type])
            + _str(t.name)
            + _str(MESSAGE_ENCODING)
            + _map(
                {"offered_qos_profiles": t.qos.to_yaml(), "topic_type_hash": TYPE_HASHES[t.type]}
            ),
        )
        for t in topics
    ]
    for rec in (*schema_records, *channel_records):
        out.write(rec)
    metadata_offset = out.pos
    metadata_record = _record(_OP_METADATA, _str(METADATA_EPISODE) + _map(metadata))
    out.write(metadata_record)

    chunk_indexes, counts, start_ns, end_ns = _write_chunks(out, blocks, channel_of, chunk_bytes)
    out.write(_record(_OP_DATA_END, struct.pack("<I", out.crc)))

    # Summary section: repeated schemas/channels, statistics, indexes; then their offsets.
    summary_start = out.pos
    statistics = _record(
        _OP_STATISTICS,
        struct.pack(
            "<QHIIIIQQ",
            sum(counts.values()),
            len(schema_of),
            len(channel_of),
            0,  # attachments
            1,  # metadata records
            len(chunk_indexes),
            start_ns,
            end_ns,
        )
        + _u16_u64_map({channel_of[t]: n for t, n in counts.items()}),
    )
    metadata_index = _record(
        _OP_METADATA_INDEX,
        struct.pack("<QQ", metadata_offset, len(metadata_record)) + _str(METADATA_EPISODE),
    )
    groups = [
        (_OP_SCHEMA, b"".join(schema_records)),
        (_OP_CHANNEL, b"".join(channel_records)),
        (_OP_STATISTICS, statistics),
        (_OP_CHUNK_INDEX, b"".join(chunk_indexes)),
        (_OP_METADATA_INDEX, metadata_index),
    ]
    summary = bytearray()
    offsets = bytearray()
    for opcode, data in groups:
        if data:
            offsets += _record(
                _OP_SUMMARY_OFFSET,
                struct.pack("<BQQ", opcode, summary_start + len(summary), len(data)),
            )
            summary += data
    summary_offset_start = summary_start + len(summary)
    summary += offsets
    footer_head = struct.pack("<BQQQ", _OP_FOOTER, 20, summary_start, summary_offset_start)
    summary_crc = zlib.crc32(footer_head, zlib.crc32(summary))
    out.write(bytes(summary) + footer_head + struct.pack("<I", summary_crc) + MCAP_MAGIC)
    return McapStats(
        {t.name: counts.get(t.name, 0) for t in topics},
        start_ns if counts else 0,
        end_ns if counts else 0,
    )


def _str_bytes(data: bytes) -> bytes:
    return struct.pack("<I", len(data)) + data


def _u16_u64_map(items: Mapping[int, int]) -> bytes:
    body = b"".join(struct.pack("<HQ", k, v) for k, v in sorted(items.items()))
    return struct.pack("<I", len(body)) + body


def _write_chunks(
    out: _Output,
    blocks: Sequence[MessageBlock],
    channel_of: Mapping[str, int],
    chunk_bytes: int,
) -> tuple[list[bytes], dict[str, int], int, int]:
    """Write message records in chunks; return chunk index records, counts, time range."""
    records: list[NDArray[np.uint8]] = []
    for b in blocks:
        n, size = b.payload.shape
        header = np.empty(n, dtype=_MESSAGE_HEADER)
        header["opcode"] = _OP_MESSAGE
        header["length"] = 2 + 4 + 8 + 8 + size
        header["channel_id"] = channel_of[b.topic]
        header["sequence"] = np.arange(n, dtype=np.uint32)
        header["log_time"] = b.log_time_ns
        header["publish_time"] = b.log_time_ns
        rec = np.empty((n, _MESSAGE_HEADER.itemsize + size), dtype=np.uint8)
        rec[:, : _MESSAGE_HEADER.itemsize] = header.view(np.uint8).reshape(
            n, _MESSAGE_HEADER.itemsize
        )
        rec[:, _MESSAGE_HEADER.itemsize :] = b.payload
        records.append(rec)
    counts = {b.topic: int(b.log_time_ns.size) for b in blocks}
    if not sum(counts.values()):
        return [], counts, 0, 0

    # Global order: by log time, then topic rank (block index), then position in the block.
    times = np.concatenate([b.log_time_ns for b in blocks]).astype(np.int64)
    block_id = np.concatenate([np.full(r.shape[0], i) for i, r in enumerate(records)])
    local = np.concatenate([np.arange(r.shape[0]) for r in records])
    order = np.lexsort((local, block_id, times))
    times, block_id, local = times[order], block_id[order], local[order]
    sizes = np.array([r.shape[1] for r in records], dtype=np.int64)[block_id]
    ends = np.cumsum(sizes)
    starts = ends - sizes
    chunk_of = starts // chunk_bytes
    bounds = [0, *(np.flatnonzero(np.diff(chunk_of)) + 1).tolist(), times.size]
    channel_ids = np.array([channel_of[b.topic] for b in blocks], dtype=np.uint16)[block_id]
    views = [memoryview(r.reshape(-1).data) for r in records]
    row_bytes = [r.shape[1] for r in records]
    compressor = zstandard.ZstdCompressor(level=ZSTD_LEVEL)

    chunk_indexes = []
    for a, z in itertools.pairwise(bounds):
        sl = slice(a, z)
        data = b"".join(
            [
                views[i][j * row_bytes[i] : (j + 1) * row_bytes[i]]
                for i, j in zip(block_id[sl].tolist(), local[sl].tolist(), strict=True)
            ]
        )
        compressed = compressor.compress(data)
        t_start, t_end = int(times[sl].min()), int(times[sl].max())
        chunk_start = out.pos
        chunk = _record(
            _OP_CHUNK,
            struct.pack("<QQQI", t_start, t_end, len(data), zlib.crc32(data))
            + _str("zstd")
            + struct.pack("<Q", len(compressed))
            + compressed,
        )
        out.write(chunk)
        index_offsets: dict[int, int] = {}
        index_start = out.pos
        offsets_in_chunk = starts[sl] - starts[a]
        for ch in np.unique(channel_ids[sl]).tolist():
            mask = channel_ids[sl] == ch
            entries = np.empty((int(mask.sum()), 2), dtype="<u8")
            entries[:, 0] = times[sl][mask]
            entries[:, 1] = offsets_in_chunk[mask]
            index_offsets[ch] = out.pos
            out.write(
                _record(
                    _OP_MESSAGE_INDEX,
                    struct.pack("<HI", ch, entries.nbytes) + entries.tobytes(),
                )
            )
        chunk_indexes.append(
            _record(
                _OP_CHUNK_INDEX,
                struct.pack("<QQQQ", t_start, t_end, chunk_start, len(chunk))
                + _u16_u64_map(index_offsets)
                + struct.pack("<Q", out.pos - index_start)
                + _str("zstd")
                + struct.pack("<QQ", len(compressed), len(data)),
            )
        )
    return chunk_indexes, counts, int(times.min()), int(times.max())


# --- metadata.yaml ------------------------------------------------------------------------


class _QuotedStr(str):
    """A string YAML writes double-quoted (like yaml-cpp does for the QoS string)."""


class _Dumper(yaml.SafeDumper):
    """Block style with indented sequences, as yaml-cpp writes rosbag2's metadata."""

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        super().increase_indent(flow, False)

    def ignore_aliases(self, data: Any) -> bool:
        return True  # repeat equal mappings instead of writing YAML anchors


_Dumper.add_representer(
    _QuotedStr,
    lambda dumper, data: dumper.represent_scalar("tag:yaml.org,2002:str", str(data), style='"'),
)


def metadata_yaml(mcap_name: str, stats: McapStats, *, custom_data: Mapping[str, str]) -> str:
    """rosbag2 ``metadata.yaml`` (version 8) text for one MCAP file."""
    duration = {"nanoseconds": stats.end_ns - stats.start_ns}
    starting = {"nanoseconds_since_epoch": stats.start_ns}
    total = sum(stats.message_counts.values())
    topics_by_name = {t.name: t for t in TOPICS}
    info: dict[str, Any] = {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": duration,
        "starting_time": starting,
        "message_count": total,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": name,
                    "type": topics_by_name[name].type,
                    "serialization_format": MESSAGE_ENCODING,
                    "offered_qos_profiles": _QuotedStr(topics_by_name[name].qos.to_yaml()),
                    "type_description_hash": TYPE_HASHES[topics_by_name[name].type],
                },
                "message_count": count,
            }
            for name, count in stats.message_counts.items()
        ],
        "compression_format": _QuotedStr(""),
        "compression_mode": _QuotedStr(""),
        "relative_file_paths": [mcap_name],
        "files": [
            {
                "path": mcap_name,
                "starting_time": starting,
                "duration": duration,
                "message_count": total,
            }
        ],
        "custom_data": dict(custom_data),
        "ros_distro": ROS_DISTRO,
    }
    text: str = yaml.dump(
        {"rosbag2_bagfile_information": info},
        Dumper=_Dumper,
        sort_keys=False,
        default_flow_style=False,
        allow_unicode=True,
        width=1 << 30,
    )
    return text


# --- safe directory writes ----------------------------------------------------------------

_AT_FDCWD = -100
_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2


def _renameat2(src: Path, dst: Path, flags: int) -> bool:
    """``renameat2(2)``; False when the platform or file system does not support ``flags``."""
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    rc = fn(_AT_FDCWD, os.fsencode(src), _AT_FDCWD, os.fsencode(dst), ctypes.c_uint(flags))
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(dst))


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale(parent: Path, name: str) -> None:
    """Delete ``.<name>.partial-<pid>`` directories left by killed writers."""
    pattern = re.compile(rf"\.{re.escape(name)}\.partial-(\d+)")
    for entry in parent.iterdir():
        match = pattern.fullmatch(entry.name)
        if match and not _pid_alive(int(match.group(1))):
            shutil.rmtree(entry, ignore_errors=True)


def _publish(tmp: Path, final: Path, *, force: bool) -> None:
    """Move the finished ``tmp`` directory to ``final`` (replacing it only with ``force``)."""
    if not os.path.lexists(final):
        if _renameat2(tmp, final, _RENAME_NOREPLACE):
            return
        if os.path.lexists(final):  # pragma: no cover - lost a race without renameat2
            raise FileExistsError(errno.EEXIST, "exists", str(final))
        os.rename(tmp, final)
        return
    if not force:
        raise RecordingError(f"{final}: recording already exists; use --force to overwrite it")
    if _renameat2(tmp, final, _RENAME_EXCHANGE):
        shutil.rmtree(tmp)  # now holds the old recording
        return
    old = final.with_name(f".{final.name}.old-{os.getpid()}")
    os.rename(final, old)
    os.rename(tmp, final)
    shutil.rmtree(old)


def _write_bag_dir(
    bag_dir: Path, blocks: Sequence[MessageBlock], metadata: Mapping[str, str], *, force: bool
) -> BagSummary:
    parent = bag_dir.parent
    parent.mkdir(parents=True, exist_ok=True)
    _remove_stale(parent, bag_dir.name)
    tmp = parent / f".{bag_dir.name}.partial-{os.getpid()}"
    if os.path.lexists(tmp):
        shutil.rmtree(tmp)
    tmp.mkdir()
    mcap_name = f"{bag_dir.name}_0.mcap"
    try:
        with open(tmp / mcap_name, "xb") as f:
            stats = write_mcap(f, blocks, metadata=metadata)
            f.flush()
            os.fsync(f.fileno())
        text = metadata_yaml(mcap_name, stats, custom_data=metadata)
        with open(tmp / METADATA_FILE, "x", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        _fsync_dir(tmp)
        size = sum(p.stat().st_size for p in tmp.iterdir())
        _publish(tmp, bag_dir, force=force)
        _fsync_dir(parent)
    except BaseException:
        with contextlib.suppress(OSError):
            shutil.rmtree(tmp)
        raise
    return BagSummary(
        path=bag_dir,
        mcap_path=bag_dir / mcap_name,
        message_counts=dict(stats.message_counts),
        size_bytes=size,
        start_ns=stats.start_ns,
        duration_ns=stats.end_ns - stats.start_ns,
    )
