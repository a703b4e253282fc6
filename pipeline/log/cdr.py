# long: one message layout for writing and reading (scalars, strings, arrays, nesting)
"""CDR (XCDR1) for any parsed ROS 2 message type: one layout, written and read.

ROS 2 serializes messages as plain CDR: a 4-byte encapsulation header (``00 01 00 00`` for
little-endian), then the fields in definition order, each primitive aligned to its own size
(at most 8) relative to the byte *after* the header; a string is a uint32 length that counts
its NUL, the UTF-8 bytes and the NUL; a sequence is a uint32 count then its elements (an
empty sequence adds no alignment padding); fixed arrays have no count.

A message's :class:`Layout` says where every numeric leaf (``header.stamp.sec``,
``reference.positions``, ``points[3].velocities``) and every string sits. The two sides
derive it the same way from the :mod:`~pipeline.log.msgdef` types:

- the writer lays out one sample message (:func:`encode`), keeps the bytes as a
  :class:`Template` and fills N copies at once with numpy (:meth:`Template.fill`): the
  joint names and sequence lengths of a topic do not change, so neither does the layout;
- the reader walks the first message of a channel (:func:`walk`) and gathers the leaves of
  every same-shaped message at once (see :mod:`pipeline.log.decode`).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.log.gather import values_at
from pipeline.log.msgdef import PRIMITIVES, MsgField, MsgTypes, root_type_name

ENCAPSULATION_CDR_LE = b"\x00\x01\x00\x00"
_NS_PER_S = 1_000_000_000

U8 = NDArray[np.uint8]
Leaf = tuple[int, str, int]  # (byte offset in the message, numpy dtype with byte order, count)


@dataclass(frozen=True)
class Layout:
    """Where each field of one message sits; shared by every same-shaped message.

    Attributes:
        size: message length [bytes], CDR header included.
        leaves: path -> (byte offset, numpy dtype string, element count) of numeric fields.
        texts: path -> string (or tuple of strings for string arrays).
        check: byte ranges (length prefixes, strings) that must be equal for another message
            to share this layout.
    """

    size: int
    leaves: dict[str, Leaf]
    texts: dict[str, str | tuple[str, ...]]
    check: tuple[tuple[int, int], ...]

    def values(self, data: bytes | memoryview, path: str) -> NDArray[Any]:
        """The array at ``path`` in ``data`` (a message with this layout)."""
        off, dtype, count = self.leaves[path]
        return np.frombuffer(data, dtype=dtype, count=count, offset=off)

    def check_cols(self) -> NDArray[np.intp]:
        if not self.check:
            return np.zeros(0, dtype=np.intp)
        return np.concatenate([np.arange(a, b, dtype=np.intp) for a, b in self.check])


def _aligned(pos: int, size: int) -> int:
    a = min(size, 8)
    return 4 + ((pos - 4 + a - 1) // a) * a


def _resolve(types: MsgTypes, root: str) -> str:
    if root in types:
        return root
    full = root_type_name(root)
    if full not in types:
        raise ValueError(f"type {root} is not defined by the schema")
    return full


# --- writing --------------------------------------------------------------------------------


class _Encoder:
    """Lays one message out from nested values, recording every leaf's place."""

    def __init__(self, types: MsgTypes) -> None:
        self.types = types
        self.buf = bytearray(ENCAPSULATION_CDR_LE)
        self.leaves: dict[str, Leaf] = {}
        self.texts: dict[str, str | tuple[str, ...]] = {}
        self.check: list[tuple[int, int]] = []

    def _pad(self, size: int) -> None:
        self.buf += b"\x00" * (_aligned(len(self.buf), size) - len(self.buf))

    def _u32(self, value: int, *, structural: bool = True) -> None:
        self._pad(4)
        if structural:
            self.check.append((len(self.buf), len(self.buf) + 4))
        self.buf += struct.pack("<I", value)

    def _string(self, text: str) -> None:
        self._pad(4)
        start = len(self.buf)
        data = text.encode("utf-8")
        self.buf += struct.pack("<I", len(data) + 1) + data + b"\x00"
        self.check.append((start, len(self.buf)))

    def message(self, type_name: str, value: Mapping[str, Any], prefix: str = "") -> None:
        for f in self.types[type_name].fields:
            self.field(f, value.get(f.name), f"{prefix}{f.name}")

    def field(self, f: MsgField, value: Any, path: str) -> None:
        if f.is_primitive:
            dtype = "<" + PRIMITIVES[f.base]
            if f.array is None:
                arr = np.asarray(_default(f) if value is None else value, dtype=dtype).reshape(1)
            else:
                arr = np.asarray([] if value is None else value, dtype=dtype).reshape(-1)
                if f.array >= 0 and value is None:
                    arr = np.zeros(f.array, dtype=dtype)
                if f.array >= 0 and arr.size != f.array:
                    raise ValueError(f"{path}: {arr.size} values for a fixed array of {f.array}")
                if f.array < 0:
                    self._u32(arr.size)
            if arr.size:
                self._pad(arr.dtype.itemsize)
            self.leaves[path] = (len(self.buf), dtype, int(arr.size))
            self.buf += arr.tobytes()
        elif f.is_string:
            if f.base == "wstring":
                raise ValueError(f"{path}: wstring is not supported")
            if f.array is None:
                text = f.default.strip("'\"") if value is None and f.default else (value or "")
                self.texts[path] = str(text)
                self._string(str(text))
            else:
                items = tuple(str(s) for s in (value or ()))
                if f.array < 0:
                    self._u32(len(items))
                self.texts[path] = items
                for s in items:
                    self._string(s)
        elif f.array is None:
            self.message(f.base, value or {}, f"{path}.")
        else:
            items_m: Sequence[Mapping[str, Any]] = value or ()
            if f.array >= 0:
                items_m = list(items_m) + [{}] * (f.array - len(items_m))
            else:
                self._u32(len(items_m))
            for k, item in enumerate(items_m):
                self.message(f.base, item, f"{path}[{k}].")


