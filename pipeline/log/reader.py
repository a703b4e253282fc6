"""Read recordings (rosbag2 directories or bare ``.mcap`` files) into Polars frames.

This is the report stage's only way into a recording, so it trusts nothing: the MCAP file is
streamed and validated by :class:`pipeline.log.mcap.McapScan` (every CRC, one chunk in memory
at a time), messages are decoded through their embedded schemas
(:mod:`pipeline.log.decode`), and any failure is a :class:`RecordingError` naming the file.

This module is the one entry point: it checks the options, finds the storage files, holds
the error boundary and sends the recording to the whole read (:mod:`pipeline.log.whole`)
or, above :data:`STREAM_ABOVE_BYTES`, to the windowed one (:mod:`pipeline.log.windowed`).
They differ only in how the decoded rows arrive: the whole read decodes them in one pass
and frames them as one window, the windowed read streams them in a second pass into many
windows. Everything else is one path: the :class:`Recording` they return
(:mod:`pipeline.log.recording`), decoding and finding each role's topic
(:mod:`pipeline.log.collect`, roles in :data:`pipeline.log.topics.ROLES`), pairing stamps
and building the tidy frames window by window (:class:`pipeline.log.pairing.Windows`),
labels and settings (:mod:`pipeline.log.labels`) and notes (:mod:`pipeline.log.notes`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from pipeline.errors import RecordingError
from pipeline.log.db3 import wal_copies
from pipeline.log.recording import (
    CONTROLLER_STATE_COLUMNS,
    SAMPLE_COLUMNS,
    STREAM_ABOVE_BYTES,
    PlannedTrajectory,
    ReadOptions,
    Recording,
    SinkError,
    WindowSink,
)
from pipeline.log.rosbag2 import find_recordings, storage_files
from pipeline.log.topics import ROLES
from pipeline.log.whole import read_whole
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
                rec = read_windowed(source, files, options, sink, copies=copies)
            else:
                rec = read_whole(source, files, options, copies=copies)
            if options.robot is None and options.tip is None:
                return rec
            return dataclasses.replace(rec, given_robot=options.robot, given_tip=options.tip)
    except RecordingError:
        raise
    except SinkError as err:  # the caller's sink failed, not the recording
        assert err.__cause__ is not None
        raise err.__cause__ from None
    except Exception as err:  # the boundary: nothing else may escape a per-recording read
        raise RecordingError(
            f"{files[0]}: cannot decode the recording: {type(err).__name__}: {err}"
        ) from err
