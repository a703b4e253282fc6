"""reports/recording.rrd: per-joint time series and the arm in 3D, with a default blueprint.

Series are sent as whole columns (``send_columns`` + ``TimeColumn``); the arm is
posed by forward kinematics of the recorded robot spec at the recorded joint
positions, thinned to :data:`ARM_RATE_HZ`. Nothing is spawned or served: the
stream goes to a file sink only.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import rerun_bindings as rr_bindings
from numpy.typing import NDArray

from pipeline.analysis.episodes import robot_spec
from pipeline.log.reader import Recording
from pipeline.model.chain import chain
from pipeline.model.dh import link_frames
from pipeline.report import entities as ent
from pipeline.report.inputs import ReportData, cs_times_s, cs_wide, times_s, wide
from pipeline.robots import RobotSpec

RRD_FILE = "recording.rrd"
APPLICATION_ID = "armlab_report"
ARM_RATE_HZ = 30.0

_COLUMNS = {
    "position": "position_rad",
    "error": "error_rad",
    "velocity": "velocity_rad_s",
    "effort": "effort_nm",
}


def blueprint(data: ReportData) -> rrb.Blueprint:
    """Default layout: the arm in 3D beside one tab per joint (position, error, velocity,
    effort stacked), built only from :mod:`pipeline.report.entities` paths."""
    joints: list[str] = []
    for rec in data.recordings:
        joints += [j for j in rec.joint_names if j not in joints]
    tabs = [
        rrb.Vertical(
            *[
                rrb.TimeSeriesView(
                    origin=ent.quantity_path(joint, q), name=f"{joint}: {ent.QUANTITY_LABELS[q]}"
                )
                for q in ent.QUANTITIES
            ],
            name=f"{k + 1} {joint}",
        )
        for k, joint in enumerate(joints)
    ]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin=ent.WORLD_ROOT, name="arm (FK of the recorded joints)"),
            rrb.Tabs(*tabs),
            column_shares=[2, 3],
        ),
        collapse_panels=True,
    )


def _recording_id(data: ReportData) -> str:
    # Same recordings -> same id, so re-runs open as the same recording in the viewer.
    digest = "".join(sorted(r.sha256 for r in data.recordings))
    return str(uuid.uuid5(uuid.NAMESPACE_URL, f"armlab:{digest}"))


def _send_series(
    stream: rr.RecordingStream,
    path: str,
    t: NDArray[np.float64],
    values: NDArray[np.float64],
    *,
    name: str,
    color: tuple[int, int, int],
    width: float = 1.5,
) -> None:
    stream.log(path, rr.SeriesLines(colors=[color], names=[name], widths=[width]), static=True)
    stream.send_columns(
        path,
        indexes=[rr.TimeColumn(ent.TIMELINE, duration=t)],
        columns=rr.Scalars.columns(scalars=np.ascontiguousarray(values)),
    )


def _arm_frames(
    spec: RobotSpec, q: NDArray[np.float64]
) -> tuple[list[NDArray[np.float64]], NDArray[np.float64], NDArray[np.float32]]:
    """Link segments in world (DH base) coordinates for each row of ``q``.

    Returns:
        strips: one (2, 3) array per segment, frame after frame.
        flange: (F, 3) flange positions.
        radii: radius of each strip [m].
    """
    links = chain(spec)
    segs = [(i, s) for i, link in enumerate(links) for s in link.segments_dh]
    starts = np.array([[*s.start, 1.0] for _, s in segs]).reshape(-1, 4)
    ends = np.array([[*s.end, 1.0] for _, s in segs]).reshape(-1, 4)
    owner = [i for i, _ in segs]
    radii = np.array([s.radius for _, s in segs], dtype=np.float32)
    strips: list[NDArray[np.float64]] = []
    flange = np.empty((q.shape[0], 3))
    for f, qf in enumerate(q):
        frames = link_frames(spec, qf)
        for k, i in enumerate(owner):
            a = (frames[i] @ starts[k])[:3]
            b = (frames[i] @ ends[k])[:3]
            strips.append(np.stack([a, b]))
        flange[f] = frames[-1][:3, 3]
    return strips, flange, np.tile(radii, q.shape[0])


def _send_arm(stream: rr.RecordingStream, rec: Recording, color: tuple[int, int, int]) -> bool:
    spec = robot_spec(rec)
    if spec is None or spec.joint_names != rec.joint_names:
        return False
    t = times_s(rec)
    if t.size == 0:
        return False
    wanted = np.arange(t[0], t[-1], 1.0 / ARM_RATE_HZ)
    idx = np.unique(np.append(np.searchsorted(t, wanted).clip(0, t.size - 1), t.size - 1))
    q = wide(rec, "position_rad")[idx]
    strips, flange, radii = _arm_frames(spec, q)
    per_frame = len(strips) // max(idx.size, 1)
    if per_frame == 0:
        return False
    colors = np.tile(np.array(color, dtype=np.uint8), (len(strips), 1))
    stream.send_columns(
        ent.arm_path(rec.episode),
        indexes=[rr.TimeColumn(ent.TIMELINE, duration=t[idx])],
        columns=rr.LineStrips3D.columns(strips=strips, radii=radii, colors=colors).partition(
            lengths=[per_frame] * idx.size
        ),
    )
    stream.log(
        ent.ee_path_path(rec.episode),
        rr.LineStrips3D([flange], radii=[0.004], colors=[color], labels=[rec.episode]),
        static=True,
    )
    return True


def _save(stream: rr.RecordingStream, path: Path, layout: rrb.Blueprint) -> Callable[[], None]:
    """``stream.save(path, default_blueprint=layout)`` that leaves no thread behind.

    Returns the function that closes the blueprint's own stream. rerun-sdk 0.41 logs a
    default blueprint into a hidden in-memory stream whose sink and stream hold each other:
    it is never freed, and its two threads (RecordingStream, ChunkBatcher) outlive the call,
    one pair per report. Here we build that stream ourselves, as ``save`` does, and
    disconnect it when done. Without those internals (another rerun version) we fall back to
    the public call; tests/report/test_report_threads.py notices the leak if it returns.
    """
    try:
        native = rr_bindings.new_blueprint(
            application_id=APPLICATION_ID,
            make_default=False,
            make_thread_default=False,
            default_enabled=True,
        )
        bp_stream = rr.RecordingStream._from_native(native)
        bp_stream.set_time("blueprint", sequence=0)
        layout.to_blueprint()._log_to_stream(bp_stream)
        storage = bp_stream.memory_recording().storage
        rr_bindings.save(
            path=str(path), default_blueprint=storage, recording=stream.to_native(),
            write_footer=True,
        )  # fmt: skip
    except (AttributeError, TypeError):  # pragma: no cover - another rerun-sdk
        stream.save(path, default_blueprint=layout)
        return lambda: None

    def close() -> None:
        bp_stream.flush()
        bp_stream.disconnect()

    return close


def write_rrd(data: ReportData, path: Path) -> list[str]:
    """Write the .rrd to ``path``; return the episodes whose arm could not be drawn.

    Every stream it opens is flushed, disconnected and freed before it returns, so a
    process calling it many times (a service, a notebook) does not accumulate threads.
    """
    stream = rr.RecordingStream(
        APPLICATION_ID, recording_id=_recording_id(data), send_properties=False
    )
    close_blueprint = _save(stream, path, blueprint(data))
    try:
        return _log_all(stream, data)
    finally:
        stream.flush()
        stream.disconnect()
        close_blueprint()
        del stream
        # a dropped stream's threads end only in this sweep (rerun-sdk 0.41)
        rr_bindings.flush_and_cleanup_orphaned_recordings()


def _log_all(stream: rr.RecordingStream, data: ReportData) -> list[str]:
    no_arm: list[str] = []
    for scenario in data.scenarios():
        recs = data.in_scenario(scenario)
        ref = recs[0]
        t_ref = cs_times_s(ref)
        q_ref = cs_wide(ref, "reference_position_rad")
        for j, joint in enumerate(ref.joint_names):
            _send_series(
                stream,
                ent.reference_path(joint, scenario),
                t_ref,
                q_ref[:, j],
                name=f"reference ({scenario})",
                color=(0, 0, 0),
                width=2.0,
            )
        for rec in recs:
            t = times_s(rec)
            color = data.color(rec.episode)
            label = f"{data.label(rec.episode)} [{scenario}]"
            for quantity, column in _COLUMNS.items():
                # The error at the /controller_state rate, as the metrics use it.
                full_rate = quantity == "error"
                values = cs_wide(rec, column) if full_rate else wide(rec, column)
                for j, joint in enumerate(rec.joint_names):
                    _send_series(
                        stream,
                        ent.series_path(joint, quantity, rec.episode),
                        cs_times_s(rec) if full_rate else t,
                        values[:, j],
                        name=label,
                        color=color,
                    )
            if not _send_arm(stream, rec, color):
                no_arm.append(rec.episode)
    return no_arm