def _default(f: MsgField) -> Any:
    if f.default is None:
        return 0
    text = f.default.strip()
    if f.base == "bool":
        return text.lower() in ("true", "1")
    return float(text) if f.base.startswith("float") else int(text, 0)


def encode(types: MsgTypes, root: str, value: Mapping[str, Any]) -> tuple[bytes, Layout]:
    """CDR bytes of one message and its layout.

    Args:
        types: parsed definitions (:func:`pipeline.log.msgdef.parse_msgdef`).
        root: the message type.
        value: field values by name; nested messages as mappings, arrays as sequences or
            numpy arrays. Missing fields take their default (0, "", empty, or the
            definition's default value).
    """
    enc = _Encoder(types)
    enc.message(_resolve(types, root), value)
    data = bytes(enc.buf)
    return data, Layout(len(data), enc.leaves, enc.texts, tuple(enc.check))


@dataclass(frozen=True)
class Template:
    """One encoded message and its layout; :meth:`fill` writes N messages at once."""

    data: U8
    layout: Layout

    @property
    def size(self) -> int:
        return int(self.data.size)

    def fill(self, count: int, values: Mapping[str, ArrayLike]) -> U8:
        """``count`` messages as a (count, size) byte matrix.

        Args:
            count: messages.
            values: leaf path -> (count, k) array of that leaf's k elements per message
                (cast to the leaf's wire type); leaves not given keep the template's values.
        """
        out = np.empty((count, self.size), dtype=np.uint8)
        out[:] = self.data
        for path, arr in values.items():
            if path not in self.layout.leaves:
                raise ValueError(f"no numeric field {path!r} in the message")
            offset, dtype, n = self.layout.leaves[path]
            cast = np.ascontiguousarray(np.asarray(arr).astype(dtype, copy=False))
            if cast.size != count * n:
                raise ValueError(f"{path}: shape {cast.shape}, expected ({count}, {n})")
            nbytes = n * cast.dtype.itemsize
            out[:, offset : offset + nbytes] = cast.view(np.uint8).reshape(count, nbytes)
        return out


