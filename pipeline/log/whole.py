"""Read a recording whole: every message of the chosen topics decoded in one pass, then
paired and framed as one window (:class:`pipeline.log.pairing.Windows`, the windowed read's
framing) into a :class:`~pipeline.log.recording.Recording`.

:func:`pipeline.log.reader.read_recording` sends recordings up to
:data:`pipeline.log.recording.STREAM_ABOVE_BYTES` here (longer ones to
:mod:`pipeline.log.windowed`, which streams the rows into many windows of the same code).
:func:`assemble` is the second half: decoded arrays -> the recording; an episode's streams
take the same way without a file (:func:`episode_recording`: the campaign path).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.constants import TYPE_CONTROLLER_STATE
from pipeline.log import cdr
from pipeline.log.collect import (
    WANT,
    Collector,
    decode_planned,
    pick_roles,
    planned_trajectory,
    scan_storage,
)
from pipeline.log.decode import Want
from pipeline.log.labels import (
    Labels,
    check_trajectory_duration,
    labels_of,
    read_labels,
    reference_end_s,
)
from pipeline.log.notes import (
    JS_OPTIONAL,
    dropped_note,
    missing_array_notes,
    no_pairs,
    paired_note,
    read_notes,
)
from pipeline.log.pairing import Framing, Stream, Windows, stamp_period_ns
from pipeline.log.recording import (
    F64,
    STREAM_ABOVE_BYTES,
    PlannedTrajectory,
    ReadOptions,
    Recording,
    episode_name,
)
from pipeline.log.schemas import message_types
from pipeline.log.streams import EpisodeStreams
from pipeline.log.topics import PAIRED, ROLES, TOPICS, Fill

__all__ = [
    "MAX_BAG_BYTES_PER_JOINT_STEP",
    "Decoded",
    "assemble",
    "episode_recording",
    "read_whole",
    "reads_whole",
]

# Bag bytes per control step and joint, at most: every topic uncompressed (Humble's
# controller state repeats reference and feedback) is ~250; zstd only shrinks it.
MAX_BAG_BYTES_PER_JOINT_STEP = 400


@dataclass(frozen=True)
class Decoded:
    """A recording's messages decoded to arrays, before the topics are paired: what
    :func:`assemble` makes the :class:`Recording` of (from a file, :func:`read_whole`;
    from an episode's streams, :func:`episode_recording`).

    Attributes:
        source, mcap_path, sha256, size_bytes: the recording as found (the file's bytes).
        names: joint order.
        js_topic, cs_topic: the joint-state and controller-state topics read.
        js_t, js_a: joint-state stamps [ns] and (N, joints) arrays (``position``,
            ``velocity``, ``effort``).
        cs_t, cs_a: controller-state stamps [ns] and arrays (:data:`WANT`'s keys).
        paired: the paired roles present (:data:`pipeline.log.topics.PAIRED`): role ->
            stamps, arrays and its joints in ``names`` order.
        notes: the read's first notes (storage, salvage, joints analysed).
        lost_pct: the share a salvage lost [%] (None: not salvaged, or unknown).
        damaged: read with salvage up to damage, or from a file short of what it declares.
        labels: the recording's labels (:func:`pipeline.log.labels.read_labels`).
        planned: the planned trajectory, and the topic it came from.
        topic_counts: messages per topic.
        decoded_messages: messages decoded into the frames.
    """

    source: Path
    mcap_path: Path
    sha256: str
    size_bytes: int
    names: tuple[str, ...]
    js_topic: str
    cs_topic: str
    js_t: NDArray[np.int64]
    js_a: dict[str, F64]
    cs_t: NDArray[np.int64]
    cs_a: dict[str, F64]
    paired: dict[str, tuple[NDArray[np.int64], dict[str, F64], list[int]]]
    notes: list[str]
    lost_pct: float | None
    damaged: bool
    labels: Labels
    planned: PlannedTrajectory | None
    planned_topic: str
    topic_counts: dict[str, int]
    decoded_messages: int


def read_whole(
    source: Path, files: list[Path], options: ReadOptions, *, copies: Mapping[Path, Path]
) -> Recording:
    mcap_path = files[0]
    collector = Collector(options.topics)
    scanned = scan_storage(files, collector, salvage=options.salvage, copies=copies, source=source)
    roles = pick_roles(
        collector, scanned.present, mcap_path, scanned.salvaged,
        joint_states_only=options.joint_states_only,
    )  # fmt: skip
    js_t, js_all = roles.js_group.concat()
    if roles.cs_dec is roles.js_dec:  # joint states only: no controller columns
        cs_t = js_t
        nulls = np.full_like(js_all["position"], np.nan, dtype=float)
        cs_a = dict.fromkeys(WANT[TYPE_CONTROLLER_STATE].arrays, nulls)
    else:
        cs_t, cs_a = roles.cs_group.concat()
    js_cols = roles.js_cols
    js_a = js_all if js_cols is None else {k: v[:, js_cols] for k, v in js_all.items()}
    notes, lost_pct = read_notes(scanned, roles)
    return assemble(
        Decoded(
            source=source,
            mcap_path=mcap_path,
            sha256=scanned.sha256,
            size_bytes=scanned.size,
            names=roles.names,
            js_topic=roles.js_dec.topic,
            cs_topic=roles.cs_dec.topic,
            js_t=js_t,
            js_a=js_a,
            cs_t=cs_t,
            cs_a=cs_a,
            paired={r: (*g.concat(), roles.perm(r)) for r, g in roles.paired.items()},
            notes=notes,
            lost_pct=lost_pct,
            damaged=scanned.damaged,
            labels=read_labels(collector, source, options, roles.chosen, roles.names),
            planned=planned_trajectory(collector, roles.chosen["planned_trajectory"]),
            planned_topic=str(roles.chosen["planned_trajectory"]),
            topic_counts=dict(collector.topic_counts),
            decoded_messages=roles.js_group.count
            + (roles.cs_group.count if roles.cs_dec is not roles.js_dec else 0)
            + sum(g.count for g in roles.paired.values()),
        )
    )


def reads_whole(episode: EpisodeStreams) -> bool:
    """The bag of ``episode`` is surely read whole (not in windows) by the reader."""
    steps = int(episode.stamp_ns.size)
    return steps * episode.spec.dof * MAX_BAG_BYTES_PER_JOINT_STEP < STREAM_ABOVE_BYTES


def _wanted(fill: Fill, want: Want | None, n: int) -> dict[str, F64]:
    """The arrays the reader decodes of a topic (``want``), taken from its fill's columns
    (first alias present wins; absent: NaN)."""
    assert want is not None
    out = {}
    for key, aliases in want.arrays.items():
        path = next((p for p in aliases if p in fill.columns), None)
        nan = np.full((fill.stamps.size, n), np.nan)
        out[key] = nan if path is None else np.asarray(fill.columns[path], dtype=np.float64)
    return out


def episode_recording(episode: EpisodeStreams, source: Path) -> Recording:
    """The recording :func:`pipeline.log.reader.read_recording` gives of the bag
    :func:`pipeline.log.bag.write_streams` writes of ``episode`` at ``source`` (read
    whole), but for the file's SHA-256 ("") and size (0): every topic's fill, its wanted
    leaves taken as the reader decodes them (the planned trajectory encoded and decoded),
    through :func:`assemble`. :func:`reads_whole` says when the bag would surely be
    read whole (a windowed read gives decimated frames).

    Raises:
        RecordingError: what the reader refuses of its bag.
    """
    by_name = {t.name: t.fill(episode) for t in TOPICS}
    fills = {role: by_name[t.name] for role, t in ROLES.items()}
    names = episode.joint_names
    n = len(names)
    js, cs = fills["joint_states"], fills["controller_state"]
    planned = ROLES["planned_trajectory"]
    types = message_types(planned.type, episode.ros_distro)
    data, _ = cdr.encode(types, planned.type, fills["planned_trajectory"].columns)
    description = fills["robot_description"].columns["data"]
    source = Path(source)
    return assemble(
        Decoded(
            source=source,
            mcap_path=source / f"{source.name}_0.mcap",
            sha256="",
            size_bytes=0,
            names=names,
            js_topic=ROLES["joint_states"].name,
            cs_topic=ROLES["controller_state"].name,
            js_t=js.stamps,
            js_a=_wanted(js, ROLES["joint_states"].want, n),
            cs_t=cs.stamps,
            cs_a=_wanted(cs, ROLES["controller_state"].want, n),
            paired={
                r: (fills[r].stamps, _wanted(fills[r], t.want, n), list(range(n)))
                for r, t in PAIRED.items()
            },
            notes=[],
            lost_pct=None,
            damaged=False,
            labels=labels_of(
                episode.metadata,
                description,
                source=source,
                options=ReadOptions(),
                urdf_topic=ROLES["robot_description"].name,
                names=names,
            ),
            planned=decode_planned(types, planned.type, data),
            planned_topic=planned.name,
            topic_counts={name: f.stamps.size for name, f in by_name.items()},
            decoded_messages=sum(
                fills[r].stamps.size for r in ("joint_states", "controller_state", *PAIRED)
            ),
        )
    )


def assemble(d: Decoded) -> Recording:
    """The :class:`Recording` of decoded messages: the windowed read's framing
    (:class:`pipeline.log.pairing.Windows`) over one window holding every row, the notes,
    the duration check."""
    js_t, js_a, cs_t, names = d.js_t, d.js_a, d.cs_t, d.names
    mcap_path, source, labels = d.mcap_path, d.source, d.labels

    def stream(stamps: NDArray[np.int64], arrays: dict[str, F64], keys: list[str]) -> Stream:
        s = Stream(names, first=0, last=0)  # one window: neither bound is asked
        s.push(stamps, {k: arrays[k] for k in keys})
        return s

    # Relative times: wall-clock header stamps (1.7e9 s) would otherwise swamp float64
    # resolution and put the motion end (a duration from the start) 50 years early.
    t0_ns = int(min(js_t[0], cs_t[0])) if js_t.size and cs_t.size else 0
    windows = Windows(
        Framing(
            names=names,
            perms={r: found[2] for r, found in d.paired.items()},
            js_period_ns=stamp_period_ns(js_t),
            cs_period_ns=stamp_period_ns(cs_t),
            t0_ns=t0_ns,
            episode=episode_name(labels.metadata, source),
        ),
        stream(js_t, js_a, list(js_a)),
        stream(cs_t, d.cs_a, list(d.cs_a)),
        {r: stream(t, a, list(a)) for r, (t, a, _) in d.paired.items() if r in PAIRED},
    )
    windows.one()
    if windows.pairs == 0:
        raise no_pairs(mcap_path)
    notes = list(d.notes)
    notes += dropped_note(windows.dropped)
    notes += missing_array_notes(js_a, d.js_topic, JS_OPTIONAL)
    notes += labels.notes
    for role, row in PAIRED.items():
        if role in d.paired:
            notes += paired_note(windows.unpaired[role], d.cs_topic, row.name)
    planned = d.planned
    contradicted = check_trajectory_duration(
        labels.settings,
        planned,
        end_s=(int(max(js_t[-1], cs_t[-1])) - t0_ns) * 1e-9,
        salvaged=d.damaged,
        control_period_s=float(np.median(np.diff(cs_t))) * 1e-9 if cs_t.size > 1 else 0.0,
        reference_end=reference_end_s(cs_t, d.cs_a["reference_position"], t0_ns),
        planned_topic=d.planned_topic,
    )
    notes += [contradicted.note] if contradicted else []
    samples, controller_states = windows.frames()
    return Recording(
        source=source,
        mcap_path=mcap_path,
        sha256=d.sha256,
        size_bytes=d.size_bytes,
        metadata=labels.metadata,
        settings=labels.settings,
        joint_names=names,
        samples=samples,
        controller_states=controller_states,
        planned=planned,
        robot_description=labels.urdf,
        topic_counts=d.topic_counts,
        decoded_messages=d.decoded_messages,
        notes=(*notes, *labels.settings_notes),
        has_ground_truth="ground_truth" in d.paired,
        salvaged=d.damaged,
        salvage_lost_pct=d.lost_pct,
        armlab_metadata=labels.ours,
        duration_contradicted=contradicted is not None,
        data_trajectory_duration_s=contradicted.duration_s if contradicted else None,
    )
