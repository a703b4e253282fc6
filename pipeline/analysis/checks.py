"""Sanity checks on a recording's frames that the metrics rely on, as report warnings.

The reader decodes what is in the file; it does not judge it. A bag recorded twice into
one file, or a bridge that re-published messages, holds the same stamp more than once on
a topic: every copy then counts in the RMS and settling metrics, silently weighting them
toward the duplicated instants. We say so instead.
"""

from __future__ import annotations

import polars as pl

from pipeline.constants import TOPIC_CONTROLLER_STATE, TOPIC_JOINT_STATES
from pipeline.log.reader import Recording


def duplicate_stamp_notes(rec: Recording) -> list[str]:
    """One note per control-rate topic that has a (stamp, joint) more than once."""
    notes: list[str] = []
    frames = ((TOPIC_JOINT_STATES, rec.samples), (TOPIC_CONTROLLER_STATE, rec.controller_states))
    for topic, frame in frames:
        if frame.is_empty():
            continue
        dup = (
            frame.group_by("stamp_ns", "joint")
            .len()
            .filter(pl.col("len") > 1)
            .group_by("stamp_ns")
            .agg(pl.col("len").max())
            .sort("stamp_ns")
        )
        if dup.is_empty():
            continue
        extra = int((dup["len"] - 1).sum())
        first_s = int(dup["stamp_ns"][0]) * 1e-9
        notes.append(
            f"{topic}: {dup.height} stamp(s) occur more than once ({extra} duplicate "
            f"message(s), first at stamp {first_s:.6f} s); metrics count every copy"
        )
    return notes