def template(types: MsgTypes, root: str, sample: Mapping[str, Any]) -> Template:
    """A :class:`Template` laid out from ``sample`` (its strings and sequence lengths)."""
    data, layout = encode(types, root, sample)
    return Template(np.frombuffer(data, dtype=np.uint8), layout)


def time_values(path: str, stamp_ns: ArrayLike) -> dict[str, NDArray[np.int64]]:
    """``{path.sec, path.nanosec}`` columns of builtin_interfaces Time/Duration values.

    Nanoseconds are floored into [0, 1e9) as rclcpp does.

    Raises:
        ValueError: a time whose seconds do not fit int32.
    """
    ns = np.asarray(stamp_ns, dtype=np.int64).reshape(-1)
    sec, nsec = np.divmod(ns, _NS_PER_S)
    if ns.size and (sec.min() < -(2**31) or sec.max() >= 2**31):
        raise ValueError("time does not fit builtin_interfaces int32 seconds")
    return {f"{path}.sec": sec, f"{path}.nanosec": nsec}


def time_value(stamp_ns: int) -> dict[str, int]:
    """One builtin_interfaces Time/Duration as a field mapping."""
    sec, nsec = divmod(int(stamp_ns), _NS_PER_S)
    return {"sec": sec, "nanosec": nsec}


# --- reading --------------------------------------------------------------------------------


def min_bytes(types: MsgTypes, type_name: str, cache: dict[str, int] | None = None) -> int:
    """The fewest bytes a ``type_name`` value takes in CDR (padding aside): what bounds a
    count read from a file, since n elements need at least n times this many bytes.

    A string takes 4 (its length; the NUL is not counted, for encoders that omit it), a
    sequence 4 (its count), a fixed array its length times its element's.
    """
    cache = {} if cache is None else cache
    known = cache.get(type_name)
    if known is not None:
        return known
    cache[type_name] = 0  # (ROS types are not recursive; this only ends a malformed loop)
    total = 0
    for f in types[type_name].fields:
        total += (
            4
            if f.array is not None and f.array < 0
            else (f.array or 1) * _element_bytes(types, f, cache)
        )
    cache[type_name] = total
    return total


def _element_bytes(types: MsgTypes, f: MsgField, cache: dict[str, int]) -> int:
    """The fewest bytes one element of ``f`` takes, at least 1 (an empty ROS 2 message
    still carries one placeholder byte; a zero would let any count through)."""
    if f.is_primitive:
        return int(PRIMITIVES[f.base][1])
    if f.is_string:
        return 4
    return max(1, min_bytes(types, f.base, cache))


def _too_many(path: str, count: int, each: int, left: int) -> ValueError:
    return ValueError(
        f"field {path}: a count of {count:,} needs at least {count * each:,} bytes, "
        f"{max(left, 0):,} remain in the message"
    )


