"""Declared counts against decoded ones: a bag whose Statistics record or ``metadata.yaml``
counts more messages than it holds is refused (one line) or, with salvage, read and marked
salvaged with the share missing; a salvaged bag's loss is of what the bag declares."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from rosbags.rosbag2 import StoragePlugin

from pipeline.constants import TOPIC_JOINT_STATES
from pipeline.errors import RecordingError
from pipeline.log import bag
from pipeline.log.mcap import FOOTER_RECORD, Op
from pipeline.log.reader import ReadOptions, read_recording
from pipeline.robots import RobotSpec
from tests.log.test_external_bags import write_external_bag
from tests.log.test_salvage import chunk_offsets
from tests.log.test_writer import analytic_episode, episode_metadata

REMOVED = 39
SALVAGE = ReadOptions(salvage=True)


@pytest.fixture
def our_bag(ur5: RobotSpec, tmp_path: Path) -> bag.BagSummary:
    result, planned = analytic_episode(ur5, n_steps=2000)
    return bag.write_episode_bag(
        tmp_path / "ep", spec=ur5, result=result, planned=planned, metadata=episode_metadata()
    )


def rewrite_without(src: Path, dst: Path, topic: str, drop: range) -> dict[str, int]:
    """Copy an MCAP file message by message with the mcap library (a consistent file: its
    CRCs and Statistics count what it holds), leaving out the ``drop``-th messages of
    ``topic``. Returns the messages per topic of the source."""
    counts: dict[str, int] = {}
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        w = Writer(out, compression=CompressionType.ZSTD, chunk_size=256 * 1024)
        header = reader.get_header()
        w.start(profile=header.profile, library="test")
        for sid, s in sorted(summary.schemas.items()):
            assert w.register_schema(s.name, s.encoding, s.data) == sid
        for cid, c in sorted(summary.channels.items()):
            assert w.register_channel(c.topic, c.message_encoding, c.schema_id, c.metadata) == cid
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            k = counts.get(channel.topic, 0)
            counts[channel.topic] = k + 1
            if channel.topic == topic and k in drop:
                continue
            w.add_message(
                channel.id, message.log_time, message.data, message.publish_time, message.sequence
            )
        w.finish()
    return counts


def raise_statistics(path: Path, topic: str, extra: int) -> None:
    """Make the Statistics record count ``extra`` more messages on ``topic`` than the file
    holds, and repair the summary CRC, so the file is self-consistent but for the count."""
    data = bytearray(path.read_bytes())
    footer_at = len(data) - 8 - FOOTER_RECORD
    (start,) = struct.unpack_from("<Q", data, footer_at + 9)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    [cid] = [c.id for c in summary.channels.values() if c.topic == topic]
    off = start
    while data[off] != Op.STATISTICS:
        (length,) = struct.unpack_from("<Q", data, off + 1)
        off += 9 + length
    body = off + 9
    (total,) = struct.unpack_from("<Q", data, body)
    struct.pack_into("<Q", data, body, total + extra)
    (nbytes,) = struct.unpack_from("<I", data, body + 42)
    for k in range(body + 46, body + 46 + nbytes, 10):
        c, n = struct.unpack_from("<HQ", data, k)
        if c == cid:
            struct.pack_into("<Q", data, k + 2, n + extra)
    crc_at = len(data) - 8 - 4
    struct.pack_into("<I", data, crc_at, zlib.crc32(bytes(data[start:crc_at])))
    path.write_bytes(bytes(data))


def bump_metadata_yaml(bag_dir: Path, topic: str, extra: int) -> None:
    meta = bag_dir / "metadata.yaml"
    info = yaml.safe_load(meta.read_text())
    for entry in info["rosbag2_bagfile_information"]["topics_with_message_count"]:
        if entry["topic_metadata"]["name"] == topic:
            entry["message_count"] += extra
    meta.write_text(yaml.safe_dump(info))


def test_a_bag_whose_statistics_count_removed_messages_is_refused_or_salvaged(
    our_bag: bag.BagSummary, tmp_path: Path
) -> None:
    bare = tmp_path / "bare.mcap"
    counts = rewrite_without(our_bag.mcap_path, bare, TOPIC_JOINT_STATES, range(700, 739))
    assert read_recording(bare).samples.height  # consistent: its Statistics count what is there
    raise_statistics(bare, TOPIC_JOINT_STATES, REMOVED)
    with open(bare, "rb") as f:  # the mcap library validates every CRC as before
        assert sum(1 for _ in StreamReader(f, validate_crcs=True).records)
    with pytest.raises(RecordingError) as err:
        read_recording(bare)
    message = str(err.value)
    assert "\n" not in message and str(bare) in message
    n = counts[TOPIC_JOINT_STATES]
    assert f"declares {n} messages on {TOPIC_JOINT_STATES}, the recording holds {n - 39}" in message
    assert "--salvage" in message

    rec = read_recording(bare, SALVAGE)
    assert rec.salvaged
    total = sum(counts.values())
    [note] = [x for x in rec.notes if x.startswith("salvaged")]
    assert f"{REMOVED} of the {total} messages its Statistics record declares" in note
    assert rec.salvage_lost_pct == pytest.approx(100 * REMOVED / total)


def test_a_bag_whose_metadata_yaml_counts_removed_messages_is_refused_or_salvaged(
    our_bag: bag.BagSummary, tmp_path: Path
) -> None:
    mcap_path = our_bag.mcap_path
    copy = tmp_path / "copy.mcap"
    counts = rewrite_without(mcap_path, copy, TOPIC_JOINT_STATES, range(100, 139))
    copy.replace(mcap_path)  # the bag folder's metadata.yaml still counts them
    with pytest.raises(RecordingError, match=r"metadata\.yaml declares") as err:
        read_recording(our_bag.path)
    assert "\n" not in str(err.value)
    rec = read_recording(our_bag.path, SALVAGE)
    assert rec.salvaged
    assert rec.salvage_lost_pct == pytest.approx(100 * REMOVED / sum(counts.values()))


@pytest.mark.parametrize(
    "storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3], ids=["mcap", "db3"]
)
def test_a_rosbags_bag_whose_metadata_yaml_counts_more_is_refused(
    tmp_path: Path, storage: StoragePlugin
) -> None:
    path = tmp_path / "run"
    write_external_bag(path, distro="jazzy", storage=storage)
    read_recording(path)  # rosbags' own counts agree with what it wrote
    bump_metadata_yaml(path, "/joint_states", REMOVED)
    with pytest.raises(RecordingError, match=r"metadata\.yaml declares .* on /joint_states"):
        read_recording(path)
    rec = read_recording(path, SALVAGE)
    assert rec.salvaged and any("metadata.yaml declares" in x for x in rec.notes)
    assert rec.salvage_lost_pct is not None and 0 < rec.salvage_lost_pct < 2
    # the windowed read (long recordings) checks the same
    with pytest.raises(RecordingError, match="declares"):
        read_recording(path, ReadOptions(stream_above_bytes=0))
    streamed = read_recording(path, ReadOptions(stream_above_bytes=0, salvage=True))
    assert streamed.salvaged and streamed.salvage_lost_pct == rec.salvage_lost_pct


def test_a_salvaged_bag_reports_its_loss_against_what_it_declares(
    our_bag: bag.BagSummary,
) -> None:
    """Issue 20: a bag cut to 60 % of its size said '0.9 % lost' (the bytes after the
    damage, of the bytes that survived); the share is of the messages metadata.yaml counts,
    close to the share of the declared duration that is missing."""
    path = our_bag.mcap_path
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 6 // 10])
    rec = read_recording(our_bag.path, SALVAGE)
    assert rec.salvaged and rec.salvage_lost_pct is not None
    info = yaml.safe_load((our_bag.path / "metadata.yaml").read_text())
    duration_s = info["rosbag2_bagfile_information"]["duration"]["nanoseconds"] * 1e-9
    end_s = float(rec.samples["time_s"].max())  # type: ignore[arg-type]
    missing_pct = 100 * (1 - end_s / duration_s)
    assert missing_pct > 20
    assert rec.salvage_lost_pct == pytest.approx(missing_pct, abs=5)
    [note] = [x for x in rec.notes if x.startswith("salvaged")]
    assert "messages metadata.yaml declares" in note


def test_a_truncated_bare_mcap_says_its_loss_is_unknown(our_bag: bag.BagSummary) -> None:
    """A bare MCAP file cut short has lost its summary: the bytes after the damage are a
    floor, not a share of the recording."""
    path = our_bag.mcap_path
    starts = chunk_offsets(path)
    path.write_bytes(path.read_bytes()[: (starts[2] + starts[3]) // 2])
    rec = read_recording(path, SALVAGE)
    assert rec.salvaged and rec.salvage_lost_pct is None
    [note] = [x for x in rec.notes if x.startswith("salvaged")]
    assert "share lost is unknown" in note


def test_a_corrupt_chunk_is_measured_against_the_statistics_at_the_file_end(
    our_bag: bag.BagSummary,
) -> None:
    """A chunk damaged in a file whose end is intact: the Statistics record there says how
    many messages the file held."""
    path = our_bag.mcap_path
    starts = chunk_offsets(path)
    data = bytearray(path.read_bytes())
    data[starts[2] + 200] ^= 0xFF
    path.write_bytes(bytes(data))
    bare = path.parent.parent / "bare.mcap"
    path.rename(bare)
    rec = read_recording(bare, SALVAGE)
    with open(bare, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    total = summary.statistics.message_count
    read = sum(rec.topic_counts.values())
    assert rec.salvage_lost_pct == pytest.approx(100 * (total - read) / total)
    assert any("its Statistics record declares" in x for x in rec.notes)
