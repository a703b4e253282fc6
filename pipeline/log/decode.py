"""Decode a control-rate topic's messages into arrays, chunk by chunk, through its schema.

The schema embedded in the recording is parsed (:mod:`pipeline.log.msgdef`), the first
message of a shape is walked once to find where every field sits (its :class:`Layout`), and
all messages of the chunk that have the same length and the same length prefixes / strings
are decoded together with numpy (a byte gather and a dtype view). Messages of another shape
(a header.frame_id that changes length, another publisher's joint list) are walked one by
one (the generic path, same values, slower) and start a shape of their own, which later
chunks decode vectorized again. Messages are grouped by their joint-name list, so a topic
with several publishers (an arm and a gripper on ``/joint_states``) keeps each one's rows.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.log.cdr import Layout, ManyLayout, walk, walk_many
from pipeline.log.gather import gather_rows, gather_u64, values_at
from pipeline.log.mcap import MESSAGE_PREFIX
from pipeline.log.msgdef import MsgTypes

F64 = NDArray[np.float64]
STAMP_SEC = "header.stamp.sec"
STAMP_NSEC = "header.stamp.nanosec"


class DecodeError(ValueError):
    """A message or schema that does not give what a role needs."""


@dataclass(frozen=True)
class Want:
    """Fields to decode from a control-rate topic (first alias present wins).

    ``required``: groups of field paths; the schema must have at least one path of
    each group (besides ``header.stamp``), else the topic cannot serve.
    """

    names: tuple[str, ...]
    arrays: dict[str, tuple[str, ...]]
    required: tuple[tuple[str, ...], ...] = ()


@dataclass
class Group:
    """The messages of one joint-name list: its layout and accumulated arrays."""

    names: tuple[str, ...]
    layout: Layout
    check_cols: NDArray[np.intp]
    check_bytes: NDArray[np.uint8]
    stamps: list[NDArray[np.int64]] = field(default_factory=list)
    arrays: dict[str, list[F64]] = field(default_factory=dict)
    count: int = 0
    # Another order of an existing group's joints: its rows go to that group, columns
    # reordered by name (``cols[i]``: this group's column of the target's joint i).
    target: Group | None = None
    cols: NDArray[np.intp] | None = None

    def __post_init__(self) -> None:
        # The check bytes as 4-byte words (with a mask for the bytes of a word outside the
        # check ranges): comparing a quarter as many columns is 2-3x faster than per byte.
        size = self.layout.size
        self._words: NDArray[np.intp] | None = None
        if size % 4 == 0 and self.check_cols.size:
            template = np.zeros(size, dtype=np.uint8)
            mask = np.zeros(size, dtype=np.uint8)
            template[self.check_cols] = self.check_bytes
            mask[self.check_cols] = 0xFF
            self._words = np.unique(self.check_cols // 4)
            self._word_mask = mask.view(np.uint32)[self._words]
            self._word_ref = template.view(np.uint32)[self._words]

    def same_shape(self, matrix: NDArray[np.uint8]) -> NDArray[np.bool_]:
        """Which rows of a (N, layout.size) byte matrix have this group's check bytes
        (length prefixes and strings), i.e. this group's layout and joint names."""
        if self._words is None:
            out: NDArray[np.bool_] = (matrix[:, self.check_cols] == self.check_bytes).all(axis=1)
            return out
        words = np.ascontiguousarray(matrix).view(np.uint32)[:, self._words]
        same: NDArray[np.bool_] = ((words & self._word_mask) == self._word_ref).all(axis=1)
        return same

    def concat(self) -> tuple[NDArray[np.int64], dict[str, F64]]:
        """All rows in time order: stamps [ns] and (N, joints) arrays.

        The per-chunk pieces are replaced by the result, so the rows are held once.
        """
        stamps = np.concatenate(self.stamps)
        self.stamps = [stamps]
        arrays = {}
        for k in list(self.arrays):
            arrays[k] = np.concatenate(self.arrays[k])
            self.arrays[k] = [arrays[k]]
        if stamps.size > 1 and not (np.diff(stamps) > 0).all():
            order = np.argsort(stamps, kind="stable")
            stamps = stamps[order]
            arrays = {k: v[order] for k, v in arrays.items()}
        return stamps, arrays

    def take(self) -> tuple[NDArray[np.int64], dict[str, F64]]:
        """The rows decoded since the last take, in the order decoded (not sorted), and
        let go of them (``count`` keeps counting); a streaming read calls it per batch."""
        empty = np.zeros((0, len(self.names)))
        stamps = np.concatenate(self.stamps) if self.stamps else np.zeros(0, dtype=np.int64)
        arrays = {k: np.concatenate(v) if v else empty for k, v in self.arrays.items()}
        self.stamps = []
        self.arrays = {k: [] for k in self.arrays}
        return stamps, arrays


