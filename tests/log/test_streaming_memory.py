"""Reading streams: validating and decompressing a bag holds about one batch of chunks,
whatever the bag's length (a one-hour bag needs no more than a minute's). What a read keeps
is the decoded arrays (bytes per sample), measured in benches/long_bag.py."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import pytest

from pipeline.log import bag
from pipeline.log.mcap import BATCH_BYTES, CHUNK_BYTES, McapScan
from pipeline.robots import RobotSpec
from tests.log.test_writer import analytic_episode, episode_metadata


def scan_peak_bytes(path: Path) -> tuple[int, int]:
    scan = McapScan(path)
    tracemalloc.start()
    try:
        scan.run()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak, scan.chunks_read


@pytest.mark.parametrize("seconds", [15, 60])
def test_scanning_a_bag_holds_one_chunk_at_a_time(
    ur5: RobotSpec, tmp_path: Path, seconds: int
) -> None:
    result, planned = analytic_episode(ur5, n_steps=seconds * 1000)
    summary = bag.write_episode_bag(
        tmp_path / "long", spec=ur5, result=result, planned=planned, metadata=episode_metadata()
    )
    del result, planned
    peak, chunks = scan_peak_bytes(summary.mcap_path)
    assert chunks > 4 * seconds  # ~0.2 s of 1 kHz messages a chunk
    assert summary.size_bytes > 10 * CHUNK_BYTES
    # one batch of decompressed chunks (handed on together) and its joined copy, whatever
    # the bag's length
    assert peak < 2 * BATCH_BYTES + 4 * CHUNK_BYTES, (peak, summary.size_bytes)
