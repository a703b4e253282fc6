"""rosbag2's sqlite3 storage (``.db3``, Humble's default): read as the MCAP scanner reads.

A ``.db3`` has ``topics`` (name, type, serialization format) and ``messages`` (topic id,
timestamp, CDR bytes); Iron and later also store the ``message_definitions`` (the same
``ros2msg`` text MCAP schemas carry). Humble's files have none: the definitions then come
from :mod:`pipeline.log.schemas`, and for the controller state (whose layout changed between
control_msgs generations) the generation that the first message's bytes fit exactly.

:class:`Db3Scan` streams the messages in timestamp order in batches, lays each batch out
as MCAP message records and hands it to the same ``on_messages`` hook as
:class:`pipeline.log.mcap.McapScan`, so decoding does not know which storage it reads.
"""

from __future__ import annotations

import hashlib
import sqlite3
import struct
from collections import defaultdict
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.constants import TYPE_CONTROLLER_STATE
from pipeline.errors import RecordingError
from pipeline.log import cdr
from pipeline.log.mcap import MESSAGE_PREFIX, RECORD_HEADER, McapChannel, McapSchema, Salvage
from pipeline.log.msgdef import parse_msgdef
from pipeline.log.schemas import MSG_TEXTS, controller_state_candidates, full_definition

BATCH_MESSAGES = 20_000


class Db3Scan:
    """Streams one rosbag2 sqlite3 file; subclasses receive messages via ``on_messages``."""

    def __init__(self, path: Path, *, salvage: bool = False) -> None:
        self.path = path
        self.schemas: dict[int, McapSchema] = {}
        self.channels: dict[int, McapChannel] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.topic_counts: dict[str, int] = {}
        self.sha = hashlib.sha256()
        self.size = 0
        self.salvage = salvage
        self.salvaged: Salvage | None = None

    def on_messages(self, channel: McapChannel, buf: bytes, starts: NDArray[np.int64]) -> None:
        """As :meth:`pipeline.log.mcap.McapScan.on_messages`."""

    def _fail(self, problem: str) -> RecordingError:
        return RecordingError(f"{self.path}: {problem}")

    def run(self) -> None:
        try:
            self.size = self.path.stat().st_size
            with open(self.path, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    self.sha.update(block)
            con = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True)
        except (OSError, sqlite3.Error) as err:
            raise self._fail(f"cannot read ({err})") from err
        try:
            self._run(con)
        except sqlite3.DatabaseError as err:
            raise self._fail(f"not a rosbag2 sqlite3 file, or corrupt ({err})") from err
        finally:
            con.close()

    def _run(self, con: sqlite3.Connection) -> None:
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not {"topics", "messages"} <= tables:
            raise self._fail("not a rosbag2 sqlite3 file (no topics/messages tables)")
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
        cursor = con.execute(
            "SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id"
        )
        while rows := cursor.fetchmany(BATCH_MESSAGES):
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
