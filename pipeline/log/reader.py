"""Read recordings (rosbag2 directories or bare ``.mcap`` files) into Polars frames.

This is the report stage's only way into a recording, so it trusts nothing: the MCAP file is
streamed and validated by :class:`pipeline.log.mcap.McapScan` (every CRC, one chunk in memory
at a time), messages are decoded through their embedded schemas
(:mod:`pipeline.log.decode`), and any failure is a :class:`RecordingError` naming the file.

The read's parts live in their own modules, shared with the windowed read of long
recordings (:mod:`pipeline.log.windowed`): the :class:`Recording` it returns
(:mod:`pipeline.log.recording`), finding each role's topic (:mod:`pipeline.log.collect`,
roles in :data:`pipeline.log.topics.ROLES`), pairing stamps into tidy frames
(:mod:`pipeline.log.pairing`), labels and settings (:mod:`pipeline.log.labels`) and notes
(:mod:`pipeline.log.notes`). This module reads a recording whole.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from pipeline.errors import RecordingError
from pipeline.log.collect import Collector, pick_roles, planned_trajectory, scan_storage
from pipeline.log.db3 import wal_copies
from pipeline.log.labels import read_labels
from pipeline.log.notes import (
    JS_OPTIONAL,
    dropped_note,
    missing_array_notes,
    no_pairs,
    read_notes,
    truth_note,
)
from pipeline.log.pairing import error_feedback, match_stamps, tidy, truth_at
from pipeline.log.recording import (
    CONTROLLER_STATE_COLUMNS,
    F64,
    SAMPLE_COLUMNS,
    STREAM_ABOVE_BYTES,
    PlannedTrajectory,
    ReadOptions,
    Recording,
    SinkError,
    WindowSink,
    episode_name,
)
from pipeline.log.rosbag2 import find_recordings, storage_files
from pipeline.log.topics import ROLES
from pipeline.log.windowed import read_windowed

# Re-exported: the reader's public surface, as its callers import it.
__all__ = [
    "CONTROLLER_STATE_COLUMNS",
    "ROLES",
    "SAMPLE_COLUMNS",
    "STREAM_ABOVE_BYTES",
    "PlannedTrajectory",
    "ReadOptions",
    "Recording",
    "WindowSink",
    "find_recordings",
    "read_recording",
]


def read_recording(
    source: Path, options: ReadOptions | None = None, *, sink: WindowSink | None = None
) -> Recording:
    """Read one recording (rosbag2 directory or bare ``.mcap``) into a :class:`Recording`.

    Times (``time_s``) count from the recording's first control-rate stamp, so header
    stamps may be simulated (from 0) or wall clock alike; ``stamp_ns`` stays as recorded.
    NaN values and empty arrays (legal in ROS messages) become nulls: "not recorded".

    A recording larger than :data:`STREAM_ABOVE_BYTES` (``options.stream_above_bytes``) is
    read in two streaming passes (:mod:`pipeline.log.windowed`): its frames are decimated
    (``decimation`` > 1) and ``sink`` receives the exact frames window by window.

    Args:
        source: the recording.
        options: remaps, salvage and labels for bags we did not write (see
            :class:`ReadOptions`); with ``salvage`` the recording says what was lost.
        sink: receives a windowed read's windows (ignored when the recording is read whole).

    Raises:
        RecordingError: missing, empty, not MCAP, truncated, corrupt (CRC), lacking
            joint states / controller state messages or a field the report needs, an
            unknown role or topic in ``topics``; any other failure while decoding is
            wrapped into one, naming the file.
    """
    source = Path(source)
    options = options or ReadOptions()
    unknown = sorted(set(options.topics) - set(ROLES))
    if unknown:
        raise RecordingError(f"--topic {unknown[0]}=...: unknown role (roles: {', '.join(ROLES)})")
    try:
        files = storage_files(source)
        total = sum(p.stat().st_size for p in files)
    except OSError as err:
        raise RecordingError(f"{source}: cannot read ({err.strerror or err})") from err
    limit = STREAM_ABOVE_BYTES if options.stream_above_bytes is None else options.stream_above_bytes
    try:
        # a .db3 with a -wal is read from a copy: one for every pass, removed however
        # the read ends (Ctrl-C and SIGTERM included)
        with wal_copies(files) as copies:
            if total > limit:
                return read_windowed(source, files, options, sink, copies=copies)
            return _read(source, files, options, copies=copies)
    except RecordingError:
        raise
    except SinkError as err:  # the caller's sink failed, not the recording
        assert err.__cause__ is not None
        raise err.__cause__ from None
    except Exception as err:  # the boundary: nothing else may escape a per-recording read
        raise RecordingError(
            f"{files[0]}: cannot decode the recording: {type(err).__name__}: {err}"
        ) from err


def _read(
    source: Path, files: list[Path], options: ReadOptions, *, copies: Mapping[Path, Path]
) -> Recording:
    mcap_path = files[0]
    collector = Collector(options.topics)
    scanned = scan_storage(files, collector, salvage=options.salvage, copies=copies)
    roles = pick_roles(collector, scanned.present, mcap_path, scanned.salvaged)
    js_t, js_all = roles.js_group.concat()
    cs_t, cs_a = roles.cs_group.concat()
    js_cols = roles.js_cols
    js_a = js_all if js_cols is None else {k: v[:, js_cols] for k, v in js_all.items()}
    names = roles.names
    js_topic, cs_topic = roles.js_dec.topic, roles.cs_dec.topic
    rows_js, rows_cs = match_stamps(js_t, cs_t)
    if rows_js.size == 0:
        raise no_pairs(mcap_path)
    notes, lost_pct = read_notes(scanned, roles)
    notes += dropped_note(js_t.size - rows_js.size)
    notes += missing_array_notes(js_a, js_topic, JS_OPTIONAL)
    raw_meta, settings, urdf, label_notes, ours = read_labels(
        collector, source, options, roles.chosen, names
    )
    notes += label_notes

    # Relative times: wall-clock header stamps (1.7e9 s) would otherwise swamp float64
    # resolution and put the motion end (a duration from the start) 50 years early.
    t0_ns = int(min(js_t[0], cs_t[0]))
    episode = episode_name(raw_meta, source)
    cs_all = cs_a
    error, feedback = error_feedback(cs_all)
    truth = roles.truth
    truth_pos, truth_vel, rows_cs_gt = truth_at(
        cs_t, truth.concat() if truth else None, roles.gt_perm if truth else [], error
    )
    if truth is not None:
        notes += truth_note(cs_t.size - rows_cs_gt.size, cs_topic)
    every_cs = rows_cs.size == cs_t.size and bool(np.all(rows_cs == np.arange(cs_t.size)))
    every_js = rows_js.size == js_t.size and bool(np.all(rows_js == np.arange(js_t.size)))

    def at_cs(a: F64) -> F64:
        return a if every_cs else a[rows_cs]

    def at_js(a: F64) -> F64:
        return a if every_js else a[rows_js]

    cs_rows = {k: at_cs(v) for k, v in cs_all.items()}
    samples = tidy(
        js_t if every_js else js_t[rows_js],
        {
            "position_rad": at_js(js_a["position"]),
            "velocity_rad_s": at_js(js_a["velocity"]),
            "effort_nm": at_js(js_a["effort"]),
            "reference_position_rad": cs_rows["reference_position"],
            "reference_velocity_rad_s": cs_rows["reference_velocity"],
            "error_rad": at_cs(error),
            "commanded_effort_nm": cs_rows["commanded_effort"],
            "true_position_rad": at_cs(truth_pos),
            "true_velocity_rad_s": at_cs(truth_vel),
        },
        names=names,
        t0_ns=t0_ns,
        episode=episode,
    )
    controller_states = tidy(
        cs_t,
        {
            "reference_position_rad": cs_all["reference_position"],
            "reference_velocity_rad_s": cs_all["reference_velocity"],
            "feedback_position_rad": feedback,
            "error_rad": error,
            "commanded_effort_nm": cs_all["commanded_effort"],
            "true_position_rad": truth_pos,
            "true_velocity_rad_s": truth_vel,
        },
        names=names,
        t0_ns=t0_ns,
        episode=episode,
    )
    return Recording(
        source=source,
        mcap_path=mcap_path,
        sha256=scanned.sha256,
        size_bytes=scanned.size,
        metadata=raw_meta,
        settings=settings,
        joint_names=names,
        samples=samples,
        controller_states=controller_states,
        planned=planned_trajectory(collector, roles.chosen["planned_trajectory"]),
        robot_description=urdf,
        topic_counts=dict(collector.topic_counts),
        decoded_messages=roles.js_group.count
        + roles.cs_group.count
        + (truth.count if truth else 0),
        notes=tuple(notes),
        has_ground_truth=truth is not None,
        salvaged=bool(scanned.salvaged),
        salvage_lost_pct=lost_pct,
        armlab_metadata=ours,
    )
