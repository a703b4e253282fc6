"""rosbag2's sqlite3 storage (``.db3``, Humble's default): read as the MCAP scanner reads.

A ``.db3`` has ``topics`` (name, type, serialization format) and ``messages`` (topic id,
timestamp, CDR bytes); Iron and later also store the ``message_definitions`` (the same
``ros2msg`` text MCAP schemas carry). Humble's files have none: the definitions then come
from :mod:`pipeline.log.schemas`, and for the controller state (whose layout changed between
control_msgs generations) the generation that the first message's bytes fit exactly.

:class:`Db3Scan` streams the messages in timestamp order in batches, lays each batch out
as MCAP message records and hands it to the same ``on_messages`` hook as
:class:`pipeline.log.mcap.McapScan`, so decoding does not know which storage it reads.

Damage. sqlite keeps no checksums: a flipped bit in a payload goes unseen (the decoder may
still refuse the message), but a truncated file (shorter than its header states) or a
damaged b-tree page is refused in one line naming the file. With ``salvage`` the message
rows are read in id (recording) order up to the first unreadable one and only those are
delivered, so a salvaged recording is a prefix of the episode; :attr:`Db3Scan.salvaged`
says how many rows were read and lost. The user's file is only ever opened read-only and
immutable (no side file is created); a ``-wal`` side file (a recorder killed before closing
the bag) is read from a copy, since sqlite would otherwise write a ``-shm`` beside it.
:func:`wal_copies` makes that copy once for all the passes of one read and removes it
when the read ends, however it ends (an error, Ctrl-C, SIGTERM).
"""

from __future__ import annotations

import contextlib
import shutil
import sqlite3
import struct
import tempfile
from collections import defaultdict
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.constants import TYPE_CONTROLLER_STATE
from pipeline.errors import RecordingError
from pipeline.log import cdr
from pipeline.log.mcap import (
    MESSAGE_PREFIX,
    RECORD_HEADER,
    McapChannel,
    McapSchema,
    Salvage,
    StorageScan,
)
from pipeline.log.msgdef import parse_msgdef
from pipeline.log.schemas import MSG_TEXTS, controller_state_candidates, full_definition

BATCH_MESSAGES = 20_000


def _wal(path: Path) -> Path | None:
    """``path``'s ``-wal`` side file if it holds writes, else None."""
    wal = path.with_name(path.name + "-wal")
    return wal if wal.is_file() and wal.stat().st_size > 0 else None


def _copy_with_wal(path: Path, wal: Path, into: Path) -> Path:
    db = into / path.name
    try:
        shutil.copyfile(path, db)
        shutil.copyfile(wal, into / wal.name)
    except OSError as err:
        raise RecordingError(f"{path}: cannot copy it with its {wal.name} ({err})") from err
    return db


@contextlib.contextmanager
def wal_copies(files: Sequence[Path]) -> Iterator[dict[Path, Path]]:
    """Copies (in one temporary folder) of the ``.db3`` files among ``files`` that have a
    non-empty ``-wal``, keyed by the original path; the folder is removed on leaving.

    Pass the mapping to :class:`Db3Scan` (``copies``) so a read of several passes copies
    a bag once, not once per pass.
    """
    with contextlib.ExitStack() as stack:
        copies: dict[Path, Path] = {}
        for path in files:
            try:
                wal = _wal(path) if path.suffix == ".db3" else None
            except OSError:
                wal = None  # the scan says what is wrong with it
            if wal is None:
                continue
            tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="armlab-db3-")))
            copies[path] = _copy_with_wal(path, wal, tmp)
        yield copies


