"""A Rerun writer that cannot finish is abandoned within a bound, with one OSError."""

from __future__ import annotations

import errno
import threading
import time
from pathlib import Path

import pytest

from pipeline.report import rerun_rrd
from pipeline.report.inputs import ReportData


def _stuck(release: threading.Event) -> object:
    def write(data: ReportData, path: Path) -> list[str]:
        release.wait(30)  # as rerun-sdk's file sink blocks once the disk is full
        return []

    return write


@pytest.mark.parametrize("full", [True, False])
def test_a_stuck_writer_is_abandoned_within_the_bound(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, full: bool
) -> None:
    release = threading.Event()
    unregistered: list[bool] = []
    monkeypatch.setattr(rerun_rrd, "_write_rrd", _stuck(release))
    monkeypatch.setattr(rerun_rrd, "_disk_full", lambda folder: full)
    monkeypatch.setattr(rerun_rrd, "DISK_FULL_GRACE_S", 0.5)
    monkeypatch.setattr(rerun_rrd, "STALL_S", 1.0)
    monkeypatch.setattr(rerun_rrd.rr, "unregister_shutdown", lambda: unregistered.append(True))
    started = time.monotonic()
    try:
        with pytest.raises(OSError) as info:
            rerun_rrd.write_rrd(None, tmp_path / "recording.rrd")  # type: ignore[arg-type]
    finally:
        release.set()
    assert time.monotonic() - started < 5
    assert info.value.errno == (errno.ENOSPC if full else errno.EIO)
    assert unregistered == [True]  # rerun's exit-time flush would block on the stuck sink


def test_file_writer_shut_down_becomes_an_os_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def write(data: ReportData, path: Path) -> list[str]:
        raise RuntimeError("File-writer thread shut down prematurely")

    monkeypatch.setattr(rerun_rrd, "_write_rrd", write)
    monkeypatch.setattr(rerun_rrd, "_disk_full", lambda folder: True)
    with pytest.raises(OSError, match="No space left on device; the Rerun file writer stopped"):
        rerun_rrd.write_rrd(None, tmp_path / "recording.rrd")  # type: ignore[arg-type]


def test_other_errors_of_the_writer_pass_through(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def write(data: ReportData, path: Path) -> list[str]:
        raise ValueError("a bug")

    monkeypatch.setattr(rerun_rrd, "_write_rrd", write)
    with pytest.raises(ValueError, match="a bug"):
        rerun_rrd.write_rrd(None, tmp_path / "recording.rrd")  # type: ignore[arg-type]
