"""The reader's two modes are one path: a recording streamed in windows gives the value the
whole read gives (which is that path with one window).

The bags here are written by ``rosbags`` (an independent writer), with what makes pairing
hard: stamps repeated in both topics (paired run with run), or in ``/joint_states`` only
(paired with the nearest controller state), and header stamps out of order within a batch of
chunks (the recorder's log times stay in order). Not here, as the two modes differ there by
design (pipeline/log/windowed.py): both kinds of repeats in one recording, and stamps going
back across batches of chunks (refused in windows: tests/log/test_windowed.py).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal
from rosbags.rosbag2 import StoragePlugin, Writer

from pipeline.log.reader import Recording, read_recording
from tests.log.rosbags_msgs import RosMsgs
from tests.log.test_windowed import WINDOW, Windows, assert_same

JOINTS = ("a", "b", "c")
T0_NS = 1_700_000_000_000_000_000
PERIOD_NS = 2_000_000
STEPS = 1500
SWAPPED = (250, 901)  # this step's and the next one's messages are written swapped


def write_hard_bag(
    path: Path, storage: StoragePlugin, *, both_twice: tuple[int, ...], js_twice: tuple[int, ...]
) -> None:
    """``both_twice``: steps whose stamp both topics carry twice (the copy with other
    values); ``js_twice``: steps whose stamp ``/joint_states`` alone carries twice."""
    m = RosMsgs("jazzy")
    JS = m.type("sensor_msgs/msg/JointState")
    CS = m.type("control_msgs/msg/JointTrajectoryControllerState")
    order = list(range(STEPS))
    for k in SWAPPED:
        order[k], order[k + 1] = order[k + 1], order[k]
    log_ns = T0_NS
    with Writer(path, version=9, storage_plugin=storage) as w:
        c_cs = w.add_connection("/controller_state", CS.__msgtype__, typestore=m.store)
        c_js = w.add_connection("/joint_states", JS.__msgtype__, typestore=m.store)
        for k in order:
            stamp = T0_NS + k * PERIOD_NS
            for copy in range(2 if k in both_twice else 1):
                ref = np.sin(0.01 * k + np.arange(3)) + copy
                q = ref - 1e-3 * np.cos(0.02 * k + np.arange(3))
                cs = m.controller_state(
                    ns=stamp,
                    joints=list(JOINTS),
                    reference=m.point(ref),
                    feedback=m.point(q),
                    error=m.point(ref - q),
                    output=m.point(eff=2.0 * q),
                )
                log_ns += 1000
                w.write(c_cs, log_ns, m.cdr(cs))
                for extra in range(2 if k in js_twice else 1):
                    js = m.joint_state(
                        ns=stamp,
                        names=list(JOINTS),
                        position=q + extra,
                        velocity=q * 0.5,
                        effort=2.0 * q,
                    )
                    log_ns += 1000
                    w.write(c_js, log_ns, m.cdr(js))


def value(rec: Recording) -> dict[str, Any]:
    """Every field but the frames and what only a windowed read counts (windows, counts,
    end, period)."""
    skip = {"samples", "controller_states", "windows", "sample_count"}
    skip |= {"controller_sample_count", "end_s", "control_period_s"}
    return {f.name: getattr(rec, f.name) for f in dataclasses.fields(rec) if f.name not in skip}


REPEATS = {"in-both": ((100, 700, 1200), ()), "in-joint-states": ((), (400, 1300))}


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3], ids=str)
@pytest.mark.parametrize("repeats", REPEATS)
def test_a_bag_streamed_in_windows_is_the_bag_read_whole(
    tmp_path: Path, storage: StoragePlugin, repeats: str
) -> None:
    both_twice, js_twice = REPEATS[repeats]
    path = tmp_path / "hard"
    write_hard_bag(path, storage, both_twice=both_twice, js_twice=js_twice)
    whole = read_recording(path)
    sink = Windows()
    win = read_recording(path, WINDOW, sink=sink)
    assert_same(whole, win, sink)
    assert win.decimation == 1
    assert_frame_equal(win.samples, whole.samples)
    assert_frame_equal(win.controller_states, whole.controller_states)
    assert value(win) == value(whole)

    # and the value is the one written: every stamp in order, repeats kept as rows
    n = len(JOINTS)
    assert whole.controller_states.height == (STEPS + len(both_twice)) * n
    stamps = whole.samples["stamp_ns"].to_numpy()[::n]
    assert stamps.size == STEPS + len(both_twice) + len(js_twice)
    assert bool((np.diff(stamps) >= 0).all())
    assert np.array_equal(np.unique(stamps), T0_NS + PERIOD_NS * np.arange(STEPS))
    a = whole.samples.filter(pl.col("joint") == "a")
    for k in both_twice:  # run with run: first with first
        at = a.filter(pl.col("stamp_ns") == T0_NS + k * PERIOD_NS)
        ref = np.sin(0.01 * k)
        assert at["reference_position_rad"].to_list() == pytest.approx([ref, ref + 1])
    for k in js_twice:  # both pair with the one controller state
        at = a.filter(pl.col("stamp_ns") == T0_NS + k * PERIOD_NS)
        assert at.height == 2 and at["reference_position_rad"].n_unique() == 1
        assert at["position_rad"][1] - at["position_rad"][0] == pytest.approx(1.0)
    for k in SWAPPED:  # sorted back: the reference at each stamp is its own step's
        at = a.filter(pl.col("stamp_ns") == T0_NS + k * PERIOD_NS)
        assert at["reference_position_rad"].to_list() == pytest.approx([np.sin(0.01 * k)])
    assert not any("dropped" in note for note in whole.notes), whole.notes