class Db3Scan(StorageScan):
    """Streams one rosbag2 sqlite3 file; subclasses receive messages via ``on_messages``."""

    def __init__(self, path: Path, *, salvage: bool = False, copy: Path | None = None) -> None:
        """``copy``: this bag copied with its ``-wal`` (:func:`wal_copies`); without one a
        bag with a non-empty ``-wal`` is copied for this scan alone."""
        super().__init__(path, salvage=salvage)
        self.copy = copy
        self._tables = False

    def _fail(self, problem: str) -> RecordingError:
        return RecordingError(f"{self.path}: {problem}")

    def run(self) -> None:
        wal = self.path.with_name(self.path.name + "-wal")
        try:
            self.size = self.path.stat().st_size
            has_wal = wal.is_file() and wal.stat().st_size > 0
            for part in (self.path, wal) if has_wal else (self.path,):
                with open(part, "rb") as f:
                    for block in iter(lambda: f.read(1 << 20), b""):
                        self.sha.update(block)
            truncated = _truncation(self.path, self.size)
        except OSError as err:
            raise self._fail(f"cannot read ({err.strerror or err})") from err
        if truncated and not self.salvage:
            raise self._fail(f"{truncated}; --salvage reads the messages before the damage")
        with contextlib.ExitStack() as stack:
            db = self.path
            if has_wal:
                # A recorder killed before closing the bag leaves its last writes in the
                # write-ahead log. sqlite would fold it in (and create a -shm beside it):
                # read a copy, so the user's bag is never modified.
                if self.copy is not None:
                    db = self.copy
                else:
                    tmp = stack.enter_context(tempfile.TemporaryDirectory(prefix="armlab-db3-"))
                    db = _copy_with_wal(self.path, wal, Path(tmp))
                self.notes.append(
                    f"{self.path.name}: its last writes are in {wal.name} (the recorder did not "
                    "close the bag); read with them from a copy, the bag is left as it is"
                )
            # Without WAL content the file is all there is: immutable, or sqlite would
            # create -wal and -shm beside a WAL-mode bag (rosbag2's "resilient" preset)
            # and leave them there.
            uri = db.resolve().as_uri() + ("?mode=ro" if has_wal else "?mode=ro&immutable=1")
            try:
                con = sqlite3.connect(uri, uri=True)
                if self.salvage:
                    # Read a truncated file up to its end instead of refusing it whole
                    # (a connection flag; the file is open read-only).
                    con.execute("PRAGMA writable_schema=ON")
            except sqlite3.Error as err:
                raise self._fail(f"cannot read ({err})") from err
            try:
                self._run(con, truncated=truncated)
            except sqlite3.DatabaseError as err:
                hint = "; --salvage reads the messages before the damage" if self._tables else ""
                raise self._fail(f"not a rosbag2 sqlite3 file, or corrupt ({err}){hint}") from err
            finally:
                con.close()

    def _run(self, con: sqlite3.Connection, *, truncated: str | None) -> None:
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not {"topics", "messages"} <= tables:
            raise self._fail("not a rosbag2 sqlite3 file (no topics/messages tables)")
        self._tables = True
        definitions: dict[str, str] = {}
        if "message_definitions" in tables:
            for type_name, encoding, text in con.execute(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
            ):
                if encoding == "ros2msg" and text:
                    definitions[str(type_name)] = str(text)
        pending: dict[int, str] = {}
        for tid, name, type_name, fmt in con.execute(
            "SELECT id, name, type, serialization_format FROM topics"
        ):
            cid = int(tid)
            self.channels[cid] = McapChannel(cid, str(name), cid, str(fmt))
            text = definitions.get(str(type_name))
            if text is None:
                short = "/".join(str(type_name).split("/")[::2])
                if type_name == TYPE_CONTROLLER_STATE:
                    pending[cid] = str(type_name)  # picked from the first message
                    continue
                text = full_definition(type_name) if short in MSG_TEXTS["jazzy"] else ""
            self.schemas[cid] = McapSchema(cid, str(type_name), "ros2msg", text.encode())
        expected = None
        if self.salvage:
            first_id, last_id, expected = self._salvage_scan(con, truncated=truncated)
            # Rows up to the damage only, by the table itself (its timestamp index may be
            # what is damaged); sorted by sqlite, in a temporary file when large. The lower
            # bound is checked row by row (+id): a damaged page can hold rows with id 0.
            cursor = con.execute(
                "SELECT topic_id, timestamp, data FROM messages NOT INDEXED "
                "WHERE id <= ? AND +id >= ? ORDER BY timestamp, id",
                (last_id, first_id),
            )
        else:
            cursor = con.execute(
                "SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id"
            )
        delivered = 0
        while rows := cursor.fetchmany(BATCH_MESSAGES):
            delivered += len(rows)
            by_topic: dict[int, list[tuple[int, bytes]]] = defaultdict(list)
            for tid, stamp, data in rows:
                by_topic[int(tid)].append((int(stamp), bytes(data)))
            for cid, messages in by_topic.items():
                channel = self.channels.get(cid)
                if channel is None:
                    raise self._fail(f"corrupt: messages of unknown topic id {cid}")
                if cid in pending:
                    self._pick_definition(cid, pending.pop(cid), messages[0][1])
                self.topic_counts[channel.topic] = self.topic_counts.get(channel.topic, 0) + len(
                    messages
                )
                buf, starts = _records(cid, messages)
                self.on_messages(channel, buf, starts)
        if expected is not None and delivered != expected:
            raise self._fail(
                f"damaged beyond salvage: {expected} message rows read in id order, "
                f"{delivered} in time order"
            )

    def _salvage_scan(
        self, con: sqlite3.Connection, *, truncated: str | None
    ) -> tuple[int, int, int]:
        """Read the message rows in id (recording) order up to the first damaged one; note
        what was lost in :attr:`salvaged` (None when nothing is). Returns the first and last
        good id and how many rows there are from one to the other.

        Rows are read whole (payload included: a damaged overflow page shows only then).
        What follows the damage is not read even where sqlite could reach it: a recording
        with a hole would pass for a continuous one in every metric, as in MCAP salvage.
        """
        read = 0
        first_id = last_id = 0
        last_ns: int | None = None
        problem = truncated
        try:
            for rid, tid, stamp, data in con.execute(
                "SELECT id, topic_id, timestamp, data FROM messages NOT INDEXED ORDER BY id"
            ):
                if read and rid <= last_id:  # a rowid scan only ever goes up
                    problem = f"message rows out of order after id {last_id} (a damaged page)"
                    break
                if tid is None or stamp is None or not isinstance(data, bytes):
                    # a row cut by the damage: sqlite returns what is missing as NULL
                    problem = f"message row {rid} has lost its values (NOT NULL columns read null)"
                    break
                read += 1
                last_id, last_ns = int(rid), int(stamp)
                first_id = first_id or last_id
        except sqlite3.DatabaseError as err:
            problem = f"message row after id {last_id} unreadable ({err})"
        if problem is None:
            return first_id, last_id, read
        if read == 0:
            raise self._fail(f"damaged before its first message, nothing to salvage ({problem})")
        try:
            max_id = con.execute("SELECT max(id) FROM messages").fetchone()[0]
        except sqlite3.DatabaseError:
            max_id = None  # the damaged part holds the table's last page
        lost = None if max_id is None else max(int(max_id) - last_id, 0)
        self.salvaged = Salvage(
            at_byte=-1,
            problem=problem,
            lost_bytes=max(_header_size(self.path) - self.size, 0),
            read_messages=read,
            lost_messages=lost,
            lost_after_ns=last_ns,
        )
        return first_id, last_id, read

    def _pick_definition(self, cid: int, type_name: str, data: bytes) -> None:
        for text in controller_state_candidates():
            try:
                cdr.walk(parse_msgdef(type_name, text), type_name, data, exact=True)
            except (ValueError, struct.error):
                continue
            self.schemas[cid] = McapSchema(cid, type_name, "ros2msg", text.encode())
            return
        raise self._fail(
            f"{self.channels[cid].topic}: the file has no message definitions and its "
            f"{type_name} messages fit no known control_msgs generation"
        )


