"""Read a long recording in two streaming passes, in windows: memory does not grow with it.

:func:`pipeline.log.reader.read_recording` sends recordings above
:data:`pipeline.log.recording.STREAM_ABOVE_BYTES` here.

- **Pass 1** keeps nothing decoded: it finds the channels and picks the roles' topics and
  joint lists as the whole read does, reads the metadata (ours sits near the end of the
  file), the planned trajectory and the robot description, and per control-rate joint
  list the message count, first and last stamp and the histogram of stamp steps (so the
  median period, which pairs stamps, is the whole recording's, exactly).
- **Pass 2** decodes the chosen topics chunk by chunk into streams, and
  :class:`pipeline.log.pairing.Windows` (the whole read's framing, where it is one window)
  cuts the rows into windows of contiguous stamp intervals, each flushed once every topic
  has delivered past its end plus a period (a watermark), so pairing ``/joint_states``
  with ``/controller_state`` and that with ``/ground_truth/joint_states`` (nearest stamp
  within half a period) gives the pairs of the whole read, also across window boundaries.
  Each window's tidy frames (the rows the whole read has in that interval) go to a
  :class:`~pipeline.log.recording.WindowSink`;
  every k-th control step is kept for the returned :class:`~pipeline.log.recording.Recording`.

Memory: one window, one batch of chunks and what the sink keeps, as long as the file holds
the topics interleaved in time (as recorders write them); a topic stored long after the
others is buffered until the others reach it (correct, not bounded). A topic that starts
late or pauses (no stamp for more than :data:`GAP_NS`) does not hold the others back: pass 1
notes its first stamp and its gaps, so pass 2 knows that nothing of it lies before or inside
one.

Stamps out of order: within a batch of chunks they are sorted, as the whole read sorts;
a stamp that goes back behind an earlier batch of the same topic and joint list is
refused in one line naming the file and topic (a window may already have been handed on).
Where both topics carry the same stamp more than once and also have stamps the other
lacks, a window pairs duplicates as identical stamp runs (the whole read: nearest).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import RecordingError
from pipeline.log.collect import (
    WANT,
    Collector,
    pick_roles,
    planned_trajectory,
    scan_storage,
)
from pipeline.log.db3 import Db3Scan
from pipeline.log.decode import DecodeError, TopicDecoder
from pipeline.log.labels import check_trajectory_duration, read_labels
from pipeline.log.mcap import McapChannel, McapScan
from pipeline.log.notes import (
    JS_OPTIONAL,
    dropped_note,
    empty_array_notes,
    no_pairs,
    paired_note,
    read_notes,
)
from pipeline.log.pairing import Framing, Stream, Windows
from pipeline.log.recording import (
    CONTROLLER_STATE_COLUMNS,
    SAMPLE_COLUMNS,
    STREAM_ABOVE_BYTES,
    ReadOptions,
    Recording,
    SinkError,
    WindowSink,
    episode_name,
)
from pipeline.log.topics import PAIRED

# A decimated recording keeps at most about this many control steps for figures and series.
MAX_KEPT_STEPS = 20_000
# Control steps per window (20 s at 1 kHz; some 15 MB of frames for six joints).
WINDOW_STEPS = 20_000
# Distinct stamp steps of batches held before merging them into a joint list's histogram.
_MERGE_STEPS = 1 << 18
# Stamps kept per joint list in pass 1 to find the last paired /joint_states message.
_TAIL = 4096
# A joint list's stamp step longer than this is a gap pass 1 notes (so pass 2 does not
# buffer the other topics while this one is silent): at most one per second of recording.
GAP_NS = 1_000_000_000

I64 = NDArray[np.int64]


@dataclass
class _StampStats:
    """One joint list's stamps as pass 1 saw them, without keeping them."""

    count: int = 0
    first: int = 0
    last: int = 0
    back: tuple[Path, int, int] | None = None  # (file, stamp, earlier stamp): out of order
    # the histogram of stamp steps [ns]: sorted distinct steps and how often each occurs
    # (16 bytes a distinct step: wall-clock stamps with jitter have many), and batches'
    # histograms not merged yet
    step_values: I64 = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    step_counts: I64 = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    pending: list[tuple[I64, I64]] = field(default_factory=list)
    pending_size: int = 0
    tail: I64 = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    # stamp before a gap (a step > GAP_NS) -> (the stamp after it, stamps up to the one before)
    gaps: dict[int, tuple[int, int]] = field(default_factory=dict)

    def add(self, stamps: I64, path: Path) -> None:
        if not stamps.size:
            return
        t = np.sort(stamps, kind="stable")
        if self.count and int(t[0]) < self.last and self.back is None:
            self.back = (path, int(t[0]), self.last)
        before = t if not self.count else np.concatenate([[self.last], t])
        diffs = np.diff(before)
        for i in np.flatnonzero(diffs > GAP_NS).tolist():
            # before[i] is the (count + i)-th stamp in order when a batch starts at the
            # previous one's last (its index 0), else the (i + 1)-th
            upto = self.count + i if self.count else i + 1
            self.gaps[int(before[i])] = (int(before[i + 1]), upto)
        values, counts = np.unique(diffs, return_counts=True)
        self.pending.append((values, counts.astype(np.int64)))
        self.pending_size += values.size
        if self.pending_size > _MERGE_STEPS:
            self._merge()
        if not self.count:
            self.first = int(t[0])
        self.last = max(self.last, int(t[-1])) if self.count else int(t[-1])
        self.count += t.size
        self.tail = np.concatenate([self.tail, t])[-_TAIL:]

    def _merge(self) -> None:
        if not self.pending:
            return
        values, where = np.unique(np.concatenate([v for v, _ in self.pending]), return_inverse=True)
        counts = np.zeros(values.size, dtype=np.int64)
        np.add.at(counts, where, np.concatenate([c for _, c in self.pending]))
        self.pending, self.pending_size = [], 0
        # into the sorted histogram: add to the steps it has, insert the others (one copy)
        at = np.searchsorted(self.step_values, values)
        known = at < self.step_values.size
        known[known] = self.step_values[at[known]] == values[known]
        self.step_counts[at[known]] += counts[known]
        self.step_values = np.insert(self.step_values, at[~known], values[~known])
        self.step_counts = np.insert(self.step_counts, at[~known], counts[~known])

    def period_ns(self) -> float:
        """``np.median(np.diff(sorted stamps))`` of every stamp (1.0 for fewer than two)."""
        self._merge()
        cum = np.cumsum(self.step_counts)
        n = int(cum[-1]) if cum.size else 0
        if n == 0:
            return 1.0

        def at(i: int) -> float:
            return float(self.step_values[int(np.searchsorted(cum, i, side="right"))])

        return at(n // 2) if n % 2 else (at(n // 2 - 1) + at(n // 2)) / 2


class _Pass1(Collector):
    """Decodes the candidates as the whole read does, keeping only :class:`_StampStats`."""

    def __init__(self, topics: dict[str, str]) -> None:
        super().__init__(topics)
        self.stats: dict[tuple[str, tuple[str, ...]], _StampStats] = {}

    def on_messages(
        self, scan: McapScan | Db3Scan, channel: McapChannel, buf: bytes, starts: I64
    ) -> None:
        super().on_messages(scan, channel, buf, starts)
        dec = self.decoders.get(channel.topic)
        if dec is None:
            return
        for group in dec.groups:
            stamps, _ = group.take()
            self.stats.setdefault((dec.topic, group.names), _StampStats()).add(stamps, self.path)


class _Chosen(Collector):
    """Decodes a chosen control-rate topic's messages (no other)."""

    def decode(
        self, scan: McapScan | Db3Scan, channel: McapChannel, buf: bytes, starts: I64
    ) -> TopicDecoder:
        type_name, types = self.type_of(scan, channel)
        dec = self.decoders.get(channel.topic)
        if dec is None:
            dec = self.decoders[channel.topic] = TopicDecoder(
                channel.topic, type_name, types, WANT[type_name]
            )
        try:
            dec.add(buf, starts)
        except DecodeError as err:
            raise self.fail(str(err)) from err
        return dec


class _LastPaired(_Chosen):
    """The largest stamp of one joint list within ``(after, after + reach]`` (a pass over
    its stamps alone, when pass 1's tail does not reach back to the last controller state)."""

    def __init__(
        self, topics: dict[str, str], topic: str, names: tuple[str, ...], after: int, reach: float
    ) -> None:
        super().__init__(topics)
        self.topic, self.names, self.after, self.reach = topic, names, after, reach
        self.found: int | None = None

    def on_messages(
        self, scan: McapScan | Db3Scan, channel: McapChannel, buf: bytes, starts: I64
    ) -> None:
        if channel.topic != self.topic:
            return
        for group in self.decode(scan, channel, buf, starts).groups:
            stamps, _ = group.take()
            if group.names != self.names:
                continue
            near = stamps[(stamps > self.after) & ((stamps - self.after) <= self.reach)]
            if near.size:
                self.found = max(int(near.max()), self.found or self.after)


class _Pass2(_Chosen):
    """Decodes the chosen topics only and hands each chosen joint list's rows on."""

    def __init__(self, topics: dict[str, str], streams: dict[str, Stream], windows: Windows):
        super().__init__(topics)
        self.streams = streams  # topic -> its chosen stream
        self.windows = windows
        self.stream_names = {t: s.names for t, s in streams.items()}

    def on_messages(
        self, scan: McapScan | Db3Scan, channel: McapChannel, buf: bytes, starts: I64
    ) -> None:
        stream = self.streams.get(channel.topic)
        if stream is None:
            return
        dec = self.decode(scan, channel, buf, starts)
        for group in dec.groups:
            stamps, arrays = group.take()
            if group.names == stream.names:
                stream.push(stamps, arrays)
        self.windows.pump()


def _refuse_unordered(stats: _StampStats, topic: str, limit: int) -> None:
    if stats.back is None:
        return
    path, stamp, earlier = stats.back
    raise RecordingError(
        f"{path}: {topic} stamps go back in time across chunks ({stamp} ns after {earlier} ns); "
        f"a recording above {limit / 2**20:g} MiB is read in windows, which needs each "
        "topic's stamps in order from one batch of chunks to the next"
    )


def _end_ns(
    cs: _StampStats, js: _StampStats, js_period_ns: float, scan_js: Callable[[int, float], int]
) -> int:
    """The last paired stamp: the last controller state, or a later joint state that
    pairs with it (within half the joint-state period).

    ``scan_js(after, reach)`` reads the joint states' stamps again for the largest within
    ``(after, after + reach]``: needed when more than :data:`_TAIL` joint states follow
    the pairing ones (a joint-state publisher that outlives the controller).
    """
    reach = js_period_ns / 2
    if js.count > js.tail.size and int(js.tail[0]) - cs.last > reach:
        return scan_js(cs.last, reach)
    later = js.tail[(js.tail - cs.last) <= reach]
    return max(cs.last, int(later.max())) if later.size else cs.last


def read_windowed(
    source: Path,
    files: list[Path],
    options: ReadOptions,
    sink: WindowSink | None,
    *,
    copies: Mapping[Path, Path] | None = None,
) -> Recording:
    """Read ``source`` in two passes (module doc); ``sink`` receives the exact windows.

    ``copies``: ``.db3`` files copied once with their ``-wal`` for every pass.
    """
    limit = STREAM_ABOVE_BYTES if options.stream_above_bytes is None else options.stream_above_bytes
    mcap_path = files[0]
    first = _Pass1(dict(options.topics))
    scanned = scan_storage(files, first, salvage=options.salvage, copies=copies, source=source)
    roles = pick_roles(first, scanned.present, mcap_path, scanned.salvaged)
    js_topic, cs_topic = roles.js_dec.topic, roles.cs_dec.topic
    js_stats = first.stats[(js_topic, roles.js_group.names)]
    cs_stats = first.stats[(cs_topic, roles.names)]
    _refuse_unordered(js_stats, js_topic, limit)
    _refuse_unordered(cs_stats, cs_topic, limit)
    paired_stats = {
        r: first.stats[(str(roles.chosen[r]), g.names)] for r, g in roles.paired.items()
    }
    for r, stats in paired_stats.items():
        _refuse_unordered(stats, str(roles.chosen[r]), limit)
    labels = read_labels(first, source, options, roles.chosen, roles.names)
    js_period = js_stats.period_ns()

    def scan_js(after: int, reach: float) -> int:
        last = _LastPaired(dict(options.topics), js_topic, roles.js_group.names, after, reach)
        scan_storage(files, last, salvage=options.salvage, copies=copies)
        return after if last.found is None else last.found

    cs_period = cs_stats.period_ns()
    steps = max(js_stats.count, cs_stats.count)
    t0_ns = min(js_stats.first, cs_stats.first)
    end_ns_1 = _end_ns(cs_stats, js_stats, js_period, scan_js)  # pass 1's
    framing = Framing(
        names=roles.names,
        perms={r: roles.perm(r) for r in paired_stats},
        js_period_ns=js_period,
        cs_period_ns=cs_period,
        t0_ns=t0_ns,
        episode=episode_name(labels.metadata, source),
        decimation=max(1, math.ceil(steps / MAX_KEPT_STEPS)),
        window_steps=options.window_steps if options.window_steps > 0 else WINDOW_STEPS,
    )
    js_keys = tuple(WANT[roles.js_dec.type_name].arrays)
    js = Stream(
        roles.js_group.names,
        js_stats.first,
        js_stats.last,
        roles.js_cols,
        js_stats.gaps,
        keys=js_keys,
    )
    cs_keys = tuple(WANT[roles.cs_dec.type_name].arrays)
    cs = Stream(roles.names, cs_stats.first, cs_stats.last, gaps=cs_stats.gaps, keys=cs_keys)
    paired = {
        r: Stream(
            roles.paired[r].names,
            stats.first,
            stats.last,
            gaps=stats.gaps,
            keys=tuple(WANT[PAIRED[r].type].arrays),
        )
        for r, stats in paired_stats.items()
    }
    windows = Windows(framing, js, cs, paired)
    header_notes, lost_pct = read_notes(scanned, roles)
    planned = planned_trajectory(first, roles.chosen["planned_trajectory"])
    contradicted = check_trajectory_duration(
        labels.settings,
        planned,
        end_s=(end_ns_1 - t0_ns) * 1e-9,
        salvaged=scanned.damaged,
        control_period_s=cs_period * 1e-9 if cs_stats.count > 1 else 0.0,
        planned_topic=str(roles.chosen["planned_trajectory"]),
    )
    header_notes += [contradicted.note] if contradicted else []
    empty = np.zeros(0, dtype=np.int64)
    no_rows = np.zeros((0, len(roles.names)))
    header = Recording(
        source=source,
        mcap_path=mcap_path,
        sha256=scanned.sha256,
        size_bytes=scanned.size,
        metadata=labels.metadata,
        settings=labels.settings,
        joint_names=roles.names,
        samples=windows.tidy(empty, dict.fromkeys(_SAMPLE_VALUES, no_rows)),
        controller_states=windows.tidy(empty, dict.fromkeys(_CS_VALUES, no_rows)),
        planned=planned,
        robot_description=labels.urdf,
        topic_counts=dict(first.topic_counts),
        decoded_messages=js_stats.count
        + cs_stats.count
        + sum(stats.count for stats in paired_stats.values()),
        notes=(*header_notes, *labels.notes, *labels.settings_notes),
        has_ground_truth="ground_truth" in paired,
        salvaged=scanned.damaged,
        salvage_lost_pct=lost_pct,
        armlab_metadata=labels.ours,
        decimation=framing.decimation,
        controller_sample_count=cs_stats.count,
        end_s=(end_ns_1 - t0_ns) * 1e-9,
        control_period_s=cs_period * 1e-9 if cs_stats.count > 1 else 0.0,
        duration_contradicted=contradicted is not None,
        data_trajectory_duration_s=contradicted.duration_s if contradicted else None,
    )
    del first
    if sink is not None:
        try:
            sink.begin(header)
        except Exception as err:
            raise SinkError() from err
    windows.sink = sink
    streams = {js_topic: js, cs_topic: cs}
    for r, stream in paired.items():
        streams[str(roles.chosen[r])] = stream
    second = _Pass2(dict(options.topics), streams, windows)
    again = scan_storage(files, second, salvage=options.salvage, copies=copies)
    if again.sha256 != scanned.sha256:
        raise RecordingError(f"{mcap_path}: the recording changed while it was being read")
    windows.pump(final=True)
    if windows.pairs == 0:
        raise no_pairs(mcap_path)
    notes = [*header_notes, *dropped_note(windows.dropped)]
    notes += empty_array_notes(
        {k for k, empty_all in windows.js_empty.items() if empty_all}, js_topic, JS_OPTIONAL
    )
    notes += labels.notes
    for r in paired:
        notes += paired_note(windows.unpaired[r], cs_topic, PAIRED[r].name)
    end_ns = end_ns_1 if windows.end_ns is None else windows.end_ns
    if end_ns != end_ns_1:  # not expected: pass 1 (with _end_ns) found the same stamp
        notes.append(
            f"the last paired stamp ({end_ns} ns) is not the one the first pass "
            f"estimated ({end_ns_1} ns): the final-window metrics used the estimate"
        )
    samples, states = windows.frames()
    return replace(
        header,
        samples=samples,
        controller_states=states,
        notes=(*notes, *labels.settings_notes),
        windows=windows.count,
        sample_count=windows.pairs,
        end_s=(end_ns - t0_ns) * 1e-9,
    )


# The value columns of the two tidy frames (after episode, stamp_ns, time_s, joint).
_SAMPLE_VALUES = SAMPLE_COLUMNS[4:]
_CS_VALUES = CONTROLLER_STATE_COLUMNS[4:]

__all__ = ["MAX_KEPT_STEPS", "WINDOW_STEPS", "read_windowed"]
