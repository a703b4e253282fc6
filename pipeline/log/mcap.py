"""The MCAP container format: opcodes, records, CRCs, and a fast writer of ROS 2 files.

We write the records ourselves instead of going through ``mcap.writer.Writer``: its
``add_message`` builds a dataclass and several ``struct.pack`` calls per message (see
``benches/log_encode.py``), which alone exceeds the logging budget of a 1 kHz episode. Here
all messages of a topic come pre-encoded as a byte matrix, their 31-byte message record
headers are filled with numpy, and a chunk is one ``bytes.join`` of slices. The file is a
complete, indexed MCAP: chunk CRCs, message indexes, chunk/metadata indexes, statistics,
summary offsets, data-section and summary CRCs, validated in tests by the ``mcap`` reader.
Reading is :mod:`pipeline.log.mcap_read`.
"""

from __future__ import annotations

import enum
import itertools
import struct
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np
import zstandard
from numpy.typing import NDArray

MAGIC = b"\x89MCAP0\r\n"
PROFILE = "ros2"
# Constant on purpose: no version or host in the file, so equal inputs give equal bytes.
LIBRARY = "armlab-pipeline"
# A record: opcode u8, body length u64, body.
RECORD_HEADER = 9
# Message record body prefix: channel_id u16, sequence u32, log_time u64, publish_time u64.
MESSAGE_PREFIX = 22
# Footer record: header + summary_start u64 + summary_offset_start u64 + summary_crc u32.
FOOTER_RECORD = RECORD_HEADER + 20

# ~256 KiB of uncompressed records per chunk: at 1 kHz with full logging (about 1 KiB of
# JointState + controller state per step for 6 joints) that is ~0.25 s of sim time, so a reader
# seeking to an instant decompresses little and a damaged chunk loses little, while zstd still
# sees enough repetition (joint names, templates) to compress ~10x.
CHUNK_BYTES = 256 * 1024
# zstd rather than lz4: both are in the MCAP spec and every reader (mcap, rosbag2, Foxglove,
# rosbags); zstd compresses these repetitive CDR records much better and at level 1 still runs
# at several hundred MB/s. Output is deterministic for a given zstd version and level.
ZSTD_LEVEL = 1


class Op(enum.IntEnum):
    """MCAP record opcodes."""

    HEADER = 0x01
    FOOTER = 0x02
    SCHEMA = 0x03
    CHANNEL = 0x04
    MESSAGE = 0x05
    CHUNK = 0x06
    MESSAGE_INDEX = 0x07
    CHUNK_INDEX = 0x08
    ATTACHMENT = 0x09
    ATTACHMENT_INDEX = 0x0A
    STATISTICS = 0x0B
    METADATA = 0x0C
    METADATA_INDEX = 0x0D
    SUMMARY_OFFSET = 0x0E
    DATA_END = 0x0F


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
assert _MESSAGE_HEADER.itemsize == RECORD_HEADER + MESSAGE_PREFIX


@dataclass(frozen=True)
class ChannelSpec:
    """A channel to write: topic, its schema (name, encoding, text) and channel metadata."""

    topic: str
    schema_name: str
    schema_text: str
    metadata: Mapping[str, str]
    schema_encoding: str = "ros2msg"
    message_encoding: str = "cdr"


