"""A long-lived process can call run_report again and again: no thread outlives a call.

rerun-sdk's recording streams run threads (RecordingStream, ChunkBatcher) until they
are disconnected and freed; the default blueprint even has a stream of its own. Python's
``threading`` does not see those native threads, so the OS count (/proc/self/task) is the
one that matters.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from pipeline.stages.report import run_report
from tests.analysis.bagfactory import paper_like, write_bag


def _os_threads() -> int:
    return len(os.listdir("/proc/self/task"))


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc")
def test_repeated_reports_do_not_grow_the_thread_count(tmp_path):
    rec = tmp_path / "rec"
    for ctrl in ("pid", "ctc"):
        write_bag(rec, paper_like(f"paper-{ctrl}", ctrl, duration_s=0.5, motion_end_s=0.3))
    # the first call may start pools that live for the process (polars, tokio); later
    # calls must not add to them
    run_report(recordings_dir=rec, out_dir=tmp_path / "rep")
    py_after_first, os_after_first = threading.active_count(), _os_threads()
    for k in range(4):
        run_report(recordings_dir=rec, out_dir=tmp_path / f"rep{k % 2}")
    assert threading.active_count() == py_after_first
    assert _os_threads() <= os_after_first, "run_report left native threads running"
    assert (tmp_path / "rep0" / "recording.rrd").stat().st_size > 0
