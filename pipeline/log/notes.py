"""The notes a read attaches to a recording (non-fatal oddities: salvage, dropped samples,
missing arrays, the joints analysed) and its one "nothing pairs" error.

Shared by the whole read (:mod:`pipeline.log.whole`) and the windowed one
(:mod:`pipeline.log.windowed`), so both say the same.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from pipeline.constants import TOPIC_CONTROLLER_STATE, TOPIC_JOINT_STATES
from pipeline.errors import RecordingError
from pipeline.log.collect import Declared, Roles, Scanned
from pipeline.log.mcap import Salvage
from pipeline.log.recording import F64

__all__ = [
    "JS_OPTIONAL",
    "declared_lost",
    "dropped_note",
    "empty_array_notes",
    "missing_array_notes",
    "no_pairs",
    "paired_note",
    "read_notes",
    "salvage_note",
]

# Optional /joint_states arrays whose absence the report notes.
JS_OPTIONAL = {"velocity": "velocity", "effort": "effort"}


def declared_lost(declared: Declared | None, found: Mapping[str, int]) -> tuple[str, float] | None:
    """What a damaged recording lost against the messages it declares: the words and the
    share [%]; None when it declares none."""
    if declared is None or not declared.total:
        return None
    total = declared.total
    lost = sum(n - min(found.get(t, 0), n) for t, n in declared.counts.items())
    pct = 100 * lost / total
    return f"{lost} of the {total} messages {declared.what} declares ({pct:.1f} %) are missing", pct


def salvage_note(
    path: Path,
    s: Salvage,
    size: int,
    unread: Sequence[Path],
    declared: tuple[str, float] | None = None,
) -> tuple[str, float | None]:
    """The note on a salvaged file and the share of the recording lost [%] (None: unknown).

    The share is of what the recording declares (``declared``, from
    :func:`declared_lost`): messages its ``metadata.yaml`` or Statistics record counts, else a
    ``.db3``'s rows or page count. Bytes left after the damage of a file that declares
    nothing (a truncated MCAP loses its summary) are a floor, not a share: None.
    """
    later = (
        f"; the {len(unread)} later split file(s) ({', '.join(p.name for p in unread)}) "
        "were not read"
        if unread
        else ""
    )
    against = f"; {declared[0]}" if declared else ""
    if s.read_messages is None:  # MCAP: bytes
        return (
            f"salvaged: {path.name} is damaged at byte {s.at_byte} ({s.problem}); "
            f"{s.lost_bytes} bytes after it were not read"
            + (against or "; it declares no message count, so the share lost is unknown")
            + later,
            declared[1] if declared else None,
        )
    pct: float | None = None
    if s.lost_messages is None:
        lost_text = "an unknown number of message rows after it were lost"
        if s.lost_bytes:  # truncated: the share of the bytes its header states
            pct = 100 * s.lost_bytes / (size + s.lost_bytes)
            lost_text += (
                f" with the file's last {s.lost_bytes} bytes ({pct:.1f} % of the recording's bytes)"
            )
    else:
        pct = 100 * s.lost_messages / max(s.read_messages + s.lost_messages, 1)
        lost_text = (
            f"{s.lost_messages} of {s.read_messages + s.lost_messages} message rows "
            f"({pct:.1f} %) after it were lost"
        )
    if declared:
        pct = declared[1]
    return (
        f"salvaged: {path.name} is damaged ({s.problem}); {s.read_messages} message rows read "
        f"up to stamp {s.lost_after_ns} ns, {lost_text}" + against + later,
        None if unread and not declared else pct,
    )


def no_pairs(mcap_path: Path) -> RecordingError:
    return RecordingError(
        f"{mcap_path}: no {TOPIC_CONTROLLER_STATE} message shares a time stamp with "
        f"{TOPIC_JOINT_STATES}"
    )


def read_notes(scanned: Scanned, roles: Roles) -> tuple[list[str], float | None]:
    """The notes every read starts with (the storage's, salvage, the joints analysed) and
    the share of the recording a salvage lost [%]."""
    notes: list[str] = list(scanned.notes)
    lost_pct: float | None = None
    for path, s in scanned.salvaged:
        declared = declared_lost(scanned.declared, scanned.found)
        note, lost_pct = salvage_note(path, s, scanned.size, scanned.unread, declared)
        notes.append(note)
    if scanned.shortfall is not None:
        words, lost_pct = declared_lost(scanned.shortfall, scanned.shortfall_found) or ("", None)
        notes.append(
            f"salvaged: {scanned.shortfall.file.name}: {words} (removed or lost): what is "
            "there is read"
        )
    for dec in (roles.cs_dec, roles.js_dec):
        if dec.reordered_count:
            notes.append(
                f"{dec.topic}: {dec.reordered_count} message(s) list the joints in another "
                "order than the first: matched by name"
            )
    if len(roles.js_dec.groups) > 1 or len(roles.js_group.names) > len(roles.names):
        notes.append(
            f"{roles.js_dec.topic}: analysing {', '.join(roles.names)} (the joints of "
            f"{roles.cs_dec.topic}) from {len(roles.js_dec.groups)} joint list(s)"
        )
    return notes, lost_pct


def dropped_note(dropped: int) -> list[str]:
    return [f"{dropped} joint-state samples without a controller state were dropped"] * bool(
        dropped
    )


def paired_note(unmatched: int, cs_topic: str, topic: str) -> list[str]:
    """``unmatched`` controller states have no message of the paired ``topic`` (our name)."""
    return [f"{unmatched} {cs_topic} samples have no {topic} sample at their time"] * bool(
        unmatched
    )


def missing_array_notes(arrays: dict[str, F64], topic: str, fields: dict[str, str]) -> list[str]:
    """Notes for optional arrays that are empty (or NaN) in every message of ``topic``."""
    empty = {k for k in fields if (v := arrays.get(k)) is not None and v.size and np.isnan(v).all()}
    return empty_array_notes(empty, topic, fields)


def empty_array_notes(empty: set[str], topic: str, fields: dict[str, str]) -> list[str]:
    return [
        f"{topic} carries no {what} values (empty arrays): {what} metrics are n/a"
        for key, what in fields.items()
        if key in empty
    ]