@dataclass
class TopicDecoder:
    """Decodes one channel's messages (type ``type_name``) into per-joint-list groups."""

    topic: str
    type_name: str
    types: MsgTypes
    want: Want
    groups: list[Group] = field(default_factory=list)
    # joint lists that reorder a group's joints (their rows are that group's)
    reordered: list[Group] = field(default_factory=list)
    reordered_count: int = 0
    # the generic path's groups by the bytes of their joint-name list
    _by_name_bytes: dict[bytes, Group] = field(default_factory=dict, repr=False)

    @property
    def count(self) -> int:
        return sum(g.count for g in self.groups)

    def largest(self) -> Group | None:
        return max(self.groups, key=lambda g: g.count, default=None)

    def add(self, buf: bytes, starts: NDArray[np.int64]) -> None:
        """Decode the messages whose MCAP message records start at ``starts`` in ``buf``.

        Raises:
            DecodeError: a message that does not fit the schema, or a schema without the
                fields ``want`` requires.
        """
        u8 = np.frombuffer(buf, dtype=np.uint8)
        lengths = gather_u64(u8, starts - 8).astype(np.int64) - MESSAGE_PREFIX
        data_start = starts + MESSAGE_PREFIX
        if not self.groups:
            first = self._walk(buf, int(data_start[0]), int(lengths[0]))
            s0 = int(data_start[0])
            self._group(first, u8[s0 : s0 + first.size])
        left = np.ones(starts.size, dtype=bool)
        for group in (*self.groups, *self.reordered):
            if not left.any():
                break
            sel = left & (lengths == group.layout.size)
            if not sel.any():
                continue
            idx = np.flatnonzero(sel)
            matrix = gather_rows(u8, data_start[idx], group.layout.size)
            same = group.same_shape(matrix)
            if same.all():  # the usual case: no copy of the rows
                self._append(group, matrix)
                left[idx] = False
            elif same.any():
                self._append(group, matrix[same])
                left[idx[same]] = False
        rest = np.flatnonzero(left)
        if rest.size:
            self._add_generic(buf, u8, data_start[rest], lengths[rest])

    def _add_generic(
        self, buf: bytes, u8: NDArray[np.uint8], starts: NDArray[np.int64], sizes: NDArray[np.int64]
    ) -> None:
        """Messages of differing shapes: walked all at once (:func:`walk_many`), grouped by
        their joint-name bytes; one message at a time only if that fails (to name it)."""
        try:
            many = walk_many(self.types, self.type_name, u8, starts, sizes)
            region = next(many.regions[p] for p in self.want.names if p in many.regions)
        except (ValueError, StopIteration):
            for s, n in zip(starts.tolist(), sizes.tolist(), strict=True):
                layout = self._walk(buf, s, n)
                row = u8[s : s + layout.size]
                self._append(self._group(layout, row), row[None, :], layout)
            return
        a, b = region
        span = b - a
        for length in np.unique(span).tolist():
            sel = np.flatnonzero(span == length)
            rows = gather_rows(u8, a[sel], int(length))
            while sel.size:  # one joint list at a time (usually one in all)
                same = (rows == rows[0]).all(axis=1)
                key = rows[0].tobytes()  # equal name bytes: equal names
                group = self._by_name_bytes.get(key)
                if group is None or not any(g is group for g in (*self.groups, *self.reordered)):
                    i = int(sel[0])
                    s, n = int(starts[i]), int(sizes[i])
                    group = self._group(self._walk(buf, s, n), u8[s : s + n])
                    self._by_name_bytes[key] = group
                self._append_many(group, u8, many, sel[same])
                sel, rows = sel[~same], rows[~same]

    def _append_many(
        self, group: Group, u8: NDArray[np.uint8], many: ManyLayout, idx: NDArray[np.intp]
    ) -> None:
        def column(path: str) -> NDArray[Any]:
            off, dtype, _ = many.leaves[path]
            return values_at(u8, dtype)[off[idx]]

        n = idx.size
        dest = self._dest(group, n)
        dest.stamps.append(
            column(STAMP_SEC).astype(np.int64) * 1_000_000_000 + column(STAMP_NSEC).astype(np.int64)
        )
        width = len(group.names)
        for key, aliases in self.want.arrays.items():
            out = np.full((n, width), np.nan)
            todo = np.ones(n, dtype=bool)
            for path in aliases:  # per message, the first alias with values wins
                if path not in many.leaves or not width:
                    continue
                off, dtype, count = many.leaves[path]
                cnt = count[idx]
                bad = todo & (cnt != width) & (cnt != 0)
                if bad.any():
                    raise DecodeError(f"{path} has {int(cnt[bad].max())} values for {width} joints")
                take = todo & (cnt == width)
                if take.all():
                    out = values_at(u8, dtype, width)[off[idx]].astype(np.float64)
                    break
                if take.any():
                    out[take] = values_at(u8, dtype, width)[off[idx[take]]]
                    todo &= ~take
            dest.arrays.setdefault(key, []).append(
                out if group.cols is None else out[:, group.cols]
            )
        dest.count += n

    def _dest(self, group: Group, n: int) -> Group:
        """The group that keeps ``group``'s rows: itself, or the one whose joints it reorders."""
        if group.target is None:
            return group
        self.reordered_count += n
        return group.target

    def _walk(self, buf: bytes, start: int, length: int) -> Layout:
        data = buf[start : start + length]
        try:
            return walk(self.types, self.type_name, data)
        except (ValueError, struct.error) as err:
            raise DecodeError(
                f"corrupt: a message on {self.topic} cannot be decoded as {self.type_name} ({err})"
            ) from err

    def _group(self, layout: Layout, data: NDArray[np.uint8]) -> Group:
        """The group of a message's joint list; a new order of a known list's joints (a
        driver that lists them differently from one message to the next) gets a group of
        its own shape whose rows, reordered by name, are the known list's."""
        names = self._names(layout)
        for g in (*self.groups, *self.reordered):
            if g.names == names:
                return g
        self._check_fields(layout)
        cols = layout.check_cols()
        group = Group(names, layout, cols, data[cols].copy())
        same = next(
            (
                g
                for g in self.groups
                if sorted(g.names) == sorted(names) and len(set(names)) == len(names)
            ),
            None,
        )
        if same is not None:
            group.target = same
            group.cols = np.array([names.index(n) for n in same.names], dtype=np.intp)
            self.reordered.append(group)
        else:
            self.groups.append(group)
        return group

    def _append(
        self, group: Group, matrix: NDArray[np.uint8], layout: Layout | None = None
    ) -> None:
        lay = layout or group.layout
        n = matrix.shape[0]
        dest = self._dest(group, n)
        dest.stamps.append(
            _column(lay, matrix, STAMP_SEC)[:, 0].astype(np.int64) * 1_000_000_000
            + _column(lay, matrix, STAMP_NSEC)[:, 0].astype(np.int64)
        )
        width = len(group.names)
        for key, aliases in self.want.arrays.items():
            values = _leaf_matrix(lay, matrix, aliases, width, n)
            dest.arrays.setdefault(key, []).append(
                values if group.cols is None else values[:, group.cols]
            )
        dest.count += n

    def _check_fields(self, layout: Layout) -> None:
        """Refuse a schema that lacks a field the report cannot do without."""
        missing = [p for p in (STAMP_SEC, STAMP_NSEC) if p not in layout.leaves]
        missing += [
            " or ".join(group)
            for group in self.want.required
            if not any(p in layout.leaves for p in group)
        ]
        if missing:
            raise DecodeError(
                f"{self.topic} ({self.type_name}) has no field {', '.join(missing)}; "
                "cannot read it as a control-rate topic"
            )

    def _names(self, layout: Layout) -> tuple[str, ...]:
        for path in self.want.names:
            value = layout.texts.get(path)
            if isinstance(value, tuple):
                return value
        raise DecodeError(
            f"{self.topic} ({self.type_name}) has no joint-name field "
            f"({' or '.join(self.want.names)})"
        )


