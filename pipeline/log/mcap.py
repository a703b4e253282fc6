# long: one container format: records, CRCs, writer and validating streaming scan
"""The MCAP container format: opcodes, records, CRCs, and a fast writer of ROS 2 files.

We write the records ourselves instead of going through ``mcap.writer.Writer``: its
``add_message`` builds a dataclass and several ``struct.pack`` calls per message (see
``benches/log_encode.py``), which alone exceeds the logging budget of a 1 kHz episode. Here
all messages of a topic come pre-encoded as a byte matrix, their 31-byte message record
headers are filled with numpy, and a chunk is one ``bytes.join`` of slices. The file is a
complete, indexed MCAP: chunk CRCs, message indexes, chunk/metadata indexes, statistics,
summary offsets, data-section and summary CRCs, validated in tests by the ``mcap`` reader.
Reading (:class:`McapScan`) streams a file chunk by chunk and checks every CRC.
"""

from __future__ import annotations

import contextlib
import enum
import hashlib
import itertools
import stat
import struct
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, BinaryIO

import numpy as np
import zstandard
from numpy.typing import NDArray

from pipeline.errors import RecordingError
from pipeline.log.gather import gather_u64, values_at

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


# zstd's largest expansion: a 128 KiB block stored as one repeated byte takes 4 bytes
_ZSTD_MAX_RATIO = 32 * 1024 + 1
# A damaged file's summary (indexes and statistics, a few bytes per chunk) read from its end
# for the counts it declares: larger is not a summary worth trusting.
_SUMMARY_MAX_BYTES = 64 << 20


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


# --- reading ----------------------------------------------------------------------------------

# Loose (unchunked) messages are batched into pseudo-chunks of this size.
_LOOSE_BATCH_BYTES = 4 << 20
# Validated chunks are handed on in batches of about this size: decoding costs a few numpy
# calls per topic and batch, which would dominate at ~200 messages a topic in one chunk.
BATCH_BYTES = 1 << 20


@dataclass(frozen=True)
class McapSchema:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class McapChannel:
    id: int
    topic: str
    schema_id: int
    encoding: str


@dataclass(frozen=True)
class Salvage:
    """Where a salvaged scan stopped: the damage, and how much of the file it left unread.

    Attributes:
        at_byte: offset of the first damaged record (a ``.db3``: of the damaged page, or
            -1 when sqlite does not say).
        problem: what is wrong there.
        lost_bytes: bytes from the damage to the end of the file.
        read_messages: messages read before the damage (a ``.db3``; None for MCAP).
        lost_messages: message rows after the damage (a ``.db3``; None: unknown).
        lost_after_ns: stamp of the last message read (a ``.db3``; None for MCAP).
    """

    at_byte: int
    problem: str
    lost_bytes: int
    read_messages: int | None = None
    lost_messages: int | None = None
    lost_after_ns: int | None = None


def not_regular(mode: int) -> str:
    """Why a path with this ``st_mode`` cannot be read as a recording file."""
    kind = (
        "a FIFO" if stat.S_ISFIFO(mode)
        else "a character device" if stat.S_ISCHR(mode)
        else "a block device" if stat.S_ISBLK(mode)
        else "a socket" if stat.S_ISSOCK(mode)
        else "a directory" if stat.S_ISDIR(mode)
        else "not a file"
    )  # fmt: skip
    return f"not a regular file ({kind}); expected an MCAP or sqlite3 recording file"


class StorageScan:
    """What a scan of one storage file (MCAP or sqlite3) collects, and how it hands on
    messages: subclasses receive them through :meth:`on_messages`.

    Attributes:
        schemas, channels: by id, as the file declares them.
        metadata: metadata records by name.
        topic_counts: messages per topic.
        sha: SHA-256 of the file's bytes, updated as they are read.
        size: bytes read.
        salvaged: where a ``salvage`` scan stopped (None: intact).
        notes: non-fatal oddities for the report.
        declared_counts: messages per topic as the file's own summary declares them (an
            MCAP Statistics record; None when the file declares none).
    """

    def __init__(self, path: Path, *, salvage: bool = False) -> None:
        self.path = path
        self.schemas: dict[int, McapSchema] = {}
        self.channels: dict[int, McapChannel] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.topic_counts: dict[str, int] = {}
        self.sha = hashlib.sha256()
        self.size = 0
        self.salvage = salvage
        self.salvaged: Salvage | None = None
        self.notes: list[str] = []
        self.declared_counts: dict[str, int] | None = None

    def on_messages(self, channel: McapChannel, buf: bytes, starts: NDArray[np.int64]) -> None:
        """Messages of ``channel`` in ``buf``: record bodies start at ``starts`` (the channel
        id), payloads at ``starts + MESSAGE_PREFIX``, body lengths at ``starts - 8``."""


