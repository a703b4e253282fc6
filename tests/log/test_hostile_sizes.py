"""Hostile sizes and kinds: counts and lengths from a file are bounded by the bytes left,
zeros are refused at once, files that are not files and folders that cannot be listed are
named, symlinked bag folders are read."""

from __future__ import annotations

import os
import re
import resource
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path
from typing import IO

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType

from pipeline.errors import RecordingError
from pipeline.log.cdr import min_bytes
from pipeline.log.mcap import MAGIC, McapScan
from pipeline.log.msgdef import parse_msgdef
from pipeline.log.reader import read_recording
from pipeline.log.rosbag2 import find_recordings
from tests.analysis.bagfactory import mcap_file, msgdef, paper_like, write_bag

ROOT = Path(__file__).resolve().parents[2]
# Each JointTrajectoryControllerState ends with 6 MultiDOFJointTrajectoryPoints of 20 bytes
# (3 empty sequences + a Duration); the first one's `transforms` count sits 120 bytes before
# the end, after `multi_dof_joint_names` (empty).
TRANSFORMS_COUNT_FROM_END = 120


def repair_chunk_crcs(path: Path) -> None:
    """Recompute the CRC of every (uncompressed) chunk: the file is self-consistent again."""
    data = bytearray(path.read_bytes())
    pos = 8
    while pos < len(data) - 8:
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if data[pos] == 0x06:
            body = pos + 9
            (n,) = struct.unpack_from("<I", data, body + 28)
            assert n == 0, "written without compression"
            off = body + 32
            (records,) = struct.unpack_from("<Q", data, off)
            crc = zlib.crc32(data[off + 8 : off + 8 + records])
            struct.pack_into("<I", data, body + 24, crc)
        pos += 9 + length
    path.write_bytes(bytes(data))


def corrupted_count_bag(root: Path) -> Path:
    """A 1.5 s bag whose 300th /controller_state message claims 2**31 transforms, CRCs
    repaired (the walk of many messages at once used to loop over that count)."""
    ep = paper_like("hostile", "pid", duration_s=1.5, motion_end_s=1.0)
    rec = write_bag(root, ep, compression=CompressionType.NONE)
    path = mcap_file(rec)
    with open(path, "rb") as fh:
        msgs = [m.data for _, _, m in make_reader(fh).iter_messages(topics=["/controller_state"])]
    data = bytearray(path.read_bytes())
    at = data.find(msgs[300]) + len(msgs[300]) - TRANSFORMS_COUNT_FROM_END
    assert struct.unpack_from("<I", data, at) == (0,)
    struct.pack_into("<I", data, at, 0x7FFFFFF0)
    path.write_bytes(bytes(data))
    repair_chunk_crcs(path)
    return rec


def test_min_bytes_bounds_a_transform_and_a_controller_state() -> None:
    types = parse_msgdef("geometry_msgs/msg/Transform", msgdef("tf2_msgs/msg/TFMessage"))
    assert min_bytes(types, "geometry_msgs/msg/Transform") == 7 * 8


@pytest.mark.slow
def test_corrupted_sequence_count_is_refused_in_one_line_under_a_memory_limit(
    tmp_path: Path,
) -> None:
    corrupted_count_bag(tmp_path / "recordings")

    started = time.monotonic()
    done = _report_under_memory_limit(tmp_path, "recordings")
    assert done.returncode == 1, done.stderr[-2000:]
    assert done.stderr.count("\n") == 1 and done.stderr.startswith("error: "), done.stderr
    assert "multi_dof_reference.transforms: a count of 2,147,483,632" in done.stderr
    assert "MemoryError" not in done.stderr
    assert time.monotonic() - started < 120


# About 4.6 GB of address space (`ulimit -v 4500000`): a report of a good bag fits (its
# virtual size, imports, thread stacks and malloc arenas, grew past 3 GB in a fresh venv
# once the report drew task-space figures), the corrupted count used to need > 6.9 GB.
ADDRESS_SPACE_LIMIT = 4_500_000 * 1024


