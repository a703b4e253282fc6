"""User-named output files: device, FIFO, folder refused; symlink written through; mode kept."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.fsutil import OutputPathError, atomic_write_bytes


def test_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "model.yaml"
    os.mkfifo(fifo)
    with pytest.raises(OutputPathError, match="is a FIFO"):
        atomic_write_bytes(fifo, b"x")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_directory_is_refused(tmp_path: Path) -> None:
    with pytest.raises(OutputPathError, match="is a directory"):
        atomic_write_bytes(tmp_path, b"x")


@pytest.mark.skipif(os.geteuid() != 0, reason="mknod of a device needs root")
def test_a_device_node_is_refused_and_kept(tmp_path: Path) -> None:
    dev = tmp_path / "null"
    os.mknod(dev, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # a /dev/null of our own
    with pytest.raises(OutputPathError, match="is a device"):
        atomic_write_bytes(dev, b"x")
    assert stat.S_ISCHR(os.lstat(dev).st_mode)


def test_a_symlink_is_written_through_and_stays_a_link(tmp_path: Path) -> None:
    target = tmp_path / "real" / "model.yaml"
    target.parent.mkdir()
    target.write_bytes(b"old")
    link = tmp_path / "model.yaml"
    link.symlink_to(target)
    atomic_write_bytes(link, b"new")
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_bytes() == b"new"


def test_a_symlink_to_a_fifo_is_refused(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe")
    (tmp_path / "out").symlink_to(tmp_path / "pipe")
    with pytest.raises(OutputPathError, match=r"is a FIFO \(through the symlink"):
        atomic_write_bytes(tmp_path / "out", b"x")


def test_the_files_mode_is_kept(tmp_path: Path) -> None:
    path = tmp_path / "secret.yaml"
    path.write_bytes(b"old")
    path.chmod(0o600)
    atomic_write_bytes(path, b"new")
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and path.read_bytes() == b"new"


def test_identify_fit_out_a_fifo_is_one_line_before_reading(tmp_path: Path) -> None:
    fifo = tmp_path / "m.yaml"
    os.mkfifo(fifo)
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "identify", "fit", str(tmp_path / "no-such-bag"),
         "--out", str(fifo)],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0] == f"error: {fifo}: is a FIFO; name a regular file to write"
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
