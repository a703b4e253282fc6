"""Sanity checks on a recording's frames that the metrics rely on, as report warnings.

The reader decodes what is in the file; it does not judge it. A bag recorded twice into
one file, or a bridge that re-published messages, holds the same stamp more than once on
a topic: every copy then counts in the RMS and settling metrics, silently weighting them
toward the duplicated instants. We say so instead.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import polars as pl

from pipeline.constants import TOPIC_CONTROLLER_STATE, TOPIC_JOINT_STATES
from pipeline.log.reader import ReadOptions, Recording


@dataclass(frozen=True)
class Duplicates:
    """Stamps that occur more than once on a topic: how many, the extra copies, the first."""

    stamps: int
    extra: int
    first_ns: int

    def __add__(self, other: Duplicates) -> Duplicates:
        """Of two time slices that share no stamp (windows of a long recording)."""
        return Duplicates(
            self.stamps + other.stamps, self.extra + other.extra, min(self.first_ns, other.first_ns)
        )


def duplicate_stamps(frame: pl.DataFrame) -> Duplicates | None:
    """The (stamp, joint) pairs of a tidy frame that occur more than once (None: none)."""
    if frame.is_empty() or _distinct_in_layout(frame):
        return None
    dup = (
        frame.group_by("stamp_ns", "joint")
        .len()
        .filter(pl.col("len") > 1)
        .group_by("stamp_ns")
        .agg(pl.col("len").max())
        .sort("stamp_ns")
    )
    if dup.is_empty():
        return None
    return Duplicates(dup.height, int((dup["len"] - 1).sum()), int(dup["stamp_ns"][0]))


def joint_blocks_repeat(joints: pl.Series, n: int) -> bool:
    """True when ``joints`` (a tidy frame's joint column) is whole blocks of ``n`` rows,
    each in the first block's order: the layout a recording is read in, a row per joint
    at every time."""
    h = joints.len()
    return n > 0 and h % n == 0 and bool(joints.slice(n).eq_missing(joints.slice(0, h - n)).all())


def _distinct_in_layout(frame: pl.DataFrame) -> bool:
    """True when the frame is laid out as recorded (a row per joint, the same joint order
    at every time) and each joint's stamps strictly increase: no (stamp, joint) twice, with
    no hashing. False says nothing (the group-by decides)."""
    joints = frame.get_column("joint")
    n = joints.head(64).n_unique()
    if joints.head(n).n_unique() != n or not joint_blocks_repeat(joints, n):
        return False
    stamps = frame.get_column("stamp_ns")
    if stamps.null_count():
        return False
    s = stamps.to_numpy().reshape(-1, n)
    return bool((s[1:] > s[:-1]).all())


def duplicate_note(topic: str, dup: Duplicates) -> str:
    return (
        f"{topic}: {dup.stamps} stamp(s) occur more than once ({dup.extra} duplicate "
        f"message(s), first at stamp {dup.first_ns * 1e-9:.6f} s); metrics count every copy"
    )


def duplicate_stamp_notes(rec: Recording) -> list[str]:
    """One note per control-rate topic that has a (stamp, joint) more than once.

    A recording read in windows (``rec.windows``) has decimated frames: its notes were
    taken per window as it was read (:func:`duplicate_stamps`), so none are added here.
    """
    if rec.windows:
        return []
    notes: list[str] = []
    frames = ((TOPIC_JOINT_STATES, rec.samples), (TOPIC_CONTROLLER_STATE, rec.controller_states))
    for topic, frame in frames:
        dup = duplicate_stamps(frame)
        if dup is not None:
            notes.append(duplicate_note(topic, dup))
    return notes


def merged_label_notes(recordings: list[Recording], options: ReadOptions | None) -> list[Recording]:
    """``recordings`` with a warning on each bag we did not write that shares its
    controller label (from ``--controller``) with another such bag of its scenario and was
    not labelled on its own (``--label``): they are averaged as repeats of one controller."""
    if options is None or not options.controller:
        return recordings
    shared: dict[tuple[str, str], list[str]] = {}
    for rec in recordings:
        bag = rec.source.name.removesuffix(".mcap")
        if not rec.armlab_metadata and bag not in options.labels:
            shared.setdefault((rec.scenario, rec.controller), []).append(rec.episode)
    merged = {e: eps for eps in shared.values() if len(eps) > 1 for e in eps}
    return [
        dataclasses.replace(
            rec,
            notes=(
                *rec.notes,
                f"labelled '{rec.controller}' by --controller like {len(merged[rec.episode]) - 1} "
                "other bag(s) without our metadata ("
                + ", ".join(e for e in merged[rec.episode] if e != rec.episode)
                + "): their metrics are averaged as repeats of one controller; if they are "
                "different controllers, label each with --label BAG=CONTROLLER",
            ),
        )
        if rec.episode in merged
        else rec
        for rec in recordings
    ]
