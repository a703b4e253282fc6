"""Pairing a recording's topics by stamp, and the tidy frames the pairs make.

One path makes every reader's frames: the decoded rows of the chosen joint lists go into
:class:`Stream` s, and :class:`Windows` cuts them into windows of contiguous stamp intervals,
pairs each window's rows (``/joint_states`` with ``/controller_state``, that with the paired
roles of :data:`pipeline.log.topics.PAIRED`: nearest stamp within half a period) and builds
its tidy frames. The whole read (:mod:`pipeline.log.whole`, and the in-memory campaign path)
is the read of one window holding every row; the windowed read
(:mod:`pipeline.log.windowed`) streams rows in and emits a window once every topic has
delivered past its end plus a period (a watermark), pairing with the whole recording's
periods, so the windows give the pairs of the whole read, also across window boundaries.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline.log.notes import JS_OPTIONAL
from pipeline.log.recording import F64, SinkError, WindowSink
from pipeline.log.topics import PAIRED

__all__ = [
    "HIGH",
    "LOW",
    "Framing",
    "Stream",
    "Windows",
    "error_feedback",
    "match_stamps",
    "paired_at",
    "stamp_period_ns",
    "tidy",
]

I64 = NDArray[np.int64]
# Stamps are compared as integers: a float64 cannot tell wall-clock nanoseconds apart.
LOW = int(np.iinfo(np.int64).min)
HIGH = int(np.iinfo(np.int64).max)


def _clamp(stamp: int) -> int:
    return min(max(stamp, LOW), HIGH)


def match_stamps(
    js_t: NDArray[np.int64], cs_t: NDArray[np.int64], *, period_ns: float | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Row pairs (joint_states, controller_state) at the same instant (nearest, < half a period).

    ``period_ns``: the ``js_t`` period (default: the median step of ``js_t``); a windowed
    read passes the whole recording's, so a window pairs rows as the whole read does.
    """
    if js_t.shape == cs_t.shape and np.array_equal(js_t, cs_t):
        idx = np.arange(js_t.size)
        return idx, idx
    if cs_t.size == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    period = period_ns if period_ns is not None else stamp_period_ns(js_t)
    j = np.searchsorted(cs_t, js_t).clip(1, max(cs_t.size - 1, 1))
    left = (j - 1).clip(0, cs_t.size - 1)
    right = j.clip(0, cs_t.size - 1)
    pick = np.where(np.abs(cs_t[left] - js_t) <= np.abs(cs_t[right] - js_t), left, right)
    ok = np.abs(cs_t[pick] - js_t) <= period / 2
    return np.flatnonzero(ok), pick[ok]


def stamp_period_ns(stamps: NDArray[np.int64]) -> float:
    """Median step of sorted ``stamps`` [ns] (1.0 for fewer than two)."""
    return float(np.median(np.diff(stamps))) if stamps.size > 1 else 1.0


def tidy(
    stamps: NDArray[np.int64],
    columns: dict[str, F64],
    *,
    names: tuple[str, ...],
    t0_ns: int,
    episode: str,
) -> pl.DataFrame:
    """A tidy frame: one row per stamp and joint, ``time_s`` from ``t0_ns``, NaN -> null."""
    n = len(names)
    m = stamps.size
    frame = pl.DataFrame(
        {
            "stamp_ns": np.repeat(stamps, n),
            "time_s": np.repeat((stamps - t0_ns).astype(np.float64) * 1e-9, n),
            "joint": pl.Series("joint", names, dtype=pl.String).gather(
                np.tile(np.arange(n, dtype=np.int64), m)
            ),
            **{k: np.ascontiguousarray(v).reshape(-1) for k, v in columns.items()},
        }
    )
    return frame.select(
        pl.lit(episode, dtype=pl.String).alias("episode"),
        pl.col("stamp_ns", "time_s", "joint"),
        pl.col(*columns).fill_nan(None),
    )


def error_feedback(cs: dict[str, F64]) -> tuple[F64, F64]:
    """error = reference - feedback: whichever of the two the controller left out."""
    error = np.where(
        np.isnan(cs["error"]), cs["reference_position"] - cs["feedback_position"], cs["error"]
    )
    feedback = np.where(
        np.isnan(cs["feedback_position"]), cs["reference_position"] - error, cs["feedback_position"]
    )
    return error, feedback


