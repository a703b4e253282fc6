"""The report on a long recording read in windows: the same metrics, episode row and notes
as when it is read whole (the windowed path forced on small bags with ReadOptions)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal
from rosbags.rosbag2 import StoragePlugin

from pipeline.analysis.checks import duplicate_stamp_notes
from pipeline.analysis.measure import Measured
from pipeline.log import bag, windowed
from pipeline.log.reader import ReadOptions, Recording
from pipeline.robots import RobotSpec
from pipeline.stages.report import read_all, run_report
from tests.analysis.bagfactory import paper_like, write_bag
from tests.log.test_external_bags import write_external_bag
from tests.log.test_salvage import chunk_offsets
from tests.log.test_writer import analytic_episode, episode_metadata

WINDOWED = ReadOptions(stream_above_bytes=0, window_steps=250)
DECIMATION_NOTE = "recording: metrics over all"


def measured(
    folder: Path, options: ReadOptions
) -> tuple[list[Recording], pl.DataFrame, pl.DataFrame]:
    m = Measured()
    recs, _ = read_all(folder, skip_bad=False, options=options, measure=m.add, sink=m)
    episodes = pl.concat([m.rows[r.episode] for r in recs])
    metrics = pl.concat([m.metrics[r.episode] for r in recs], how="vertical_relaxed")
    return recs, episodes, metrics


def assert_report_inputs_equal(folder: Path, options: ReadOptions | None = None) -> list[str]:
    """Read ``folder`` whole and in windows; return the windowed read's decimation note."""
    options = options or ReadOptions()
    recs, episodes, metrics = measured(folder, options)
    w_recs, w_episodes, w_metrics = measured(
        folder,
        dataclasses.replace(options, stream_above_bytes=0, window_steps=WINDOWED.window_steps),
    )
    assert all(r.windows > 3 for r in w_recs)
    assert_frame_equal(w_episodes, episodes)
    assert_frame_equal(w_metrics, metrics, check_exact=False, rel_tol=1e-12, abs_tol=0.0)
    joints = metrics.filter(pl.col("joint") != "tcp")  # the TCP: task-space metrics only
    assert joints["max_abs_error"].is_not_null().all() and joints["rms_effort"].is_not_null().all()
    # as the report warns: the reader's notes, then the frame checks'
    notes = [[*r.notes, *duplicate_stamp_notes(r)] for r in recs]
    w_notes = [
        [n for n in (*r.notes, *duplicate_stamp_notes(r)) if DECIMATION_NOTE not in n]
        for r in w_recs
    ]
    assert w_notes == notes
    return [n for r in w_recs for n in r.notes if DECIMATION_NOTE in n]


@pytest.mark.parametrize("kept", [20_000, 400], ids=["all-kept", "every-7th-kept"])
def test_pre_roll_ground_truth_and_decimated_joint_states(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kept: int
) -> None:
    # the motion start (step 250) is not a kept step when every 7th is kept: the state
    # there must still come from the exact samples
    monkeypatch.setattr(windowed, "MAX_KEPT_STEPS", kept)
    ep = paper_like("long", "pid", duration_s=6.0, motion_end_s=4.0)
    rng = np.random.default_rng(3)
    ep = dataclasses.replace(
        ep,
        motion_start_s=0.5,
        q_true=ep.q + rng.normal(0, 1e-6, ep.q.shape),
        joint_state_every=3,
    )
    write_bag(tmp_path / "recs", ep)
    [note] = assert_report_inputs_equal(tmp_path / "recs")
    assert "metrics over all 2,751 controller-state and 917 joint-state samples" in note


def test_duplicate_stamps(tmp_path: Path) -> None:
    ep = paper_like("dup", "pid", duration_s=5.0, motion_end_s=3.0)
    stamps = ep.stamp_ns.copy()
    stamps[1000:1010] = stamps[999]  # a stretch recorded twice
    write_bag(tmp_path / "recs", dataclasses.replace(ep, stamp_ns=stamps))
    assert_report_inputs_equal(tmp_path / "recs")
    recs, _, _ = measured(tmp_path / "recs", WINDOWED)
    assert any("10 duplicate message(s)" in n for n in recs[0].notes)