@dataclass(frozen=True)
class MessageBlock:
    """Messages of one topic: row k of ``payload`` (CDR bytes) is logged at ``log_time_ns[k]``."""

    topic: str
    log_time_ns: NDArray[np.int64]
    payload: NDArray[np.uint8]


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
    channels: Sequence[ChannelSpec],
    blocks: Sequence[MessageBlock],
    *,
    metadata: Mapping[str, Mapping[str, str]],
    chunk_bytes: int = CHUNK_BYTES,
) -> McapStats:
    """Write a complete, indexed ROS 2 MCAP file.

    Args:
        stream: binary output.
        channels: channel ids 1.. in this order; channels without a block are left out.
        blocks: messages per topic, stored in log-time order (ties in ``channels`` order); a
            chunk holds the messages whose record starts within its ``chunk_bytes`` window
            of the record stream.
        metadata: MCAP metadata records by name.
        chunk_bytes: uncompressed chunk size target [bytes].
    """
    present = {b.topic for b in blocks}
    unknown = present - {c.topic for c in channels}
    if unknown:
        raise ValueError(f"messages for undeclared topics {sorted(unknown)}")
    used = [c for c in channels if c.topic in present]
    channel_of = {c.topic: i + 1 for i, c in enumerate(used)}
    schema_of = {
        key: i + 1
        for i, key in enumerate(dict.fromkeys((c.schema_name, c.schema_text) for c in used))
    }
    rank = {c.topic: i for i, c in enumerate(channels)}
    blocks = sorted(blocks, key=lambda b: rank[b.topic])

    out = _Output(stream)
    out.write(MAGIC)
    out.write(_record(Op.HEADER, _str(PROFILE) + _str(LIBRARY)))

    encoding_of = {(c.schema_name, c.schema_text): c.schema_encoding for c in used}
    schema_records = [
        _record(
            Op.SCHEMA,
            struct.pack("<H", sid)
            + _str(name)
            + _str(encoding_of[(name, text)])
            + _str_bytes(text.encode()),
        )
        for (name, text), sid in schema_of.items()
    ]
    channel_records = [
        _record(
            Op.CHANNEL,
            struct.pack("<HH", channel_of[c.topic], schema_of[(c.schema_name, c.schema_text)])
            + _str(c.topic)
            + _str(c.message_encoding)
            + _map(c.metadata),
        )
        for c in used
    ]
    for rec in (*schema_records, *channel_records):
        out.write(rec)
    metadata_index = b""
    for name, values in metadata.items():
        offset = out.pos
        record = _record(Op.METADATA, _str(name) + _map(values))
        out.write(record)
        metadata_index += _record(
            Op.METADATA_INDEX, struct.pack("<QQ", offset, len(record)) + _str(name)
        )

    chunk_indexes, counts, start_ns, end_ns = _write_chunks(out, blocks, channel_of, chunk_bytes)
    out.write(_record(Op.DATA_END, struct.pack("<I", out.crc)))

    # Summary section: repeated schemas/channels, statistics, indexes; then their offsets.
    summary_start = out.pos
    statistics = _record(
        Op.STATISTICS,
        struct.pack(
            "<QHIIIIQQ",
            sum(counts.values()),
            len(schema_of),
            len(channel_of),
            0,  # attachments
            len(metadata),
            len(chunk_indexes),
            start_ns,
            end_ns,
        )
        + _u16_u64_map({channel_of[t]: n for t, n in counts.items()}),
    )
    groups = [
        (Op.SCHEMA, b"".join(schema_records)),
        (Op.CHANNEL, b"".join(channel_records)),
        (Op.STATISTICS, statistics),
        (Op.CHUNK_INDEX, b"".join(chunk_indexes)),
        (Op.METADATA_INDEX, metadata_index),
    ]
    summary = bytearray()
    offsets = bytearray()
    for opcode, data in groups:
        if data:
            offsets += _record(
                Op.SUMMARY_OFFSET,
                struct.pack("<BQQ", opcode, summary_start + len(summary), len(data)),
            )
            summary += data
    summary_offset_start = summary_start + len(summary)
    summary += offsets
    footer_head = struct.pack("<BQQQ", Op.FOOTER, 20, summary_start, summary_offset_start)
    summary_crc = zlib.crc32(footer_head, zlib.crc32(summary))
    out.write(bytes(summary) + footer_head + struct.pack("<I", summary_crc) + MAGIC)
    return McapStats(
        {c.topic: counts.get(c.topic, 0) for c in used},
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
        header["opcode"] = Op.MESSAGE
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
            Op.CHUNK,
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
                    Op.MESSAGE_INDEX,
                    struct.pack("<HI", ch, entries.nbytes) + entries.tobytes(),
                )
            )
        chunk_indexes.append(
            _record(
                Op.CHUNK_INDEX,
                struct.pack("<QQQQ", t_start, t_end, chunk_start, len(chunk))
                + _u16_u64_map(index_offsets)
                + struct.pack("<Q", out.pos - index_start)
                + _str("zstd")
                + struct.pack("<QQ", len(compressed), len(data)),
            )
        )
    return chunk_indexes, counts, int(times.min()), int(times.max())
