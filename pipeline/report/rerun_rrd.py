"""reports/recording.rrd: per-joint time series and the arm in 3D, with a default blueprint.

Bounded whatever N is: the episodes shown one by one are :meth:`ReportData.sample_roles`
(every episode of a small group; the median and the worst per controller and condition
otherwise), each labelled with its role, plus the error's 5/50/95 % percentile band over
every episode of a large group. Colours are per controller (:mod:`pipeline.report.colors`),
the reference is light grey (visible on the viewer's dark theme), legends are hidden in
the plots and given once as a text panel.

The arm is drawn from the robot's geometry (the capsules of :func:`pipeline.model.chain.chain`,
as in the MJCF) posed by forward kinematics of the recorded joint positions at
:data:`ARM_RATE_HZ`; each episode stands on its own base, side by side, and the 3D view's
camera frames them all. Series are sent as whole columns (``send_columns``). Nothing is
spawned or served: the stream goes to a file sink only.
"""

from __future__ import annotations

import errno
import os
import threading
import time
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
from pipeline.report.colors import REFERENCE_RGB, hex_color
from pipeline.report.figures import MAX_FIGURE_JOINTS
from pipeline.report.inputs import ReportData, cs_times_s, cs_wide, times_s, wide
from pipeline.robots import RobotSpec

RRD_FILE = "recording.rrd"
APPLICATION_ID = "armlab_report"
ARM_RATE_HZ = 30.0
# Episodes stand this far apart in the 3D view [m] (a UR5 reaches ~0.85 m).
SPACING_M = 1.6
# Groups (scenarios, campaign conditions) drawn; the rest are in the CSV/Parquet files.
MAX_RRD_GROUPS = 12
BAND_LEVELS = (("p05", 5.0), ("p50", 50.0), ("p95", 95.0))

# The writer runs in a thread the caller waits on (so Ctrl-C and SIGTERM are handled while it
# writes) and is abandoned, with one line, when the disk has been full this long [s] ...
DISK_FULL_GRACE_S = 3.0
# ... or when the file has not grown for this long [s] (a stuck sink; logging sends data
# every few milliseconds, so a working writer never pauses nearly this long)
STALL_S = 120.0
# how long a flush may wait for the file sink [s] (rerun waits forever by default)
FLUSH_TIMEOUT_S = 60.0

_COLUMNS = {
    "position": "position_rad",
    "error": "error_rad",
    "velocity": "velocity_rad_s",
    "effort": "effort_nm",
}


def _joints(data: ReportData) -> list[str]:
    """The joints drawn (at most :data:`MAX_FIGURE_JOINTS`, as in the figures)."""
    joints: list[str] = []
    for rec in data.sample():
        joints += [j for j in _drawn(rec.joint_names) if j not in joints]
    return joints[:MAX_FIGURE_JOINTS]


def _drawn(names: tuple[str, ...]) -> tuple[str, ...]:
    return names[:MAX_FIGURE_JOINTS]


def blueprint(
    data: ReportData, *, eye: tuple[NDArray[np.float64], NDArray[np.float64]]
) -> rrb.Blueprint:
    """Default layout: the arms in 3D (camera at ``eye`` = (position, target)) and the colour
    key, beside one tab per joint (position, error, velocity, effort stacked), built only
    from :mod:`pipeline.report.entities` paths."""
    tabs = [
        rrb.Vertical(
            *[
                rrb.TimeSeriesView(
                    origin=ent.quantity_path(joint, q),
                    name=f"{joint}: {ent.QUANTITY_LABELS[q]}",
                    plot_legend=rrb.PlotLegend(visible=False),
                )
                for q in ent.QUANTITIES
            ],
            name=f"{k + 1} {joint}",
        )
        for k, joint in enumerate(_joints(data))
    ]
    if data.task_space:
        tabs.append(
            rrb.Vertical(
                *[
                    rrb.TimeSeriesView(
                        origin=ent.tcp_quantity_path(q),
                        name=label,
                        plot_legend=rrb.PlotLegend(visible=False),
                    )
                    for q, label in ent.TCP_QUANTITIES.items()
                ],
                name="TCP",
            )
        )
    position, target = eye
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(
                    origin=ent.WORLD_ROOT,
                    name="arms (FK of the recorded joints), one base per episode",
                    eye_controls=rrb.EyeControls3D(
                        position=position.tolist(), look_target=target.tolist(), eye_up=[0, 0, 1]
                    ),
                ),
                rrb.TextDocumentView(origin=ent.LEGEND, name="colour key"),
                row_shares=[4, 1],
            ),
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