def _records(cid: int, messages: list[tuple[int, bytes]]) -> tuple[bytes, NDArray[np.int64]]:
    """Messages laid out as MCAP message records (so one decoder serves both storages)."""
    parts = []
    starts = np.empty(len(messages), dtype=np.int64)
    pos = 0
    for k, (stamp, data) in enumerate(messages):
        head = struct.pack("<BQHIQQ", 5, MESSAGE_PREFIX + len(data), cid, k, stamp, stamp)
        parts.append(head)
        parts.append(data)
        starts[k] = pos + RECORD_HEADER
        pos += len(head) + len(data)
    return b"".join(parts), starts


def _header_size(path: Path) -> int:
    """The database size its header states [bytes] (0 when it states none validly)."""
    with open(path, "rb") as f:
        head = f.read(100)
    if len(head) < 100 or not head.startswith(b"SQLite format 3\0"):
        return 0
    page = int.from_bytes(head[16:18], "big")
    page = 65536 if page == 1 else page
    # the page count is valid only when the change counter matches version-valid-for
    pages = int.from_bytes(head[28:32], "big") if head[24:28] == head[92:96] else 0
    return page * pages


def _truncation(path: Path, size: int) -> str | None:
    """How the file falls short of the size its header states, None if it does not."""
    expected = _header_size(path)
    if expected > size:
        return f"truncated: {size} of the {expected} bytes its sqlite header states"
    return None
