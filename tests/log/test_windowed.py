"""Long recordings read in windows (pipeline/log/windowed.py) against the whole read.

The windowed path is forced on small bags (``ReadOptions(stream_above_bytes=0)`` and small
windows), so each recording spans many windows and both reads can be compared row for row:
the windows put together are the whole read's frames, the decimated frames are its rows at
every k-th step, and the counts, end and notes agree.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal
from rosbags.rosbag2 import StoragePlugin

from pipeline.errors import RecordingError
from pipeline.log import bag, pairing, windowed
from pipeline.log.reader import ReadOptions, Recording, read_recording
from pipeline.robots import RobotSpec
from tests.log.test_external_bags import write_external_bag
from tests.log.test_salvage import chunk_offsets
from tests.log.test_writer import analytic_episode, episode_metadata

WINDOW = ReadOptions(stream_above_bytes=0, window_steps=300)


class Windows:
    """A sink that keeps every window (tests only: the report keeps partial metrics)."""

    def __init__(self) -> None:
        self.header: Recording | None = None
        self.samples: list[pl.DataFrame] = []
        self.states: list[pl.DataFrame] = []

    def begin(self, header: Recording) -> None:
        self.header = header

    def window(self, samples: pl.DataFrame, controller_states: pl.DataFrame) -> None:
        self.samples.append(samples)
        self.states.append(controller_states)


def both(path: Path, options: ReadOptions | None = None) -> tuple[Recording, Recording, Windows]:
    options = options or ReadOptions()
    whole = read_recording(path, options)
    sink = Windows()
    win = read_recording(
        path,
        ReadOptions(
            topics=options.topics,
            salvage=options.salvage,
            stream_above_bytes=0,
            window_steps=WINDOW.window_steps,
        ),
        sink=sink,
    )
    return whole, win, sink


def assert_same(whole: Recording, win: Recording, sink: Windows) -> None:
    n = len(whole.joint_names)
    assert whole.windows == 0 and whole.decimation == 1
    assert win.windows == len(sink.samples) > 3  # many windows, not one
    assert_frame_equal(pl.concat(sink.samples), whole.samples)
    assert_frame_equal(pl.concat(sink.states), whole.controller_states)
    assert win.sample_count == whole.samples.height // n
    assert win.controller_sample_count == whole.controller_states.height // n
    ends = [whole.samples["time_s"].max(), whole.controller_states["time_s"].max()]
    assert win.end_s == max(ends)  # type: ignore[type-var]
    t = whole.controller_states["time_s"].to_numpy()[::n]
    assert win.control_period_s == pytest.approx(float(np.median(np.diff(t))), rel=1e-9)
    assert win.notes == whole.notes
    assert (win.metadata, win.settings, win.joint_names) == (
        whole.metadata,
        whole.settings,
        whole.joint_names,
    )
    assert (win.topic_counts, win.decoded_messages, win.sha256, win.has_ground_truth) == (
        whole.topic_counts,
        whole.decoded_messages,
        whole.sha256,
        whole.has_ground_truth,
    )
    assert sink.header is not None and sink.header.settings == whole.settings
    if win.decimation == 1:
        assert_frame_equal(win.samples, whole.samples)
        assert_frame_equal(win.controller_states, whole.controller_states)


def kept_steps(frame: pl.DataFrame, n: int, k: int) -> pl.DataFrame:
    """Every k-th step of a tidy frame, and its last one."""
    steps = frame.height // n
    keep = sorted({*range(0, steps, k), steps - 1})
    return frame.filter(pl.Series(np.repeat(np.isin(np.arange(steps), keep), n)))


@pytest.fixture
def our_bag(ur5: RobotSpec, tmp_path: Path) -> Path:
    result, planned = analytic_episode(ur5, n_steps=3001)
    return bag.write_episode_bag(
        tmp_path / "ep",
        spec=ur5,
        result=result,
        planned=planned,
        metadata=episode_metadata(),
        joint_state_decimation=4,
    ).path


def test_our_bag_read_in_windows_is_the_whole_read(our_bag: Path) -> None:
    whole, win, sink = both(our_bag)
    assert whole.has_ground_truth
    assert_same(whole, win, sink)


def test_decimated_frames_keep_every_kth_step_and_the_last(
    our_bag: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(windowed, "MAX_KEPT_STEPS", 500)
    whole, win, sink = both(our_bag)
    assert_same(whole, win, sink)
    k = win.decimation
    assert k == 7  # ceil(3001 / 500)
    n = len(whole.joint_names)
    assert_frame_equal(win.controller_states, kept_steps(whole.controller_states, n, k))
    assert_frame_equal(win.samples, kept_steps(whole.samples, n, k))


@pytest.mark.parametrize(
    ("distro", "storage"),
    [("humble", StoragePlugin.MCAP), ("jazzy", StoragePlugin.SQLITE3)],
    ids=["humble-mcap", "jazzy-db3"],
)
def test_a_robots_bag_read_in_windows_is_the_whole_read(
    tmp_path: Path, distro: str, storage: StoragePlugin
) -> None:
    # wall-clock stamps, a gripper in the joint list and a gripper-only publisher,
    # /joint_states at a third of the controller's rate
    path = tmp_path / "robot"
    write_external_bag(path, distro=distro, storage=storage, js_every=3)
    whole, win, sink = both(path)
    assert whole.samples.height // 3 < whole.controller_states.height // 3
    assert_same(whole, win, sink)


def test_a_window_cut_between_a_joint_state_and_its_controller_state(tmp_path: Path) -> None:
    # each /joint_states stamp is 0.4 periods before the /controller_state it goes with: a
    # window ending at a controller-state stamp holds the joint state but not its partner
    path = tmp_path / "robot"
    s = write_external_bag(path, distro="jazzy", storage=StoragePlugin.MCAP, js_offset_ns=-800_000)
    whole, win, sink = both(path)
    assert_same(whole, win, sink)
    assert whole.samples.height == 3 * len(s["t_ns"])  # every joint state paired
    cut = sink.states[1]["stamp_ns"].min()
    before = sink.samples[0].filter(pl.col("stamp_ns") == pl.col("stamp_ns").max())
    assert before["stamp_ns"][0] == cut - 800_000  # the window's last joint state ...
    partner = sink.states[1].filter(pl.col("stamp_ns") == cut)  # ... pairs with the next's
    assert before["reference_position_rad"].to_list() == partner["reference_position_rad"].to_list()


def test_a_salvaged_bag_read_in_windows_is_the_whole_read(our_bag: Path) -> None:
    mcap = next(our_bag.glob("*.mcap"))
    starts = chunk_offsets(mcap)
    cut = (starts[-3] + starts[-2]) // 2
    mcap.write_bytes(mcap.read_bytes()[:cut])
    whole, win, sink = both(our_bag, ReadOptions(salvage=True))
    assert whole.salvaged and win.salvaged
    assert_same(whole, win, sink)


def test_stamps_going_back_across_chunks_are_refused_in_one_line(tmp_path: Path) -> None:
    from tests.analysis.bagfactory import paper_like, write_bag

    ep = paper_like("back", "pid", duration_s=4.0)
    stamps = ep.stamp_ns.copy()
    stamps[-200:] -= 3_000_000_000  # the last 200 messages stamped 3 s early
    path = write_bag(tmp_path, ep.__class__(**{**ep.__dict__, "stamp_ns": stamps}))
    read_recording(path)  # read whole: sorted, as always
    with pytest.raises(RecordingError, match="stamps go back in time across chunks") as err:
        read_recording(path, WINDOW)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


@pytest.mark.parametrize("start_s", [4, 0], ids=["pause", "late-start"])
def test_a_topic_that_pauses_does_not_hold_the_others_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, start_s: int
) -> None:
    # /joint_states silent for 12 s of 20 s (6,000 controller states at 500 Hz), in the
    # middle or from the start: the controller states of the pause must be windowed as
    # they come, not buffered until the joint states resume (memory would grow with the
    # length of the pause)
    from tests.analysis.bagfactory import paper_like, write_bag

    ep = paper_like("pause", "pid", duration_s=20.0, motion_end_s=3.0)
    gap = (start_s * 10**9, (start_s + 12) * 10**9)
    path = write_bag(tmp_path, replace(ep, joint_state_gap_ns=gap))
    most = [0]
    push = pairing.Stream.push

    def counting(self: pairing.Stream, stamps: np.ndarray, arrays: dict) -> None:
        push(self, stamps, arrays)
        most[0] = max(most[0], self.stamps.size)

    whole = read_recording(path)  # one window of every row: not counted
    monkeypatch.setattr(pairing.Stream, "push", counting)
    sink = Windows()
    win = read_recording(path, WINDOW, sink=sink)
    assert_same(whole, win, sink)
    assert whole.samples.height // 6 == 10_001 - 6_000  # the pause is in the bag
    # a batch of chunks, a window and up to GAP_NS of the others (measured: 1,203 rows;
    # 6,253 when the pause was buffered)
    assert most[0] < 2_500, most[0]


def test_joint_states_published_long_after_the_controller_stops(tmp_path: Path) -> None:
    # /joint_states stamped 0.4 ms after the controller state it goes with, and published
    # for 10 s (5,000 messages) after the controller stopped: the last joint state that
    # pairs (0.4 ms after the last controller state) ends the recording, in both reads
    from tests.analysis.bagfactory import paper_like, write_bag

    ep = paper_like("after", "pid", duration_s=16.0, motion_end_s=3.0)
    ep = replace(ep, joint_state_offset_ns=400_000, controller_state_until_ns=6 * 10**9)
    path = write_bag(tmp_path, ep)
    whole, win, sink = both(path)
    assert_same(whole, win, sink)
    assert whole.samples["stamp_ns"].max() == 6 * 10**9 - 2_000_000 + 400_000
    assert not any("estimated" in n for n in win.notes)


@pytest.mark.parametrize("n", [1, 2, 7, 10_000, 10_001])
def test_the_period_from_pass_1_is_the_median_step_of_every_stamp(n: int) -> None:
    rng = np.random.default_rng(n)
    t = np.cumsum(rng.integers(0, 3_000_000, n)).astype(np.int64)  # with duplicates
    stats = windowed._StampStats()
    for k in range(0, n, 997):
        stats.add(t[k : k + 997], Path("x"))
    expected = float(np.median(np.diff(t))) if n > 1 else 1.0
    assert stats.period_ns() == expected
    assert stats.count == n and (stats.first, stats.last) == (int(t[0]), int(t[-1]))


def test_the_stamp_step_histogram_of_jittered_wall_clock_stamps_stays_small() -> None:
    # 1 kHz stamps with +-0.5 ms of jitter (a real robot's clock): some 630,000 distinct
    # steps in 1,000,000; a dict held them in 41 MB (16 bytes a step as arrays)
    import tracemalloc

    rng = np.random.default_rng(0)
    n = 1_000_000
    t = np.cumsum(1_000_000 + rng.integers(-500_000, 500_000, n)).astype(np.int64)
    tracemalloc.start()
    try:
        stats = windowed._StampStats()
        for k in range(0, n, 5000):
            stats.add(t[k : k + 5000], Path("x"))
        period = stats.period_ns()
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert period == float(np.median(np.diff(t)))
    assert held < 20e6, held


def test_what_the_sink_raises_is_not_blamed_on_the_recording(our_bag: Path) -> None:
    # the report's metrics run inside the read: their failure is not "cannot decode the
    # recording" (which --skip-bad would skip as a bad bag)
    class Failing(Windows):
        def window(self, samples: pl.DataFrame, controller_states: pl.DataFrame) -> None:
            raise ZeroDivisionError("in the sink")

    for salvage in (False, True):
        options = replace(WINDOW, salvage=salvage)
        with pytest.raises(ZeroDivisionError, match="in the sink"):
            read_recording(our_bag, options, sink=Failing())