class McapScan(StorageScan):
    """Streams one MCAP file, validating it: every record, chunk CRC, data and summary CRC.

    One chunk is in memory at a time. Subclasses receive the messages through
    :meth:`on_messages` (per chunk, the message record starts of each channel), with
    :attr:`schemas` and :attr:`channels` known by then. With ``salvage``, damage after the
    first intact chunk ends the scan instead of failing it: :attr:`salvaged` then says where
    and why, and everything before it has been delivered.
    """

    def __init__(self, path: Path, *, salvage: bool = False) -> None:
        super().__init__(path, salvage=salvage)
        self.chunks_read = 0
        self._damage_at = 0
        self._batch: list[tuple[bytes, dict[int, NDArray[np.int64]]]] = []
        self._batch_bytes = 0
        # The chunk read last and its message indexes, decoded once the indexes are in.
        self._pending: tuple[bytes, int] | None = None
        self._index: dict[int, NDArray[np.uint64]] = {}

    # ---- errors
    def _fail(self, problem: str) -> RecordingError:
        return RecordingError(f"{self.path}: {problem}")

    # ---- the record loop
    def run(self) -> None:
        try:
            info = self.path.stat()
            if not stat.S_ISREG(info.st_mode):  # a FIFO blocks, /dev/zero never ends
                raise self._fail(not_regular(info.st_mode))
            self.size = info.st_size
            fh = open(self.path, "rb")  # noqa: SIM115 - closed in finally below
        except OSError as err:
            raise self._fail(f"cannot read ({err.strerror})") from err
        try:
            self._run(fh)
        except RecordingError as err:
            if not (self.salvage and (self.chunks_read or self._pending)):
                raise
            self._salvaged(str(err))
        finally:
            fh.close()

    def _salvaged(self, problem: str) -> None:
        """End a salvaged scan at the damage: deliver the last intact chunk, note the rest."""
        at = self._damage_at
        # A pending chunk whose own records are damaged is lost with the rest.
        with contextlib.suppress(RecordingError):
            self._flush()
        self._deliver()
        self.declared_counts = self._declared_from_end()
        self.salvaged = Salvage(
            at_byte=at,
            problem=problem.removeprefix(f"{self.path}: "),
            lost_bytes=self.size - at,
        )

    def _read(self, fh: IO[bytes], n: int) -> bytes:
        data = fh.read(n)
        self.sha.update(data)
        return data

    def _run(self, fh: IO[bytes]) -> None:
        if self.size == 0:
            raise self._fail("empty file (0 bytes); expected an MCAP recording")
        magic = self._read(fh, 8)
        if magic != MAGIC:
            raise self._fail("not an MCAP file (the first bytes are not the MCAP magic)")
        crc = zlib.crc32(magic)
        pos = 8
        loose = bytearray()
        while True:
            self._damage_at = pos
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
            # Opcode 0 is invalid and a file starts with its Header: zeros (a preallocated
            # or wiped file) are refused here at once, not walked 9 bytes at a time.
            if op == 0 or (pos == 8 and op != Op.HEADER):
                raise self._fail(
                    f"corrupt: record at byte {pos} has opcode {op:#04x}"
                    + (", expected the Header record (0x01)" if pos == 8 else " (invalid)")
                )
            if op != Op.MESSAGE_INDEX:
                self._flush()
            if op == Op.DATA_END:
                body = self._read(fh, length)
                if length < 4:
                    raise self._fail(
                        f"corrupt: DataEnd record at byte {pos} has {length} bytes, expected 4"
                    )
                (expected,) = struct.unpack_from("<I", body, 0)
                if expected and expected != crc:
                    raise self._fail(
                        f"corrupt: data section CRC mismatch (recorded {expected:#010x}, "
                        f"computed {crc:#010x})"
                    )
                pos += 9 + length
                break
            body = self._read(fh, length)
            crc = zlib.crc32(body, zlib.crc32(head, crc))
            if op == Op.CHUNK:
                self._pending = (self._chunk(body, pos), pos)
            elif op == Op.MESSAGE_INDEX:
                self._message_index(body, pos)
            elif op == Op.MESSAGE:
                loose += head + body
                if len(loose) >= _LOOSE_BATCH_BYTES:
                    self._records(bytes(loose), pos)
                    loose.clear()
            elif op in (Op.SCHEMA, Op.CHANNEL):
                self._records(head + body, pos)
            elif op == Op.METADATA:
                self._metadata(body, pos)
            elif op == Op.FOOTER:
                raise self._fail(f"corrupt: footer at byte {pos} before the DataEnd record")
            pos += 9 + length
        if loose:
            self._records(bytes(loose), pos)
        self._deliver()
        self._damage_at = pos
        self._finish_file(fh, pos)

    def _finish_file(self, fh: IO[bytes], pos: int) -> None:
        """Check the end of the file: footer + magic, and the summary CRC if recorded.

        The summary itself is not needed here, but a damaged one misleads other tools.
        It holds indexes and statistics only (a few bytes per chunk), so it is read whole.
        """
        rest = self._read(fh, self.size - pos)
        if len(rest) < FOOTER_RECORD + 8:
            raise self._fail(f"truncated: no footer after the data section (ends at byte {pos})")
        footer = rest[-(FOOTER_RECORD + 8) :]
        if footer[-8:] != MAGIC or footer[0] != Op.FOOTER:
            raise self._fail("truncated or corrupt: the file does not end with a footer and magic")
        start, _, expected = struct.unpack_from("<QQI", footer, 9)
        # The summary (if any) starts right after DataEnd, else the footer does: anything
        # else is a damaged footer or DataEnd record, which other readers refuse too.
        if start == 0 and len(rest) != FOOTER_RECORD + 8:
            raise self._fail(
                f"corrupt: {len(rest) - FOOTER_RECORD - 8} bytes between the data section "
                f"(ends at byte {pos}) and the footer, which records no summary"
            )
        if start not in (0, pos):
            raise self._fail(
                f"corrupt: the footer's summary_start ({start}) is not where the data section "
                f"ends (byte {pos})"
            )
        if start == 0:
            return  # no summary
        if expected:
            covered = rest[start - pos : len(rest) - 8 - 4]  # up to the footer's CRC field
            crc = zlib.crc32(covered)
            if crc != expected:
                raise self._fail(
                    f"corrupt: summary section CRC mismatch (recorded {expected:#010x}, "
                    f"computed {crc:#010x})"
                )
        self.declared_counts = self._summary_counts(rest[start - pos : len(rest) - 8])

    def _declared_from_end(self) -> dict[str, int] | None:
        """The Statistics of a damaged file whose end is intact (footer, magic, summary):
        what it held before the damage; None when its end is lost too."""
        tail = FOOTER_RECORD + 8
        try:
            with open(self.path, "rb") as fh:
                if self.size < 8 + tail:
                    return None
                fh.seek(self.size - tail)
                footer = fh.read(tail)
                if footer[-8:] != MAGIC or footer[0] != Op.FOOTER:
                    return None
                (start,) = struct.unpack_from("<Q", footer, 9)
                end = self.size - tail
                if not 8 < start < end or end - start > _SUMMARY_MAX_BYTES:
                    return None
                fh.seek(start)
                return self._summary_counts(fh.read(end - start) + footer[:-8])
        except OSError:
            return None

    def _summary_counts(self, summary: bytes) -> dict[str, int] | None:
        """Messages per topic from the summary section's Statistics record (topics from its
        Channel records, else the data section's); None without one or when it cannot be
        read (the data section has been checked: a damaged summary is not fatal)."""
        topics = {cid: c.topic for cid, c in self.channels.items()}
        counts: dict[int, int] | None = None
        total = 0
        off = 0
        try:
            while off + 9 <= len(summary):
                op = summary[off]
                (length,) = struct.unpack_from("<Q", summary, off + 1)
                body = summary[off + 9 : off + 9 + length]
                if len(body) != length:
                    return None
                if op == Op.CHANNEL:
                    (cid,) = struct.unpack_from("<H", body, 0)
                    topics[cid], _ = self._str(body, 4)
                elif op == Op.STATISTICS:
                    (total,) = struct.unpack_from("<Q", body, 0)
                    (nbytes,) = struct.unpack_from("<I", body, 42)
                    if 46 + nbytes > length or nbytes % 10:
                        return None
                    counts = {}
                    for k in range(46, 46 + nbytes, 10):
                        cid, n = struct.unpack_from("<HQ", body, k)
                        counts[cid] = n
                off += 9 + length
        except (struct.error, ValueError, UnicodeDecodeError):
            return None
        if counts is None or (not counts and total):
            return None  # no Statistics, or no per-channel counts in it
        if any(cid not in topics for cid in counts):
            return None
        out: dict[str, int] = {}
        for cid, n in counts.items():
            out[topics[cid]] = out.get(topics[cid], 0) + n
        return out

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
        # the uncompressed size is allocated before decompressing: bound it by what the
        # compressed bytes can expand to
        most = {"": clen, "lz4": 256 * clen + 64, "zstd": _ZSTD_MAX_RATIO * clen + 1024}
        if compression in most and usize > most[compression]:
            raise self._fail(
                f"corrupt: chunk at byte {pos} claims {usize:,} uncompressed bytes, more than "
                f"its {clen:,} {compression or 'uncompressed'} bytes can hold"
            )
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
        self.chunks_read += 1
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
        if offsets.size == 0 or int(offsets.max()) + 9 + MESSAGE_PREFIX > u8.size:
            return None
        order = np.sort(offsets)
        lengths = gather_u64(u8, order + 1).astype(np.int64)
        ends = order + 9 + lengths
        if order[0] != 0 or ends[-1] != u8.size or not np.array_equal(ends[:-1], order[1:]):
            return None
        if not (u8[order] == Op.MESSAGE).all():
            return None
        owners = np.repeat(np.array(list(index), dtype=np.uint16), [v.size for v in index.values()])
        if not np.array_equal(values_at(u8, "<u2")[offsets + 9], owners):
            return None  # a message indexed under another channel than its record's
        return {cid: np.sort(offs.astype(np.int64)) + 9 for cid, offs in index.items()}

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
                if op == Op.MESSAGE:
                    (cid,) = unpack("<H", buf, start)
                    lst = positions.get(cid)
                    if lst is None:
                        lst = positions[cid] = []
                    lst.append(start)
                elif op == Op.SCHEMA:
                    self._schema(buf[start : start + length])
                elif op == Op.CHANNEL:
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
        for cid in positions:
            if cid not in self.channels:
                raise self._fail(f"corrupt: message on unknown channel {cid} (chunk at byte {pos})")
        self._batch.append((buf, positions))
        self._batch_bytes += len(buf)
        if self._batch_bytes >= BATCH_BYTES:
            self._deliver()

    def _deliver(self) -> None:
        """Hand the batched chunks' messages on, one call per channel."""
        batch, self._batch, self._batch_bytes = self._batch, [], 0
        if not batch:
            return
        if len(batch) == 1:
            buf, positions = batch[0]
        else:
            shift = np.cumsum([0] + [len(b) for b, _ in batch[:-1]])
            buf = b"".join(b for b, _ in batch)
            merged: dict[int, list[NDArray[np.int64]]] = {}
            for offset, (_, pos) in zip(shift.tolist(), batch, strict=True):
                for cid, starts in pos.items():
                    merged.setdefault(cid, []).append(starts + offset)
            positions = {cid: np.concatenate(parts) for cid, parts in merged.items()}
        for cid, starts in positions.items():
            channel = self.channels[cid]
            self.topic_counts[channel.topic] = self.topic_counts.get(channel.topic, 0) + len(starts)
            self.on_messages(channel, buf, starts)

    def _schema(self, body: bytes) -> None:
        (sid,) = struct.unpack_from("<H", body, 0)
        name, off = self._str(body, 2)
        encoding, off = self._str(body, off)
        (n,) = struct.unpack_from("<I", body, off)
        if off + 4 + n > len(body):
            raise ValueError(f"schema {sid}: its data claims {n} bytes, past its record")
        self.schemas[sid] = McapSchema(sid, name, encoding, body[off + 4 : off + 4 + n])

    def _channel(self, body: bytes) -> None:
        cid, sid = struct.unpack_from("<HH", body, 0)
        topic, off = self._str(body, 4)
        encoding, off = self._str(body, off)
        self.channels[cid] = McapChannel(cid, topic, sid, encoding)