def _z_to(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quaternions (x, y, z, w) turning +Z onto each row of unit vectors ``v``."""
    z = np.array([0.0, 0.0, 1.0])
    q = np.concatenate([np.cross(z, v), 1.0 + v @ z[:, None]], axis=1)
    flip = q[:, 3] < 1e-9  # v = -Z: half a turn about X
    q[flip] = [1.0, 0.0, 0.0, 0.0]
    out: NDArray[np.float64] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return out


def _arm_capsules(
    spec: RobotSpec, q: NDArray[np.float64]
) -> tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float32],
    NDArray[np.float64],
]:
    """Link capsules in world (robot base) coordinates for each row of ``q``.

    Returns:
        translations (F*S, 3), quaternions (F*S, 4), lengths (F*S,), radii (F*S,) and the
        flange positions (F, 3); S segments per frame.
    """
    links = chain(spec)
    segs = [
        (i, s)
        for i, link in enumerate(links)
        for s in link.segments
        if np.linalg.norm(np.subtract(s.end, s.start)) > 1e-9
    ]
    starts = np.array([[*s.start, 1.0] for _, s in segs]).reshape(-1, 4)
    ends = np.array([[*s.end, 1.0] for _, s in segs]).reshape(-1, 4)
    owner = [i for i, _ in segs]
    radii = np.array([s.radius for _, s in segs], dtype=np.float32)
    a = np.empty((q.shape[0], len(segs), 3))
    b = np.empty_like(a)
    flange = np.empty((q.shape[0], 3))
    for f, qf in enumerate(q):
        frames = link_frames(spec, qf)
        for k, i in enumerate(owner):
            a[f, k] = (frames[i] @ starts[k])[:3]
            b[f, k] = (frames[i] @ ends[k])[:3]
        flange[f] = frames[-1][:3, 3]
    starts_w, ends_w = a.reshape(-1, 3), b.reshape(-1, 3)
    lengths = np.linalg.norm(ends_w - starts_w, axis=1)
    quats = _z_to((ends_w - starts_w) / lengths[:, None])
    return starts_w, quats, lengths, np.tile(radii, q.shape[0]), flange


def _send_arm(
    stream: rr.RecordingStream,
    rec: Recording,
    color: tuple[int, int, int],
    *,
    offset: NDArray[np.float64],
    label: str,
) -> bool:
    """Draw the episode's arm on its own base (False: no robot spec or no samples)."""
    spec = robot_spec(rec)
    if spec is None or spec.joint_names != rec.joint_names:
        return False
    t = times_s(rec)
    if t.size == 0:
        return False
    wanted = np.arange(t[0], t[-1], 1.0 / ARM_RATE_HZ)
    idx = np.unique(np.append(np.searchsorted(t, wanted).clip(0, t.size - 1), t.size - 1))
    q = wide(rec, "position_rad")[idx]
    if not np.isfinite(q).all():
        q = np.nan_to_num(q)
    trans, quats, lengths, radii, flange = _arm_capsules(spec, q)
    per_frame = lengths.size // max(idx.size, 1)
    if per_frame == 0:
        return False
    root = ent.episode_root(rec.episode)
    stream.log(root, rr.Transform3D(translation=offset.tolist()), static=True)
    stream.send_columns(
        ent.arm_path(rec.episode),
        indexes=[rr.TimeColumn(ent.TIMELINE, duration=t[idx])],
        columns=rr.Capsules3D.columns(
            translations=trans,
            quaternions=quats,
            lengths=lengths,
            radii=radii,
            colors=np.tile(np.array(color, dtype=np.uint8), (lengths.size, 1)),
        ).partition(lengths=[per_frame] * idx.size),
    )
    stream.log(
        ent.ee_path_path(rec.episode),
        rr.LineStrips3D([flange], radii=[0.004], colors=[color]),
        static=True,
    )
    stream.log(
        ent.label_path(rec.episode),
        rr.Points3D([[0.0, 0.0, -0.05]], radii=[0.02], colors=[color], labels=[label]),
        static=True,
    )
    return True


def _send_tcp(
    stream: rr.RecordingStream,
    data: ReportData,
    rec: Recording,
    color: tuple[int, int, int],
    *,
    label: str,
) -> None:
    """The TCP errors as series and the TCP's path in 3D (nothing without a robot model)."""
    errors = data.tcp_series(rec.episode)
    if not errors.height:
        return
    t = errors.get_column("time_s").to_numpy()
    for quantity in ent.TCP_QUANTITIES:
        _send_series(
            stream,
            ent.tcp_series_path(quantity, rec.episode),
            t,
            errors.get_column(quantity).to_numpy(),
            name=label,
            color=color,
        )
    _, path_m = data.tcp_path_m(rec.episode)
    if path_m.shape[0]:
        step = max(1, path_m.shape[0] // 2000)
        stream.log(
            ent.tcp_path_path(rec.episode),
            rr.LineStrips3D([path_m[::step]], radii=[0.003], colors=[color]),
            static=True,
        )


def _send_bands(stream: rr.RecordingStream, data: ReportData, group: str) -> None:
    """5/50/95 % of the error over every episode of a large (group, controller)."""
    by_ctrl: dict[str, list[Recording]] = {}
    for rec in data.in_group(group):
        if rec.status == "ok" and not rec.salvaged:  # a cut series would cut every band
            by_ctrl.setdefault(rec.controller, []).append(rec)
    for ctrl, recs in by_ctrl.items():
        if len(recs) <= 3:
            continue
        series = [data.errors(r.episode) for r in recs]
        n = min(t.size for t, _ in series)
        if n == 0:
            continue
        t = series[0][0][:n]
        stack = np.stack([e[:n] for _, e in series])  # (E, n, J)
        levels = np.nanpercentile(stack, [p for _, p in BAND_LEVELS], axis=0)
        color = data.controller_color(ctrl)
        for j, joint in enumerate(_drawn(recs[0].joint_names)):
            for (name, _), values in zip(BAND_LEVELS, levels, strict=True):
                _send_series(
                    stream,
                    ent.band_path(joint, group, ctrl, name),
                    t,
                    values[:, j],
                    name=f"{ctrl} {name} of {len(recs)} [{group}]",
                    color=color,
                    width=2.5 if name == "p50" else 0.6,
                )


def _legend(data: ReportData) -> str:
    rows = [f"- <span style='color:{hex_color(REFERENCE_RGB)}'>■</span> reference (light grey)"]
    for ctrl in data.controllers():
        rows.append(f"- **{ctrl}**: {hex_color(data.controller_color(ctrl))}")
    return (
        "Colours: one per controller, in every plot and arm.\n\n"
        + "\n".join(rows)
        + "\n\nEach episode stands on its own base, labelled `episode: controller (role)`; "
        "role *median* / *worst* (by max |error|) for large groups, whose error is also drawn "
        "as thin 5 % / 95 % and thick 50 % percentile lines (`band_*`). Hide an episode in "
        "the blueprint panel to compare others."
    )


def _layout(data: ReportData) -> list[tuple[str, list[Recording]]]:
    """(group, its sampled episodes) for the groups drawn, in order."""
    roles = data.sample_roles
    out = []
    for group in data.groups():
        recs = [r for r in data.in_group(group) if r.episode in roles]
        if recs:
            out.append((group, recs))
    return out[:MAX_RRD_GROUPS]


def _offset(k: int) -> NDArray[np.float64]:
    """The k-th episode's base: rows of six, :data:`SPACING_M` apart."""
    return np.array([(k % 6) * SPACING_M, -(k // 6) * SPACING_M, 0.0])


def _reach_m(data: ReportData) -> float:
    """How far any drawn arm reaches from its base [m] (its summed link lengths)."""
    reach = 0.0
    for rec in data.sample():
        spec = robot_spec(rec)
        if spec is not None:
            reach = max(reach, spec.reach_m())
    return reach or 1.0


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

    The writing runs in a thread this one waits on: Ctrl-C and SIGTERM are handled while
    it writes, and a writer that cannot finish is abandoned within a bound (rerun-sdk's
    file sink can block for good once the disk is full): when the file system has had no
    free space for :data:`DISK_FULL_GRACE_S`, or the file has not grown for
    :data:`STALL_S`. Rerun's exit-time flush is then skipped, so the process can end.

    Raises:
        OSError: the disk is full (``ENOSPC``), the writer stopped or stalled (``EIO``).
    """
    outcome: dict[str, object] = {}

    def run() -> None:
        try:
            outcome["value"] = _write_rrd(data, path)
        except BaseException as err:  # handed to the waiting thread
            outcome["error"] = err

    worker = threading.Thread(target=run, name="rrd-writer", daemon=True)
    worker.start()
    try:
        _wait(worker, path)
    finally:
        if worker.is_alive():  # abandoned (or interrupted): its flush at exit would block
            rr.unregister_shutdown()
    err = outcome.get("error")
    if isinstance(err, RuntimeError) and _sink_failure(err):
        raise _disk_error(path, f"the Rerun file writer stopped ({err})") from err
    if isinstance(err, BaseException):
        raise err
    value = outcome["value"]
    assert isinstance(value, list)
    return value


def _wait(worker: threading.Thread, path: Path) -> None:
    """Wait for the writer; raise OSError when it is to be abandoned."""
    full_since: float | None = None
    size, grew_at = -1, time.monotonic()
    while True:
        worker.join(0.2)
        if not worker.is_alive():
            return
        now = time.monotonic()
        if _disk_full(path.parent):
            full_since = full_since if full_since is not None else now
            if now - full_since > DISK_FULL_GRACE_S:
                raise _disk_error(path, "the Rerun file writer could not finish")
        else:
            full_since = None
        try:
            current = os.stat(path).st_size
        except OSError:
            current = -1
        if current != size:
            size, grew_at = current, now
        elif now - grew_at > STALL_S:
            raise OSError(
                errno.EIO, f"the Rerun file writer made no progress for {STALL_S:.0f} s", str(path)
            )


def _disk_full(folder: Path) -> bool:
    try:
        st = os.statvfs(folder)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize < 4096


def _sink_failure(err: RuntimeError) -> bool:
    """Whether rerun-sdk's error is its file sink failing (a full disk, an I/O error)."""
    text = str(err).lower()
    return "file-writer" in text or "flush" in text or "os error" in text


def _disk_error(path: Path, what: str) -> OSError:
    if _disk_full(path.parent):
        return OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)}; {what}", str(path))
    return OSError(errno.EIO, what, str(path))


def _write_rrd(data: ReportData, path: Path) -> list[str]:
    """:func:`write_rrd`'s work, in the calling thread (flushes wait at most
    :data:`FLUSH_TIMEOUT_S`)."""
    layout = _layout(data)
    n = sum(len(recs) for _, recs in layout)
    reach = _reach_m(data)
    corners = [_offset(k) + sign * reach for k in range(max(n, 1)) for sign in (-1.0, 1.0)]
    stream = rr.RecordingStream(
        APPLICATION_ID, recording_id=_recording_id(data), send_properties=False
    )
    close_blueprint = _save(stream, path, blueprint(data, eye=_eye(corners)))
    try:
        return _log_all(stream, data, layout)
    finally:
        stream.flush(timeout_sec=FLUSH_TIMEOUT_S)
        stream.disconnect()
        close_blueprint()
        del stream
        # a dropped stream's threads end only in this sweep (rerun-sdk 0.41)
        rr_bindings.flush_and_cleanup_orphaned_recordings()


def _log_all(
    stream: rr.RecordingStream, data: ReportData, layout: list[tuple[str, list[Recording]]]
) -> list[str]:
    no_arm: list[str] = []
    roles = data.sample_roles
    k = 0
    for group, recs in layout:
        ref = recs[0]
        t_ref = cs_times_s(ref)
        q_ref = cs_wide(ref, "reference_position_rad")
        for j, joint in enumerate(_drawn(ref.joint_names)):
            _send_series(
                stream,
                ent.reference_path(joint, group),
                t_ref,
                q_ref[:, j],
                name=f"reference ({group})",
                color=REFERENCE_RGB,
                width=2.0,
            )
        _send_bands(stream, data, group)
        for rec in recs:
            t = times_s(rec)
            color = data.color(rec.episode)
            role = roles.get(rec.episode, "")
            who = f"{rec.controller}{f' ({role})' if role else ''}"
            if rec.salvaged:  # read up to the damage of its file
                who += " (salvaged)"
            label = f"{who} {rec.episode} [{group}]"
            for quantity, column in _COLUMNS.items():
                # The error at the /controller_state rate, as the metrics use it.
                full_rate = quantity == "error"
                values = cs_wide(rec, column) if full_rate else wide(rec, column)
                for j, joint in enumerate(_drawn(rec.joint_names)):
                    _send_series(
                        stream,
                        ent.series_path(joint, quantity, rec.episode),
                        cs_times_s(rec) if full_rate else t,
                        values[:, j],
                        name=label,
                        color=color,
                    )
            _send_tcp(stream, data, rec, color, label=label)
            drawn = _send_arm(stream, rec, color, offset=_offset(k), label=f"{rec.episode}: {who}")
            k += 1
            if not drawn:
                no_arm.append(rec.episode)
    stream.log(ent.LEGEND, rr.TextDocument(_legend(data), media_type="text/markdown"), static=True)
    return no_arm


def _eye(points: list[NDArray[np.float64]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A camera that frames every arm (``points``: corners of the space they can reach):
    looking at the centre, from the front-right and above, far enough for the whole box to
    fit a ~60 deg view."""
    if not points:
        return np.array([2.0, -2.0, 1.5]), np.zeros(3)
    allp = np.vstack(points)
    low, high = allp.min(axis=0), allp.max(axis=0)
    centre = (low + high) / 2
    radius = max(float(np.linalg.norm(high - low)) / 2, 0.3)
    direction = np.array([0.6, -1.0, 0.55])
    position = centre + direction / np.linalg.norm(direction) * radius * 2.2
    return position, centre