class _Walk:
    """Walks one CDR message, recording where each numeric leaf and string sits.

    Every element count of a string or message array is checked against the bytes left
    (:func:`min_bytes`) before anything loops over it.
    """

    __slots__ = (
        "align", "buf", "check", "end", "endian", "leaves", "mins", "pos", "repeat", "texts",
        "types",
    )  # fmt: skip

    def __init__(self, types: MsgTypes, buf: bytes | memoryview, *, repeat: bool = True) -> None:
        if len(buf) < 4:
            raise ValueError("shorter than the CDR encapsulation header")
        kind = buf[1]
        if kind not in (0, 1):
            raise ValueError(f"unsupported CDR encapsulation kind {kind}")
        self.endian = "<" if kind == 1 else ">"
        self.types = types
        self.buf = buf
        self.end = len(buf)
        self.pos = 4
        self.leaves: dict[str, Leaf] = {}
        self.texts: dict[str, str | tuple[str, ...]] = {}
        self.check: list[tuple[int, int]] = []
        self.align = 1  # the largest alignment applied so far [bytes]
        self.repeat = repeat
        self.mins: dict[str, int] = {}

    def _sub(self, pos: int) -> _Walk:
        """A walker over the same bytes from ``pos``, with its own (empty) records."""
        sub = _Walk.__new__(_Walk)
        sub.endian, sub.types, sub.buf, sub.end, sub.pos = (
            self.endian, self.types, self.buf, self.end, pos
        )  # fmt: skip
        sub.leaves, sub.texts, sub.check, sub.align, sub.repeat = {}, {}, [], 1, self.repeat
        sub.mins = self.mins
        return sub

    def _u32(self, structural: bool = True) -> int:
        self.align = max(self.align, 4)
        self.pos = _aligned(self.pos, 4)
        if self.pos + 4 > self.end:
            raise ValueError("message ends inside a length field")
        (value,) = struct.unpack_from(self.endian + "I", self.buf, self.pos)
        if structural:
            self.check.append((self.pos, self.pos + 4))
        self.pos += 4
        return int(value)

    def _string(self) -> str:
        start = _aligned(self.pos, 4)
        n = self._u32(structural=False)
        if self.pos + n > self.end:
            raise ValueError("message ends inside a string")
        raw = bytes(self.buf[self.pos : self.pos + n])
        self.pos += n
        self.check.append((start, self.pos))
        return raw.rstrip(b"\x00").decode("utf-8", errors="replace")

    def walk(self, type_name: str, prefix: str = "") -> None:
        for f in self.types[type_name].fields:
            path = f"{prefix}{f.name}"
            count = 1 if f.array is None else (self._u32() if f.array < 0 else f.array)
            if not f.is_primitive and f.array is not None and count:
                each = _element_bytes(self.types, f, self.mins)
                if count * each > self.end - self.pos:
                    raise _too_many(path, count, each, self.end - self.pos)
            if f.is_primitive:
                dtype = PRIMITIVES[f.base]
                size = int(dtype[1])
                if count:
                    self.align = max(self.align, min(size, 8))
                    self.pos = _aligned(self.pos, size)
                if self.pos + size * count > self.end:
                    raise ValueError(f"message ends inside field {path}")
                self.leaves[path] = (self.pos, self.endian + dtype, count)
                self.pos += size * count
            elif f.is_string:
                if f.base == "wstring":
                    raise ValueError(f"wstring field {path} is not supported")
                values = tuple(self._string() for _ in range(count))
                self.texts[path] = values[0] if f.array is None else values
            elif f.array is None:
                self.walk(f.base, f"{path}.")
            elif self.repeat and count >= _REPEAT_FROM:
                self._elements(f.base, path, count)
            else:
                for k in range(count):
                    self.walk(f.base, f"{path}[{k}].")

    def _elements(self, type_name: str, path: str, count: int) -> None:
        """``count`` consecutive ``type_name`` values (a message array), walking a block of
        them and reusing its layout, shifted, for the following blocks of the same shape.

        The walk of a value depends only on its start modulo the alignments it applies and on
        the bytes of its length prefixes and strings (its ``check`` ranges). A block is one
        value, or as many (up to 8) as make its length a multiple of their largest alignment
        (an 18-byte value after a 16-byte one, say); if the next block's check bytes
        (``size`` further on) equal this one's, its layout is this one's shifted by ``size``:
        same leaves, same strings, same end.
        """
        k = 0
        while k < count:
            start = pos = self.pos
            block: list[tuple[_Walk, str]] = []
            align = 1
            while True:
                first = f"{path}[{k + len(block)}]."  # (the walk's own names, for its errors)
                sub = self._sub(pos)
                sub.walk(type_name, first)
                block.append((sub, first))
                pos, align = sub.pos, max(align, sub.align)
                size = pos - start
                if size % align == 0 or len(block) == 8 or k + len(block) == count:
                    break
            m = len(block)
            same = 1
            if size > 0 and size % align == 0 and k + m < count:
                check = [c for sub, _ in block for c in sub.check]
                most = min((count - k - m) // m, (self.end - pos) // size)
                same += _repeats(self.buf, start, size, check, most)
            shifts = range(0, same * size, size)
            for i, (sub, first) in enumerate(block):
                prefixes = [f"{path}[{k + j * m + i}]." for j in range(same)]
                cut = len(first)
                for p, (off, dtype, n) in sub.leaves.items():
                    tail = p[cut:]
                    self.leaves.update(
                        zip(
                            [q + tail for q in prefixes],
                            [(off + d, dtype, n) for d in shifts],
                            strict=True,
                        )
                    )
                for p, text in sub.texts.items():
                    self.texts.update((q + p[cut:], text) for q in prefixes)
            self.check.extend(
                [(a + d, b + d) for d in shifts for sub, _ in block for a, b in sub.check]
            )
            self.align = max(self.align, align)
            self.pos = start + same * size
            k += same * m


_REPEAT_FROM = 8  # shorter message arrays are walked element by element (numpy costs more)


def _repeats(
    buf: bytes | memoryview, start: int, size: int, check: list[tuple[int, int]], most: int
) -> int:
    """How many ``size``-byte values after the one at ``start`` have its ``check`` bytes
    (relative to their own start), counting up to ``most``."""
    if most <= 0:
        return 0
    if not check:
        return most
    u8 = np.frombuffer(buf, dtype=np.uint8)
    cols = np.concatenate([np.arange(a - start, b - start, dtype=np.int64) for a, b in check])
    ref = u8[start + cols]
    at = start + size * np.arange(1, most + 1, dtype=np.int64)
    equal = (u8[at[:, None] + cols[None, :]] == ref[None, :]).all(axis=1)
    return most if equal.all() else int(np.argmin(equal))


def walk(
    types: MsgTypes,
    root: str,
    data: bytes | memoryview,
    *,
    exact: bool = False,
    repeat: bool = True,
) -> Layout:
    """The layout of one CDR message of type ``root`` (read from its bytes).

    Args:
        exact: also refuse bytes left over after the last field (beyond alignment
            padding): tells apart definitions that share a prefix.
        repeat: walk the first of a run of same-shaped array elements only and shift its
            layout for the others (the same result as walking each; False walks each, for
            the tests that compare the two).

    Raises:
        ValueError: the bytes do not fit the type (truncated or corrupt).
    """
    w = _Walk(types, data, repeat=repeat)
    w.walk(_resolve(types, root))
    if exact and w.end - w.pos > 3:
        raise ValueError(f"{w.end - w.pos} bytes left after the last field")
    return Layout(len(data), w.leaves, w.texts, tuple(w.check))


def decode(types: MsgTypes, root: str, data: bytes | memoryview) -> dict[str, Any]:
    """Every field of one message as a flat mapping: leaf path -> array or string(s)."""
    layout = walk(types, root, data)
    out: dict[str, Any] = {p: layout.values(data, p) for p in layout.leaves}
    out.update(layout.texts)
    return out


# --- reading many messages at once -----------------------------------------------------------


@dataclass(frozen=True)
class ManyLayout:
    """Where each numeric field sits in each of N messages of possibly different shapes.

    Attributes:
        leaves: path -> (byte offsets (N,) in the buffer, numpy dtype, element counts (N,));
            for elements of nested sequences only messages that have them count (offset -1
            and count 0 elsewhere).
        regions: path of every string and string sequence -> (start, end) (N,) byte ranges
            in the buffer: equal bytes there mean equal strings.
    """

    leaves: dict[str, tuple[NDArray[np.int64], str, NDArray[np.int64]]]
    regions: dict[str, tuple[NDArray[np.int64], NDArray[np.int64]]]


class _ManyWalk:
    """The :class:`_Walk` over N messages in lockstep: numpy per field, not per message.

    Bounds: the count of a string or message sequence is checked to lie inside its message
    before it is read (loops run over it), and then that its elements fit in the bytes left
    (at least :func:`min_bytes` each); the fields, strings and the counts of primitive
    sequences are checked once, at the end (:func:`walk_many`): positions only grow, so one
    past its message's end shows there (or sends a read off the buffer: IndexError).
    """

    def __init__(
        self,
        types: MsgTypes,
        u8: NDArray[np.uint8],
        base: NDArray[np.int64],
        size: NDArray[np.int64],
    ) -> None:
        self.types = types
        self.u8 = u8
        self.base = base  # buffer offset of each message's first byte (its CDR header)
        self.size = size
        self.u32_at = values_at(u8, "<u4")
        # Every position is known to be this aligned (relative to the byte after the CDR
        # header) while walking; alignments it implies are skipped. See :meth:`_align`.
        self.known = 8
        self.consts: dict[int, NDArray[np.int64]] = {}
        self.mins: dict[str, int] = {}
        self.leaves: dict[str, tuple[NDArray[np.int64], str, NDArray[np.int64]]] = {}
        self.regions: dict[str, tuple[NDArray[np.int64], NDArray[np.int64]]] = {}

    def _check(
        self,
        rel: NDArray[np.int64],
        nbytes: NDArray[np.int64] | int,
        path: str,
        live: NDArray[np.bool_] | None,
    ) -> None:
        over = rel + nbytes > self.size
        if (over if live is None else live & over).any():
            raise ValueError(f"message ends inside field {path}")

    def _u32(
        self,
        rel: NDArray[np.int64],
        path: str,
        live: NDArray[np.bool_] | None,
        *,
        check: bool = True,
    ) -> NDArray[np.int64]:
        """The uint32 at ``rel`` in each message (0 where not ``live``).

        ``check=False`` (a count that only moves positions, no loop runs over it) leaves the
        bounds to the final check; a read past the buffer raises IndexError there.
        """
        if check:
            self._check(rel, 4, path, live)
        if live is None:
            every: NDArray[np.int64] = self.u32_at[self.base + rel].astype(np.int64)
            return every
        values = self.u32_at[np.where(live, self.base + rel, 0)].astype(np.int64)
        out: NDArray[np.int64] = np.where(live, values, 0)
        return out

    def walk(
        self,
        type_name: str,
        rel: NDArray[np.int64],
        live: NDArray[np.bool_] | None,
        prefix: str = "",
    ) -> NDArray[np.int64]:
        """Advance ``rel`` (positions inside each message) over one ``type_name`` value, in
        the ``live`` messages (None: all; the others have no such value, their counts are 0)."""

        def pick(new: NDArray[np.int64], old: NDArray[np.int64]) -> NDArray[np.int64]:
            return new if live is None else np.where(live, new, old)

        for f in self.types[type_name].fields:
            path = f"{prefix}{f.name}"
            if f.array is None or f.array >= 0:
                fixed = 1 if f.array is None else f.array
                count = self._const(fixed) if live is None else np.where(live, fixed, 0)
            else:
                rel = pick(self._align(rel, 4), rel)
                if live is None:  # (else the absent values keep their positions)
                    self.known = max(self.known, 4)
                count = self._u32(rel, path, live, check=not f.is_primitive)
                rel = pick(rel + 4, rel)
                self.known = min(self.known, 4)
            if not f.is_primitive and f.array is not None:
                self._fits(f, path, count, rel)
            if f.is_primitive:
                dtype = PRIMITIVES[f.base]
                size = int(dtype[1])
                if self.known < min(size, 8):
                    if live is None and f.array is None:
                        rel = self._align(rel, size)
                        self.known = min(size, 8)
                    else:  # an empty sequence is not aligned (nor are absent values)
                        rel = np.where(count > 0, _aligned_v(rel, size), rel)
                at = self.base + rel
                self.leaves[path] = (
                    at if live is None else np.where(live, at, -1),
                    "<" + dtype,
                    count,
                )
                rel = rel + count * size
                self.known = min(self.known, size)
            elif f.is_string:
                if f.base == "wstring":
                    raise ValueError(f"wstring field {path} is not supported")
                start = rel.copy()
                for k in range(int(count.max(initial=0))):
                    has = k < count
                    if has.all():
                        at = self._align(rel, 4)
                        rel = at + 4 + self._u32(at, path, None)
                    else:
                        at = np.where(has, self._align(rel, 4), rel)
                        rel = np.where(has, at + 4 + self._u32(at, path, has), rel)
                    self.known = 1
                self.regions[path] = (self.base + start, self.base + rel)
            elif f.array is None:
                rel = self.walk(f.base, rel, live, f"{path}.")
            else:
                for k in range(int(count.max(initial=0))):
                    has = k < count
                    rel = self.walk(f.base, rel, None if has.all() else has, f"{path}[{k}].")
        return rel

    def _fits(
        self, f: MsgField, path: str, count: NDArray[np.int64], rel: NDArray[np.int64]
    ) -> None:
        """Refuse counts whose elements cannot fit in the bytes left of their message (before
        a loop runs over them: a corrupted count would loop billions of times)."""
        each = _element_bytes(self.types, f, self.mins)
        left = self.size - rel
        over = (count > 0) & (count * each > left)
        if over.any():
            k = int(np.argmax(over))
            raise _too_many(path, int(count[k]), each, int(left[k]))

    def _align(self, rel: NDArray[np.int64], size: int) -> NDArray[np.int64]:
        """``rel`` aligned for a ``size``-byte primitive; free when it is known to be."""
        a = min(size, 8)
        if self.known >= a:
            return rel
        out: NDArray[np.int64] = 4 + ((rel - 4 + (a - 1)) & -a)
        return out

    def _const(self, value: int) -> NDArray[np.int64]:
        """A read-only (N,) array of ``value`` (shared: element counts of fixed fields)."""
        arr = self.consts.get(value)
        if arr is None:
            arr = self.consts[value] = np.full(self.base.size, value, dtype=np.int64)
            arr.flags.writeable = False
        return arr


def _aligned_v(rel: NDArray[np.int64], size: int) -> NDArray[np.int64]:
    a = min(size, 8)
    if a == 1:
        return rel
    out: NDArray[np.int64] = 4 + ((rel - 4 + (a - 1)) & -a)
    return out


def walk_many(
    types: MsgTypes,
    root: str,
    u8: NDArray[np.uint8],
    starts: NDArray[np.int64],
    sizes: NDArray[np.int64],
) -> ManyLayout:
    """The layouts of N little-endian CDR messages of type ``root`` at once.

    Args:
        u8: the buffer holding the messages.
        starts: each message's first byte (its CDR header) in ``u8``.
        sizes: each message's length [bytes].

    Raises:
        ValueError: a message that does not fit the type, or is not little-endian CDR.
    """
    if np.any(sizes < 4) or not np.all(u8[starts + 1] == 1):
        raise ValueError("not little-endian CDR (encapsulation header)")
    w = _ManyWalk(types, u8, starts.astype(np.int64), sizes.astype(np.int64))
    try:
        end = w.walk(_resolve(types, root), np.full(starts.size, 4, dtype=np.int64), None)
    except IndexError as err:  # a count read past its message sent a position off the buffer
        raise ValueError("a message ends inside a field") from err
    # Positions only grow, so a field, string or count running past its message shows here;
    # the counts that loops run over were checked before they were read.
    if (end > w.size).any():
        raise ValueError("a message ends inside a field")
    return ManyLayout(w.leaves, w.regions)