def paired_at(
    cs_t: NDArray[np.int64],
    found: tuple[NDArray[np.int64], dict[str, F64]] | None,
    perm: list[int],
    columns: Mapping[str, str],
    like: F64,
    *,
    period_ns: float | None = None,
) -> tuple[dict[str, F64], NDArray[np.intp]]:
    """A paired topic's ``columns`` (column -> its array's key) at each controller-state
    row (NaN where none), and the rows that have one."""
    out = {c: np.full_like(like, np.nan) for c in columns}
    if found is None:
        return out, np.zeros(0, dtype=np.intp)
    t, arrays = found
    rows_cs, rows = match_stamps(cs_t, t, period_ns=period_ns)
    for column, key in columns.items():
        out[column][rows_cs] = arrays[key][rows][:, perm]
    return out, rows_cs


@dataclass
class Stream:
    """The not yet windowed rows of one chosen joint list, sorted by stamp."""

    names: tuple[str, ...]
    first: int  # its first stamp in the recording
    last: int  # its last stamp in the recording
    cols: list[int] | None = None  # columns in controller joint order
    # stamp before a gap -> (the stamp after it, stamps up to the one before): nothing of
    # the stream lies inside (the windowed read's pass 1 finds them)
    gaps: dict[int, tuple[int, int]] = field(default_factory=dict)
    stamps: I64 = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    arrays: dict[str, F64] = field(default_factory=dict)
    high: int = LOW  # largest stamp delivered so far
    delivered: int = 0  # rows delivered so far
    keys: tuple[str, ...] = ()  # its arrays, empty until rows come (a window may come first)

    def __post_init__(self) -> None:
        width = len(self.cols) if self.cols is not None else len(self.names)
        self.arrays = {k: np.zeros((0, width)) for k in self.keys}

    def push(self, stamps: I64, arrays: dict[str, F64]) -> None:
        """Rows in any order: kept sorted by stamp (stable: equal stamps keep theirs)."""
        if not stamps.size:
            return
        if self.cols is not None:
            arrays = {k: v[:, self.cols] for k, v in arrays.items()}
        if stamps.size > 1 and not bool((np.diff(stamps) >= 0).all()):
            order = np.argsort(stamps, kind="stable")
            stamps = stamps[order]
            arrays = {k: v[order] for k, v in arrays.items()}
        held = self.stamps.size > 0
        self.stamps = np.concatenate([self.stamps, stamps]) if held else stamps
        for k, v in arrays.items():
            old = self.arrays.get(k)
            self.arrays[k] = np.concatenate([old, v]) if held and old is not None else v
        self.high = max(self.high, int(stamps[-1]))
        self.delivered += stamps.size

    def complete_to(self) -> int:
        """Every row below this stamp has been delivered (:data:`HIGH`: every row); at the
        start of a gap, with every row up to it delivered, the stamp after the gap."""
        if self.high >= self.last:
            return HIGH
        if not self.delivered:  # nothing lies before its first stamp (a late start)
            return self.first
        gap = self.gaps.get(self.high)
        if gap is not None and gap[1] == self.delivered:
            return gap[0]
        return self.high

    def span(self, lo: int, hi: int) -> tuple[int, int]:
        lo, hi = _clamp(lo), _clamp(hi)
        return int(np.searchsorted(self.stamps, lo)), int(np.searchsorted(self.stamps, hi))

    def rows(self, a: int, b: int) -> tuple[I64, dict[str, F64]]:
        return self.stamps[a:b], {k: v[a:b] for k, v in self.arrays.items()}

    def drop_below(self, stamp: int) -> None:
        a = int(np.searchsorted(self.stamps, _clamp(stamp)))
        self.stamps = self.stamps[a:]
        self.arrays = {k: v[a:] for k, v in self.arrays.items()}