def _report_under_memory_limit(cwd: Path, recordings: str) -> subprocess.CompletedProcess[str]:
    def limit() -> None:  # in the child before exec, as `ulimit -v` does
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE_LIMIT, ADDRESS_SPACE_LIMIT))

    return subprocess.run(
        [sys.executable, "-m", "pipeline", "report", "--recordings", recordings],
        preexec_fn=limit,  # (pytest may have threads; setrlimit is async-signal-safe)
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.mark.slow
def test_a_good_bag_reports_under_the_memory_limit(tmp_path: Path) -> None:
    """The control: the limit itself is not what refuses the corrupted bag."""
    write_bag(tmp_path / "good", paper_like("good", "pid", duration_s=1.5, motion_end_s=1.0))
    done = _report_under_memory_limit(tmp_path, "good")
    assert done.returncode == 0, done.stderr[-2000:]


def _zeros_after_header(path: Path, size: int) -> None:
    with open(path, "wb") as fh:
        fh.write(MAGIC)
        fh.truncate(size)  # sparse: 100 MB of zeros that take no disk


class _Counting(McapScan):
    read_bytes = 0

    def _read(self, fh: IO[bytes], n: int) -> bytes:
        data = super()._read(fh, n)
        self.read_bytes += len(data)
        return data


@pytest.mark.parametrize("size", [100, 100 * 1024 * 1024])
def test_mcap_header_followed_by_zeros_is_refused_without_walking_them(
    tmp_path: Path, size: int
) -> None:
    path = tmp_path / "zeros.mcap"
    _zeros_after_header(path, size)
    scan = _Counting(path)
    with pytest.raises(RecordingError, match="record at byte 8 has opcode 0x00"):
        scan.run()
    assert scan.read_bytes <= 17  # the magic and one record header, whatever the size


def test_zeros_inside_the_data_section_are_refused_at_once(tmp_path: Path) -> None:
    rec = write_bag(tmp_path, paper_like("z", "pid", duration_s=0.5, motion_end_s=0.2))
    path = mcap_file(rec)
    data = path.read_bytes()
    first_chunk = data.index(b"\x06", 8 + 9 + struct.unpack_from("<Q", data, 9)[0])
    path.write_bytes(data[:first_chunk] + bytes(50 * 1024 * 1024))
    scan = _Counting(path)
    with pytest.raises(RecordingError, match=f"record at byte {first_chunk} has opcode 0x00"):
        scan.run()
    assert scan.read_bytes < first_chunk + 64


def test_chunk_claiming_more_than_its_bytes_can_expand_to_is_refused(tmp_path: Path) -> None:
    rec = write_bag(tmp_path, paper_like("big", "pid", duration_s=0.5, motion_end_s=0.2))
    path = mcap_file(rec)
    data = bytearray(path.read_bytes())
    chunk = data.index(b"\x06", 8 + 9 + struct.unpack_from("<Q", data, 9)[0])
    struct.pack_into("<Q", data, chunk + 9 + 16, 1 << 50)  # uncompressed_size: 1 PiB
    path.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match=r"claims 1,125,899,906,842,624 uncompressed bytes"):
        read_recording(rec)


@pytest.mark.parametrize("kind", ["fifo", "dev_zero"])
def test_fifo_or_device_named_mcap_is_refused_as_not_a_regular_file(
    tmp_path: Path, kind: str
) -> None:
    path = tmp_path / "recordings" / "x.mcap"
    path.parent.mkdir()
    if kind == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to("/dev/zero")
    assert find_recordings(tmp_path / "recordings") == [path]
    what = "a FIFO" if kind == "fifo" else "a character device"
    with pytest.raises(RecordingError, match=re.escape(f"not a regular file ({what})")):
        read_recording(path)


def test_folder_that_cannot_be_listed_is_reported(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_bag(tmp_path / "recordings", paper_like("a", "pid", duration_s=0.3, motion_end_s=0.1))
    locked = tmp_path / "recordings" / "team-b"
    locked.mkdir()
    locked.chmod(0)
    try:
        if os.geteuid() == 0:  # root lists anything: make the kernel's answer by hand
            real = os.scandir

            def scandir(path: str | os.PathLike[str] = ".") -> object:
                if Path(path) == locked:
                    raise PermissionError(13, "Permission denied", str(path))
                return real(path)

            monkeypatch.setattr(os, "scandir", scandir)
        with pytest.raises(RecordingError, match=r"team-b: cannot list this folder \(Permission"):
            find_recordings(tmp_path / "recordings")
    finally:
        locked.chmod(0o755)


def test_symlinked_bag_folders_are_followed_once(tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    bag = write_bag(elsewhere, paper_like("linked", "pid", duration_s=0.3, motion_end_s=0.1))
    root = tmp_path / "recordings"
    root.mkdir()
    (root / "linked").symlink_to(bag, target_is_directory=True)
    (root / "loop").symlink_to(root, target_is_directory=True)  # must not walk forever
    assert find_recordings(root) == [root / "linked"]
    assert read_recording(root / "linked").episode == "linked"
