"""Damaged rosbag2 sqlite3 bags (written by rosbags' Writer, Humble and Jazzy stores): refused
in one line, salvaged up to the damage with ``salvage``; a killed recorder's ``-wal`` side
file read without touching the bag."""

from __future__ import annotations

import hashlib
import shutil
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin

from pipeline.errors import RecordingError
from pipeline.log.reader import ReadOptions, read_recording
from tests.log.test_external_bags import JOINTS, N, write_external_bag

SALVAGE = ReadOptions(salvage=True)
# Humble's .db3 files carry no message definitions; Jazzy's do
DISTROS = [("humble", True), ("jazzy", False)]


def db3_bag(path: Path, distro: str, drop: bool) -> tuple[Path, dict[str, np.ndarray]]:
    s = write_external_bag(
        path, distro=distro, storage=StoragePlugin.SQLITE3, drop_definitions=drop
    )
    [db] = path.glob("*.db3")
    return db, s


def rows(db: Path) -> list[tuple[int, str, int]]:
    """(id, topic, stamp) of every message row in id order, read from the intact file."""
    with sqlite3.connect(db) as con:
        return [
            (int(i), str(t), int(st))
            for i, t, st in con.execute(
                "SELECT m.id, t.name, m.timestamp FROM messages m JOIN topics t "
                "ON m.topic_id = t.id ORDER BY m.id"
            )
        ]


def page_of(db: Path, table: str) -> tuple[int, int]:
    """(page size, a leaf page of ``table``'s b-tree in the middle of the file)."""
    with sqlite3.connect(db) as con:
        size = con.execute("PRAGMA page_size").fetchone()[0]
        pages = [
            p
            for (p,) in con.execute(
                "SELECT pageno FROM dbstat WHERE name = ? AND pagetype = 'leaf'", (table,)
            )
        ]
    return size, pages[len(pages) // 2]


@pytest.mark.parametrize(("distro", "drop"), DISTROS)
def test_a_truncated_db3_is_refused_then_salvaged_to_a_prefix(
    tmp_path: Path, distro: str, drop: bool
) -> None:
    db, s = db3_bag(tmp_path / "run", distro, drop)
    every = rows(db)
    data = db.read_bytes()
    db.write_bytes(data[: len(data) * 6 // 10])
    with pytest.raises(RecordingError) as err:
        read_recording(tmp_path / "run")
    message = str(err.value)
    assert "\n" not in message and str(db) in message and "truncated" in message
    assert f"{len(data)} bytes" in message  # what the header says the file should be

    rec = read_recording(tmp_path / "run", SALVAGE)
    assert rec.salvaged
    [note] = [n for n in rec.notes if n.startswith("salvaged")]
    read = int(note.split(" message rows read")[0].rsplit(" ", 1)[1])
    assert 0 < read < len(every)
    # The rows read are the first ones in id (recording) order: the samples are the
    # joint-state / controller-state pairs among them.
    first = every[:read]
    js_stamps = {st for _, t, st in first if t == "/joint_states"}
    cs_stamps = {st for _, t, st in first if t.endswith("controller_state")}
    paired = sorted(js_stamps & cs_stamps)
    frame = rec.samples.filter(rec.samples["joint"] == "wrist").sort("stamp_ns")
    np.testing.assert_array_equal(frame["stamp_ns"].to_numpy(), np.array(paired))
    k = frame.height
    np.testing.assert_array_equal(frame["error_rad"].to_numpy(), s["err"][:k, 2])
    # the table's last page is cut off, so sqlite cannot count the rows lost; the share is
    # of the messages metadata.yaml declares (not of the bytes that survived)
    cut = len(data) * 6 // 10
    assert f"last {len(data) - cut} bytes" in note
    lost = len(every) - read
    assert f"{lost} of the {len(every)} messages metadata.yaml declares" in note
    assert rec.salvage_lost_pct == pytest.approx(100 * lost / len(every))


@pytest.mark.parametrize(("distro", "drop"), DISTROS)
def test_a_damaged_message_page_is_refused_and_salvage_stops_there(
    tmp_path: Path, distro: str, drop: bool
) -> None:
    db, s = db3_bag(tmp_path / "run", distro, drop)
    every = rows(db)
    page_size, page = page_of(db, "messages")
    data = bytearray(db.read_bytes())
    data[(page - 1) * page_size] = 0x55  # not a b-tree page type: sqlite sees the damage
    db.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="malformed") as err:
        read_recording(tmp_path / "run")
    assert "\n" not in str(err.value) and "--salvage" in str(err.value)

    rec = read_recording(tmp_path / "run", SALVAGE)
    assert rec.salvaged
    [note] = [n for n in rec.notes if n.startswith("salvaged")]
    read = int(note.split(" message rows read")[0].rsplit(" ", 1)[1])
    assert f"{len(every) - read} of {len(every)} message rows" in note  # max(id) still known
    assert rec.salvage_lost_pct == pytest.approx(100 * (len(every) - read) / len(every))
    frame = rec.samples.filter(rec.samples["joint"] == "wrist").sort("stamp_ns")
    k = frame.height
    assert 0 < k < N
    np.testing.assert_array_equal(frame["stamp_ns"].to_numpy(), s["t_ns"][:k])
    np.testing.assert_array_equal(frame["reference_position_rad"].to_numpy(), s["ref"][:k, 2])


def test_a_damaged_timestamp_index_loses_nothing_under_salvage(tmp_path: Path) -> None:
    db, s = db3_bag(tmp_path / "run", "jazzy", False)
    page_size, page = page_of(db, "timestamp_idx")
    data = bytearray(db.read_bytes())
    data[(page - 1) * page_size] = 0x55
    db.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="malformed"):
        read_recording(tmp_path / "run")
    rec = read_recording(tmp_path / "run", SALVAGE)
    # every row is readable through the table itself: the whole episode, in time order
    frame = rec.samples.filter(rec.samples["joint"] == JOINTS[0]).sort("stamp_ns")
    np.testing.assert_array_equal(frame["stamp_ns"].to_numpy(), s["t_ns"])
    np.testing.assert_array_equal(frame["error_rad"].to_numpy(), s["err"][:, 0])


def test_damage_before_the_first_message_cannot_be_salvaged(tmp_path: Path) -> None:
    db, _ = db3_bag(tmp_path / "run", "jazzy", False)
    page_size, _ = page_of(db, "messages")
    with sqlite3.connect(db) as con:
        [(first,)] = con.execute(
            "SELECT min(pageno) FROM dbstat WHERE name = 'messages' AND pagetype = 'leaf'"
        )
    data = bytearray(db.read_bytes())
    data[(first - 1) * page_size] = 0x55
    db.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="nothing to salvage") as err:
        read_recording(tmp_path / "run", SALVAGE)
    assert "\n" not in str(err.value)


