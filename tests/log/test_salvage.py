"""Damaged bags: refused by default in one line, salvaged on request, footer gaps closed."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from pipeline.errors import RecordingError
from pipeline.log import bag
from pipeline.log.mcap import FOOTER_RECORD, MAGIC, Op
from pipeline.log.reader import ReadOptions, read_recording
from pipeline.robots import RobotSpec
from tests.log.test_writer import analytic_episode, episode_metadata

N_STEPS = 4000  # 4 s at 1 kHz: several 256 KiB chunks


@pytest.fixture
def long_bag(ur5: RobotSpec, tmp_path: Path) -> bag.BagSummary:
    result, planned = analytic_episode(ur5, n_steps=N_STEPS)
    return bag.write_episode_bag(
        tmp_path / "ep", spec=ur5, result=result, planned=planned, metadata=episode_metadata()
    )


def chunk_offsets(path: Path) -> list[int]:
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return sorted(c.chunk_start_offset for c in summary.chunk_indexes)


def test_truncated_bag_is_refused_then_salvaged_up_to_the_damage(
    long_bag: bag.BagSummary, ur5: RobotSpec
) -> None:
    path = long_bag.mcap_path
    starts = chunk_offsets(path)
    assert len(starts) >= 4
    cut = (starts[2] + starts[3]) // 2  # inside the third chunk
    path.write_bytes(path.read_bytes()[:cut])
    with pytest.raises(RecordingError, match="truncated") as err:
        read_recording(long_bag.path)
    assert "\n" not in str(err.value)

    rec = read_recording(long_bag.path, ReadOptions(salvage=True))
    assert rec.salvaged
    [note] = [n for n in rec.notes if n.startswith("salvaged")]
    assert f"{cut - starts[2]} bytes" in note  # lost: from the damaged chunk to the cut
    # Every message of the intact chunks, exactly: a prefix of the episode.
    result, _ = analytic_episode(ur5, n_steps=N_STEPS)
    js = rec.samples.filter(rec.samples["joint"] == ur5.joint_names[0])
    k = js.height
    assert 0 < k < N_STEPS
    assert np.array_equal(js["stamp_ns"].to_numpy(), result.stamp_ns[:k])
    assert np.array_equal(js["position_rad"].to_numpy(), result.q[:k, 0])


def test_a_corrupt_chunk_is_refused_and_salvage_keeps_the_chunks_before_it(
    long_bag: bag.BagSummary,
) -> None:
    path = long_bag.mcap_path
    starts = chunk_offsets(path)
    data = bytearray(path.read_bytes())
    data[starts[2] + 200] ^= 0xFF  # inside the compressed records of the third chunk
    path.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="corrupt"):
        read_recording(long_bag.path)
    rec = read_recording(long_bag.path, ReadOptions(salvage=True))
    assert rec.salvaged and 0 < rec.samples["stamp_ns"].n_unique() < N_STEPS


def test_damage_before_any_chunk_cannot_be_salvaged(long_bag: bag.BagSummary) -> None:
    path = long_bag.mcap_path
    starts = chunk_offsets(path)
    path.write_bytes(path.read_bytes()[: starts[0] + 100])
    with pytest.raises(RecordingError, match="truncated"):
        read_recording(long_bag.path, ReadOptions(salvage=True))


def footer_fields(data: bytes) -> tuple[int, int, int]:
    footer = data[-(FOOTER_RECORD + len(MAGIC)) :]
    assert footer[0] == Op.FOOTER
    start, offsets, crc = struct.unpack_from("<QQI", footer, 9)
    return start, offsets, crc


def test_a_lowered_summary_start_is_refused(long_bag: bag.BagSummary) -> None:
    path = long_bag.mcap_path
    data = bytearray(path.read_bytes())
    start, _, _ = footer_fields(bytes(data))
    at = len(data) - len(MAGIC) - FOOTER_RECORD + 9
    struct.pack_into("<Q", data, at, start - 1)
    path.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="summary_start"):
        read_recording(long_bag.path)


@pytest.mark.parametrize("delta", [1, -1, 8])
def test_a_changed_data_end_length_is_refused(long_bag: bag.BagSummary, delta: int) -> None:
    path = long_bag.mcap_path
    data = bytearray(path.read_bytes())
    start, _, _ = footer_fields(bytes(data))
    data_end = start - 13  # DataEnd: opcode, length 4, crc
    assert data[data_end] == Op.DATA_END
    struct.pack_into("<Q", data, data_end + 1, 4 + delta)
    path.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="corrupt"):
        read_recording(long_bag.path)


@pytest.mark.parametrize("damage", ["truncate", "bitflip"])
def test_a_rosbags_mcap_damaged_in_its_only_chunk_is_refused_even_with_salvage(
    tmp_path: Path, damage: str
) -> None:
    # rosbags' writer puts a short bag in one chunk: damage there leaves no intact chunk
    # (salvage does not recover single messages from a damaged chunk).
    from rosbags.rosbag2 import StoragePlugin

    from tests.log.test_external_bags import write_external_bag

    write_external_bag(tmp_path / "run", distro="jazzy", storage=StoragePlugin.MCAP)
    [path] = (tmp_path / "run").glob("*.mcap")
    [start] = chunk_offsets(path)
    data = bytearray(path.read_bytes())
    if damage == "truncate":
        data = data[: len(data) // 2]
    else:
        data[start + 5000] ^= 0x01
    path.write_bytes(bytes(data))
    for options in (None, ReadOptions(salvage=True)):
        with pytest.raises(RecordingError, match=r"truncated|corrupt|CRC") as err:
            read_recording(tmp_path / "run", options)
        assert "\n" not in str(err.value) and str(path) in str(err.value)