@pytest.mark.parametrize(
    ("distro", "storage"),
    [("humble", StoragePlugin.MCAP), ("jazzy", StoragePlugin.SQLITE3)],
    ids=["humble-mcap", "jazzy-db3"],
)
def test_a_robots_bag(tmp_path: Path, distro: str, storage: StoragePlugin) -> None:
    write_external_bag(tmp_path / "recs" / "robot", distro=distro, storage=storage, js_every=2)
    assert_report_inputs_equal(tmp_path / "recs")


def test_a_salvaged_bag(ur5: RobotSpec, tmp_path: Path) -> None:
    result, planned = analytic_episode(ur5, n_steps=4000)
    summary = bag.write_episode_bag(
        tmp_path / "recs" / "ep",
        spec=ur5,
        result=result,
        planned=planned,
        metadata=episode_metadata(),
    )
    starts = chunk_offsets(summary.mcap_path)
    cut = (starts[-3] + starts[-2]) // 2
    summary.mcap_path.write_bytes(summary.mcap_path.read_bytes()[:cut])
    assert_report_inputs_equal(tmp_path / "recs", ReadOptions(salvage=True))


def test_the_report_says_a_long_recording_was_decimated(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(windowed, "MAX_KEPT_STEPS", 400)
    write_bag(tmp_path / "recs", paper_like("long", "pid", duration_s=4.0, motion_end_s=3.0))
    result = run_report(
        recordings_dir=tmp_path / "recs", out_dir=tmp_path / "out", options=WINDOWED
    )
    [note] = [n for _, n in result.warnings if DECIMATION_NOTE in n]
    assert note.startswith("0.0667-minute recording: metrics over all 2,001 controller-state")
    assert "streamed in 9 windows" in note and "show every 6-th sample" in note
    assert note in (tmp_path / "out" / "report.md").read_text()


CHILD = """
import sys
from pathlib import Path
from pipeline.log import windowed
windowed.MAX_KEPT_STEPS = 1000
from pipeline.log.reader import ReadOptions
from pipeline.analysis.measure import Measured
from pipeline.stages.report import read_all
m = Measured()
options = ReadOptions(stream_above_bytes=int(sys.argv[2]), window_steps=1000)
read_all(Path(sys.argv[1]), skip_bad=False, options=options, measure=m.add, sink=m)
# VmHWM, not ru_maxrss: Linux carries the parent's peak over fork + exec into ru_maxrss
print(next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")))
"""
MEMORY_MARGIN_MB = 40


def peak_rss_mb(folder: Path, *, stream_above_bytes: int = 0) -> float:
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(folder), str(stream_above_bytes)],
        capture_output=True,
        text=True,
        check=True,
        cwd=Path(__file__).resolve().parents[2],
    )
    return int(out.stdout.split()[-1]) / 1024


def test_reading_and_measuring_a_long_recording_holds_a_window_not_the_recording(
    ur5: RobotSpec, tmp_path: Path
) -> None:
    # 10 s and 40 s at 1 kHz in windows of 1 s: the peak RSS of read + protocol + metrics
    # must not grow with the length (measured: +1.4 MB; read whole: +87 MB, so the margin
    # tells the two apart; docs/BENCHMARKS.md "Memory of long bags")
    peaks = []
    for steps in (10_000, 40_000):
        result, planned = analytic_episode(ur5, n_steps=steps)
        bag.write_episode_bag(
            tmp_path / str(steps) / "ep",
            spec=ur5,
            result=result,
            planned=planned,
            metadata=episode_metadata(),
        )
        del result, planned
        peaks.append(peak_rss_mb(tmp_path / str(steps)))
    assert peaks[1] - peaks[0] < MEMORY_MARGIN_MB, peaks


def test_joint_states_that_outlive_the_controller(tmp_path: Path) -> None:
    # the last pairing joint state (0.4 ms after the last controller state) ends the
    # recording and so places the final window, with 5,000 joint states after it
    ep = paper_like("after", "pid", duration_s=16.0, motion_end_s=3.0)
    ep = dataclasses.replace(ep, joint_state_offset_ns=400_000, controller_state_until_ns=6 * 10**9)
    write_bag(tmp_path / "recs", ep)
    assert_report_inputs_equal(tmp_path / "recs")