def test_an_intact_db3_read_with_salvage_is_not_marked(tmp_path: Path) -> None:
    db3_bag(tmp_path / "run", "humble", True)
    rec = read_recording(tmp_path / "run", SALVAGE)
    assert not rec.salvaged and rec.salvage_lost_pct is None
    assert not any(n.startswith("salvaged") for n in rec.notes)


# A recorder killed (SIGKILL) with rosbag2's "resilient" preset (journal_mode=WAL): its last
# commits are in the -wal side file, the main file does not have them yet.
_KILLED_RECORDER = """
import os, signal, sqlite3, sys
db, keep = sys.argv[1], int(sys.argv[2])
con = sqlite3.connect(db, isolation_level=None)
tail = con.execute("SELECT * FROM messages WHERE id > ? ORDER BY id", (keep,)).fetchall()
con.execute("DELETE FROM messages WHERE id > ?", (keep,))
con.execute("PRAGMA journal_mode=WAL")
con.execute("PRAGMA wal_autocheckpoint=0")
con.execute("BEGIN")
con.executemany("INSERT INTO messages VALUES (?, ?, ?, ?)", tail)
con.execute("COMMIT")
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_wal_mode_bag_closed_cleanly_is_read_without_side_files(tmp_path: Path) -> None:
    db, s = db3_bag(tmp_path / "run", "jazzy", False)
    with sqlite3.connect(db) as con:  # rosbag2's "resilient" preset, closed: no -wal left
        con.execute("PRAGMA journal_mode=WAL")
    con.close()
    assert db.read_bytes()[18:20] == b"\x02\x02"  # the header says WAL
    before = _state(tmp_path / "run")
    rec = read_recording(tmp_path / "run")
    # a plain read-only connection would leave run.db3-wal and run.db3-shm behind
    assert _state(tmp_path / "run") == before
    assert rec.samples["stamp_ns"].n_unique() == s["t_ns"].size


def _state(folder: Path) -> dict[str, tuple[str, int]]:
    return {
        p.name: (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
        for p in sorted(folder.iterdir())
    }


@pytest.mark.parametrize(
    ("salvage", "windowed"),
    [(False, False), (True, False), (False, True)],
    ids=["plain", "salvage", "windowed"],
)
def test_a_killed_recorders_wal_is_read_and_the_bag_left_untouched(
    tmp_path: Path, salvage: bool, windowed: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    db, s = db3_bag(tmp_path / "run", "jazzy", False)
    total = len(rows(db))
    keep = total // 2
    done = subprocess.run([sys.executable, "-c", _KILLED_RECORDER, str(db), str(keep)], check=False)
    assert done.returncode != 0  # killed, the connection never closed
    wal = db.with_name(db.name + "-wal")
    assert wal.stat().st_size > 0
    with sqlite3.connect(f"file:{db}?immutable=1", uri=True) as con:  # the main file alone
        assert con.execute("SELECT count(*) FROM messages").fetchone()[0] == keep
    before = _state(tmp_path / "run")

    # windowed: two passes over it (and the temporary copies), as for a long recording
    options = ReadOptions(salvage=salvage, stream_above_bytes=0 if windowed else None)
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temporary))
    copied: list[str] = []
    copyfile = shutil.copyfile

    def counting(src: Path, dst: Path) -> Path:
        copied.append(Path(src).name)
        return copyfile(src, dst)

    monkeypatch.setattr(shutil, "copyfile", counting)
    rec = read_recording(tmp_path / "run", options)
    assert _state(tmp_path / "run") == before  # no byte, no file, no mtime changed
    assert not any(temporary.iterdir())  # the copies are gone
    # one copy for the whole read, however many passes it makes (windowed: 2-3)
    assert sorted(copied) == sorted([db.name, wal.name])
    assert rec.windows > 0 if windowed else rec.windows == 0
    assert not rec.salvaged
    assert any(wal.name in n and "did not close" in n for n in rec.notes)
    frame = rec.samples.filter(rec.samples["joint"] == JOINTS[1]).sort("stamp_ns")
    np.testing.assert_array_equal(frame["stamp_ns"].to_numpy(), s["t_ns"])
    np.testing.assert_array_equal(frame["error_rad"].to_numpy(), s["err"][:, 1])
