"""A foreign bag whose controller lists its joints in another order mid-bag: every message
is matched by joint name, none is dropped."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin

from pipeline.log.reader import ReadOptions, read_recording
from tests.log.test_external_bags import JOINTS, N, write_external_bag


@pytest.mark.parametrize(
    "storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3], ids=["mcap", "db3"]
)
@pytest.mark.parametrize("stream_above_bytes", [None, 0], ids=["whole", "windowed"])
def test_a_joint_order_that_flips_mid_bag_is_read_whole_by_name(
    tmp_path: Path, storage: StoragePlugin, stream_above_bytes: int | None
) -> None:
    path = tmp_path / "flip"
    s = write_external_bag(path, distro="jazzy", storage=storage, cs_flip_at=N // 2)
    rec = read_recording(path, ReadOptions(stream_above_bytes=stream_above_bytes))
    assert rec.joint_names == JOINTS
    end_s = rec.end_s if rec.end_s is not None else float(rec.samples["time_s"].max())  # type: ignore[arg-type]
    assert end_s == pytest.approx((N - 1) / 500)  # 1.998 s, not 0.998
    assert (rec.controller_sample_count or rec.controller_states.height // 3) == N
    assert any("in another order" in n and "matched by name" in n for n in rec.notes)
    if stream_above_bytes is None:
        for j, joint in enumerate(JOINTS):
            rows = rec.samples.filter(rec.samples["joint"] == joint).sort("stamp_ns")
            assert np.array_equal(rows["stamp_ns"].to_numpy(), s["t_ns"])
            np.testing.assert_array_equal(rows["reference_position_rad"].to_numpy(), s["ref"][:, j])
            np.testing.assert_array_equal(rows["error_rad"].to_numpy(), s["err"][:, j])
            np.testing.assert_array_equal(rows["position_rad"].to_numpy(), s["q"][:, j])