@dataclass(frozen=True)
class Framing:
    """What pairing and framing a recording's windows needs besides its rows.

    Attributes:
        names: controller joint order.
        perms: each paired role's columns in ``names`` order (present roles only).
        js_period_ns, cs_period_ns: the whole recording's joint-state and controller-state
            periods (median stamp step): the pairing tolerance is half of one.
        t0_ns: the time origin (the first control-rate stamp).
        episode: the frames' episode column.
        decimation: every k-th control step is kept for the returned frames.
        window_steps: controller states per window.
    """

    names: tuple[str, ...]
    perms: Mapping[str, list[int]]
    js_period_ns: float
    cs_period_ns: float
    t0_ns: int
    episode: str
    decimation: int = 1
    window_steps: int = 0


def _at(a: F64, rows: NDArray[np.intp], every: bool) -> F64:
    return a if every else a[rows]


def _every(rows: NDArray[np.intp], size: int) -> bool:
    """``rows`` is every row of ``size`` in order (indexing with it would copy them)."""
    return rows.size == size and bool(np.all(rows == np.arange(size)))


class Windows:
    """Cuts the chosen streams into windows at a watermark and builds their frames; read
    whole, a recording is one window (:meth:`one`)."""

    def __init__(
        self, framing: Framing, js: Stream, cs: Stream, paired: Mapping[str, Stream]
    ) -> None:
        self.f = framing
        self.js, self.cs, self.paired = js, cs, dict(paired)
        self.margin = math.ceil(max(framing.js_period_ns, framing.cs_period_ns))
        self.lo = LOW
        self.count = 0
        self.pairs = 0  # /joint_states rows paired so far
        self.cs_rows = 0
        self.dropped = 0
        self.unpaired = dict.fromkeys(self.paired, 0)  # controller states without its row
        self.js_empty = {k: True for k in JS_OPTIONAL}
        self.end_ns: int | None = None  # the last paired stamp so far
        self.kept: list[tuple[pl.DataFrame, pl.DataFrame]] = []
        self.last: list[pl.DataFrame | None] = [None, None]  # unkept last steps
        self.sink: WindowSink | None = None

    def one(self) -> None:
        """Every row delivered: the recording as one window (the whole read)."""
        self._emit(self.lo, HIGH)
        self.lo = HIGH

    def pump(self, *, final: bool = False) -> None:
        while True:
            limit = HIGH
            if not final:
                limit = min(self.js.complete_to(), self._less(self.cs.complete_to()))
                for stream in self.paired.values():
                    limit = min(limit, self._less(stream.complete_to()))
            a, b = self.cs.span(self.lo, limit)
            steps = self.f.window_steps
            cut = a + steps
            if cut < b and self.cs.stamps[cut] == self.cs.stamps[a]:
                # one stamp repeated over a whole window: cut after its last copy
                cut = int(np.searchsorted(self.cs.stamps, self.cs.stamps[a], side="right"))
            if cut < b:
                hi = int(self.cs.stamps[cut])
            elif limit == HIGH:
                hi = HIGH
            else:
                return
            self._emit(self.lo, hi)
            self.lo = hi
            if hi == HIGH:
                return

    def _less(self, complete_to: int) -> int:
        """A topic complete to a stamp pairs rows up to a margin before it."""
        return HIGH if complete_to == HIGH else complete_to - self.margin

    def _emit(self, lo: int, hi: int) -> None:
        f, n = self.f, self.margin
        ja, jb = self.js.span(lo, hi)
        js_t, js_a = self.js.rows(ja, jb)
        xa, xb = self.cs.span(lo - n, hi + n)  # every controller state a js row may pair with
        cs_t, cs_a = self.cs.rows(xa, xb)
        wa, wb = self.cs.span(lo, hi)
        wa, wb = wa - xa, wb - xa  # the window's own controller states, within cs_t
        if js_t.size and js_t.shape == cs_t[wa:wb].shape and np.array_equal(js_t, cs_t[wa:wb]):
            rows_js, rows_cs = np.arange(js_t.size), np.arange(wa, wb)
        else:
            rows_js, rows_cs = match_stamps(js_t, cs_t, period_ns=f.js_period_ns)
        every_js = _every(rows_js, js_t.size)
        every_cs = _every(rows_cs, cs_t.size)
        error, feedback = error_feedback(cs_a)
        paired: dict[str, F64] = {}
        for role, row in PAIRED.items():
            stream = self.paired.get(role)
            found = None
            if stream is not None:
                ga, gb = stream.span(lo - n, hi + n)
                found = stream.rows(ga, gb)
            columns, rows = paired_at(
                cs_t,
                found,
                f.perms[role] if stream is not None else [],
                row.paired or {},
                error,
                period_ns=f.cs_period_ns,
            )
            paired |= columns
            if stream is not None:
                self.unpaired[role] += (wb - wa) - int(((rows >= wa) & (rows < wb)).sum())
        for k in self.js_empty:
            self.js_empty[k] = self.js_empty[k] and bool(np.isnan(js_a[k]).all())
        self.dropped += js_t.size - rows_js.size

        def at_js(a: F64) -> F64:
            return _at(a, rows_js, every_js)

        def at_cs(a: F64) -> F64:
            return _at(a, rows_cs, every_cs)

        samples = self._tidy(
            js_t if every_js else js_t[rows_js],
            {
                "position_rad": at_js(js_a["position"]),
                "velocity_rad_s": at_js(js_a["velocity"]),
                "effort_nm": at_js(js_a["effort"]),
                "reference_position_rad": at_cs(cs_a["reference_position"]),
                "reference_velocity_rad_s": at_cs(cs_a["reference_velocity"]),
                "error_rad": at_cs(error),
                "commanded_effort_nm": at_cs(cs_a["commanded_effort"]),
                **{k: at_cs(v) for k, v in paired.items()},
            },
        )
        w = slice(wa, wb)
        states = self._tidy(
            cs_t[w],
            {
                "reference_position_rad": cs_a["reference_position"][w],
                "reference_velocity_rad_s": cs_a["reference_velocity"][w],
                "feedback_position_rad": feedback[w],
                "error_rad": error[w],
                "commanded_effort_nm": cs_a["commanded_effort"][w],
                **{k: v[w] for k, v in paired.items()},
            },
        )
        ends = [int(js_t[rows_js].max())] if rows_js.size else []
        ends += [int(cs_t[wb - 1])] if wb > wa else []
        if ends:
            self.end_ns = max(ends) if self.end_ns is None else max(self.end_ns, *ends)
        if samples.height or states.height:
            self.count += 1
            if self.sink is not None:
                try:
                    self.sink.window(samples, states)
                except Exception as err:
                    raise SinkError() from err
        self.kept.append(
            (self._decimate(samples, self.pairs, 0), self._decimate(states, self.cs_rows, 1))
        )
        self.pairs += rows_js.size
        self.cs_rows += wb - wa
        self.js.drop_below(hi)
        self.cs.drop_below(hi - n)
        for stream in self.paired.values():
            stream.drop_below(hi - n)

    def tidy(self, stamps: I64, columns: dict[str, F64]) -> pl.DataFrame:
        """A tidy frame of the recording (its joints, time origin and episode)."""
        return tidy(stamps, columns, names=self.f.names, t0_ns=self.f.t0_ns, episode=self.f.episode)

    _tidy = tidy

    def _decimate(self, frame: pl.DataFrame, before: int, which: int) -> pl.DataFrame:
        """Every k-th step of the recording (by its index ``before`` + row // joints); the
        window's last step is held back in case it is the recording's last."""
        if self.f.decimation == 1:  # every step kept
            self.last[which] = None
            return frame
        j = max(len(self.f.names), 1)
        steps = frame.height // j
        if not steps:
            return frame
        index = before + np.repeat(np.arange(steps), j)
        keep = index % self.f.decimation == 0
        self.last[which] = None if keep[-1] else frame.tail(j)
        return frame.filter(pl.Series(keep))

    def frames(self) -> tuple[pl.DataFrame, pl.DataFrame]:
        """The kept (decimated) frames, the last step of each included."""
        out = []
        for which in (0, 1):
            parts = [k[which] for k in self.kept]
            last = self.last[which]
            if last is not None:
                parts.append(last)
            out.append(parts[0] if len(parts) == 1 else pl.concat(parts, how="vertical"))
        return out[0], out[1]