def _column(layout: Layout, matrix: NDArray[np.uint8], path: str) -> NDArray[Any]:
    off, dtype, count = layout.leaves[path]
    rows = np.ascontiguousarray(matrix)  # (a no-op: rows are gathered or sliced whole)
    return np.ndarray(
        (rows.shape[0], count), dtype=dtype, buffer=rows, offset=off,
        strides=(rows.strides[0], int(dtype[2])),
    )  # fmt: skip


def _leaf_matrix(
    layout: Layout, matrix: NDArray[np.uint8], aliases: tuple[str, ...], width: int, n: int
) -> F64:
    for path in aliases:
        if path in layout.leaves:
            _, _, count = layout.leaves[path]
            if count == 0:
                continue
            if count != width:
                raise DecodeError(f"{path} has {count} values for {width} joints")
            return _column(layout, matrix, path).astype(np.float64)
    # An empty or absent optional array (e.g. no commanded effort): NaN, not a crash.
    return np.full((n, width), np.nan)


def leaf_rows(layout: Layout, data: bytes | memoryview, paths: Sequence[str], width: int) -> F64:
    """The numeric leaves at ``paths`` of one message (e.g. every ``points[k].positions``)
    as a (len(paths), width) float64 matrix, gathered at once per dtype; a row of NaN where a
    path is absent or holds another number of values than ``width``."""
    out = np.full((len(paths), width), np.nan)
    if not width:
        return out
    u8 = np.frombuffer(data, dtype=np.uint8)
    leaves = [leaf for leaf in (layout.leaves.get(p) for p in paths) if leaf is not None]
    if paths and len(leaves) == len(paths):  # the common case: one dtype and width for all
        dtype = leaves[0][1]
        if {leaf[1:] for leaf in leaves} == {(dtype, width)}:
            at = np.array([leaf[0] for leaf in leaves], dtype=np.int64)
            every: F64 = values_at(u8, dtype, width)[at].astype(np.float64)
            return every
    found: dict[str, tuple[list[int], list[int]]] = {}  # dtype -> (rows, byte offsets)
    for k, path in enumerate(paths):
        leaf = layout.leaves.get(path)
        if leaf is not None and leaf[2] == width:
            rows, offsets = found.setdefault(leaf[1], ([], []))
            rows.append(k)
            offsets.append(leaf[0])
    for dtype, (rows, offsets) in found.items():
        block = gather_rows(u8, np.array(offsets, dtype=np.int64), int(dtype[2]) * width)
        out[rows] = np.ascontiguousarray(block).view(dtype).astype(np.float64)
    return out
