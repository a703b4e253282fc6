"""reports/recording.rrd: per-joint time series and the arm in 3D, with a default blueprint.

Bounded whatever N is: the episodes shown one by one are :meth:`ReportData.sample_roles`
(every episode of a small group; the median and the worst per controller and condition
otherwise), each labelled with its role, plus the error's 5/50/95 % percentile band over
every episode of a large group. Colours are per controller (:mod:`pipeline.report.colors`),
the reference is light grey (visible on the viewer's dark theme), legends are hidden in
the plots and given once as a text panel.

The arm is drawn from the robot's geometry (the capsules of :func:`pipeline.model.chain.chain`,
as in the MJCF) posed by forward kinematics of the recorded joint positions at
:data:`ARM_RATE_HZ`; each episode stands on its own base, a group's side by side in one
row, and the 3D view's camera frames them all; with no robot model in any bag there is no
3D view. Errors are plotted in mrad, and the error, effort and TCP views get a y range
with readable ticks (:func:`readable_range`). The colour key is plain Markdown with the
colours named. Series are sent as whole columns (``send_columns``). Nothing is spawned or
served: the stream goes to a file sink only.
"""

from __future__ import annotations

import errno
import os
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
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
from pipeline.report.colors import REFERENCE_RGB, color_name, hex_color
from pipeline.report.figures import MAX_FIGURE_JOINTS
from pipeline.report.inputs import ReportData, cs_times_s, cs_wide, times_s, wide
from pipeline.robots import RobotSpec

RRD_FILE = "recording.rrd"
APPLICATION_ID = "armlab_report"
ARM_RATE_HZ = 30.0
# Episodes stand this far apart in the 3D view [m] (a UR5 reaches ~0.85 m).
SPACING_M = 1.6
# A group's episodes stand in rows of at most this many (a narrow 3D panel fits a squarish
# block of arms better than one long row).
ROW_LENGTH = 3
# Every other episode's label sits this much lower [m], so neighbours' labels stay apart.
LABEL_STAGGER_M = 0.3
# The 3D camera looks at the arms from this side (x right, -y front, z up) ...
VIEW_DIRECTION = (0.2, -1.0, 0.55)
# ... and fits them within this angle of its axis [deg] (Rerun's default field of view is
# 55 deg high; a narrow panel sees less across, hence the margin) ...
VIEW_HALF_ANGLE_DEG = 22.0
# ... with this much room around them.
FRAME_MARGIN = 1.05
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
    data: ReportData,
    *,
    eye: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    ranges: dict[str, tuple[float, float]] | None = None,
) -> rrb.Blueprint:
    """Default layout: the arms in 3D (camera at ``eye`` = (position, target); no 3D view
    when ``eye`` is None: no arm to draw) and the colour key, beside one tab per joint
    (position, error, velocity, effort stacked), built only from
    :mod:`pipeline.report.entities` paths. ``ranges``: a view origin's y range (a few
    readable ticks, :func:`readable_range`)."""
    ranges = ranges or {}
    state = _state(data)

    def plot(origin: str, title: str) -> rrb.TimeSeriesView:
        y = ranges.get(origin)
        return rrb.TimeSeriesView(
            origin=origin,
            name=title,
            plot_legend=rrb.PlotLegend(visible=False),
            axis_y=rrb.ScalarAxis(range=y) if y is not None else None,
        )

    tabs = [
        rrb.Vertical(
            *[
                plot(
                    ent.quantity_path(joint, q),
                    f"{joint}: {ent.QUANTITY_LABELS[q].format(state=state)}",
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
                    plot(ent.tcp_quantity_path(q), label.format(state=state))
                    for q, label in ent.TCP_QUANTITIES.items()
                ],
                name="TCP",
            )
        )
    key = rrb.TextDocumentView(origin=ent.LEGEND, name="colour key")
    if eye is None:  # no robot model in any bag: no empty 3D panel
        return rrb.Blueprint(
            rrb.Vertical(rrb.Tabs(*tabs), key, row_shares=[6, 1]), collapse_panels=True
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
                key,
                row_shares=[4, 1],
            ),
            rrb.Tabs(*tabs),
            column_shares=[2, 3],
        ),
        collapse_panels=True,
    )


def _state(data: ReportData) -> str:
    """The state the plotted errors, positions and velocities are of (the metrics')."""
    sources = {
        data.protocol[r.episode].error_source for r in data.sample() if r.episode in data.protocol
    }
    return ent.state_words(sources)


# A y range reaches this share of itself beyond its end ticks.
RANGE_PAD = 0.06


def readable_range(lo: float, hi: float, *, max_steps: int = 3) -> tuple[float, float]:
    """A y range holding [lo, hi] whose ends are multiples of a power of ten, at most
    ``max_steps`` of it apart: Rerun ticks powers of ten only, and labels them only when
    they are far enough apart, so a series spanning six steps of 0.1 gets the one tick "0"
    (issue 20); this range gets two to four labelled ticks, :data:`RANGE_PAD` inside
    its ends."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return (-1.0, 1.0)
    if hi - lo <= 0:
        pad = 10.0 ** np.floor(np.log10(abs(lo))) if lo else 1.0
        lo, hi = lo - pad, hi + pad
    step = 10.0 ** np.floor(np.log10(hi - lo))
    while True:
        a, b = np.floor(lo / step + 1e-9) * step, np.ceil(hi / step - 1e-9) * step
        if round((b - a) / step) <= max_steps:
            pad = RANGE_PAD * (b - a)  # ticks at the very ends are cut off
            return (float(a - pad), float(b + pad))
        step *= 10.0


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
    """Link capsules in world (DH base) coordinates for each row of ``q``.

    Returns:
        translations (F*S, 3), quaternions (F*S, 4), lengths (F*S,), radii (F*S,) and the
        flange positions (F, 3); S segments per frame.
    """
    links = chain(spec)
    segs = [
        (i, s)
        for i, link in enumerate(links)
        for s in link.segments_dh
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


@dataclass(frozen=True)
class _Series:
    """One series to send, and the view (origin) it is drawn in."""

    path: str
    view: str
    t: NDArray[np.float64]
    values: NDArray[np.float64]
    name: str
    color: tuple[int, int, int]
    width: float = 1.5


@dataclass(frozen=True)
class _Arm:
    """An episode's arm, posed at :data:`ARM_RATE_HZ`, on its own base."""

    episode: str
    offset: NDArray[np.float64]
    label: str
    label_z_m: float
    color: tuple[int, int, int]
    t: NDArray[np.float64]
    translations: NDArray[np.float64]
    quaternions: NDArray[np.float64]
    lengths: NDArray[np.float64]
    radii: NDArray[np.float32]
    flange: NDArray[np.float64]

    def corners(self) -> list[NDArray[np.float64]]:
        """Two corners of a box around everything drawn for it, in world coordinates."""
        pts = np.vstack([self.translations, self.flange, [[0.0, 0.0, self.label_z_m]]])
        pad = float(self.radii.max()) if self.radii.size else 0.0
        return [pts.min(axis=0) - pad + self.offset, pts.max(axis=0) + pad + self.offset]


def _arm(
    rec: Recording,
    color: tuple[int, int, int],
    *,
    offset: NDArray[np.float64],
    label: str,
    label_z_m: float,
) -> _Arm | None:
    """The episode's arm (None: no robot spec or no samples)."""
    spec = robot_spec(rec)
    if spec is None or spec.joint_names != rec.joint_names:
        return None
    t = times_s(rec)
    if t.size == 0:
        return None
    wanted = np.arange(t[0], t[-1], 1.0 / ARM_RATE_HZ)
    idx = np.unique(np.append(np.searchsorted(t, wanted).clip(0, t.size - 1), t.size - 1))
    q = wide(rec, "position_rad")[idx]
    if not np.isfinite(q).all():
        q = np.nan_to_num(q)
    trans, quats, lengths, radii, flange = _arm_capsules(spec, q)
    if lengths.size // max(idx.size, 1) == 0:
        return None
    return _Arm(rec.episode, offset, label, label_z_m, color, t[idx], trans, quats, lengths,
                radii, flange)  # fmt: skip


def _send_arm(stream: rr.RecordingStream, arm: _Arm) -> None:
    """Draw the episode's arm on its own base, with its flange path and its label."""
    root = ent.episode_root(arm.episode)
    stream.log(root, rr.Transform3D(translation=arm.offset.tolist()), static=True)
    per_frame = arm.lengths.size // arm.t.size
    stream.send_columns(
        ent.arm_path(arm.episode),
        indexes=[rr.TimeColumn(ent.TIMELINE, duration=arm.t)],
        columns=rr.Capsules3D.columns(
            translations=arm.translations,
            quaternions=arm.quaternions,
            lengths=arm.lengths,
            radii=arm.radii,
            colors=np.tile(np.array(arm.color, dtype=np.uint8), (arm.lengths.size, 1)),
        ).partition(lengths=[per_frame] * arm.t.size),
    )
    stream.log(
        ent.ee_path_path(arm.episode),
        rr.LineStrips3D([arm.flange], radii=[0.004], colors=[arm.color]),
        static=True,
    )
    stream.log(
        ent.label_path(arm.episode),
        rr.Points3D(
            [[0.0, 0.0, arm.label_z_m]], radii=[0.02], colors=[arm.color], labels=[arm.label]
        ),
        static=True,
    )


def _tcp_series(
    data: ReportData, rec: Recording, color: tuple[int, int, int], *, label: str
) -> list[_Series]:
    """The TCP errors as series (none without a robot model)."""
    errors = data.tcp_series(rec.episode)
    if not errors.height:
        return []
    t = errors.get_column("time_s").to_numpy()
    return [
        _Series(
            ent.tcp_series_path(quantity, rec.episode),
            ent.tcp_quantity_path(quantity),
            t,
            errors.get_column(quantity).to_numpy(),
            label,
            color,
        )
        for quantity in ent.TCP_QUANTITIES
    ]


def _send_tcp_path(
    stream: rr.RecordingStream, data: ReportData, rec: Recording, color: tuple[int, int, int]
) -> None:
    """The TCP's path in 3D (nothing without a robot model)."""
    _, path_m = data.tcp_path_m(rec.episode)
    if path_m.shape[0]:
        step = max(1, path_m.shape[0] // 2000)
        stream.log(
            ent.tcp_path_path(rec.episode),
            rr.LineStrips3D([path_m[::step]], radii=[0.003], colors=[color]),
            static=True,
        )


def _band_series(data: ReportData, group: str) -> list[_Series]:
    """5/50/95 % of the error over every episode of a large (group, controller)."""
    by_ctrl: dict[str, list[Recording]] = {}
    for rec in data.in_group(group):
        if rec.status == "ok" and not rec.salvaged:  # a cut series would cut every band
            by_ctrl.setdefault(rec.controller, []).append(rec)
    out: list[_Series] = []
    scale = ent.QUANTITY_SCALES.get("error", 1.0)
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
                out.append(
                    _Series(
                        ent.band_path(joint, group, ctrl, name),
                        ent.quantity_path(joint, "error"),
                        t,
                        values[:, j] * scale,
                        f"{ctrl} {name} of {len(recs)} [{group}]",
                        color,
                        2.5 if name == "p50" else 0.6,
                    )
                )
    return out


def _legend(data: ReportData, *, arms: bool) -> str:
    """The colour key: plain Markdown (Rerun's text view renders no HTML), colours named."""
    rows = [f"- reference: {color_name(REFERENCE_RGB)} ({hex_color(REFERENCE_RGB)})"]
    for ctrl in data.controllers():
        rgb = data.controller_color(ctrl)
        rows.append(f"- **{ctrl}**: {color_name(rgb)} ({hex_color(rgb)})")
    where = (
        "Each episode stands on its own base (a scenario or condition starts a row), labelled "
        "`episode (role)`. "
        if arms
        else "No bag holds a robot model, so no arm is drawn. "
    )
    return (
        "Colours: one per controller, in every plot"
        + (" and arm" if arms else "")
        + ".\n\n"
        + "\n".join(rows)
        + f"\n\nErrors are reference − {_state(data)}, in mrad. "
        + where
        + "Role *median* / *worst* (by max |error|) for large groups, whose error is also "
        "drawn as thin 5 % / 95 % and thick 50 % percentile lines (`band_*`). Hide an "
        "episode in the blueprint panel to compare others."
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


def _offset(row: int, column: int) -> NDArray[np.float64]:
    """An episode's base: rows :data:`SPACING_M` apart, front to back, and so are the
    episodes in a row."""
    return np.array([column * SPACING_M, -row * SPACING_M, 0.0])


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
    series, arms, no_arm = _plan(data, layout)
    corners = [c for arm in arms for c in arm.corners()]
    layout_bp = blueprint(data, eye=_eye(corners) if arms else None, ranges=_ranges(series))
    stream = rr.RecordingStream(
        APPLICATION_ID, recording_id=_recording_id(data), send_properties=False
    )
    close_blueprint = _save(stream, path, layout_bp)
    try:
        for s in series:
            _send_series(stream, s.path, s.t, s.values, name=s.name, color=s.color,
                         width=s.width)  # fmt: skip
        for arm in arms:
            _send_arm(stream, arm)
        for _, recs in layout:
            for rec in recs:
                _send_tcp_path(stream, data, rec, data.color(rec.episode))
        stream.log(
            ent.LEGEND,
            rr.TextDocument(_legend(data, arms=bool(arms)), media_type="text/markdown"),
            static=True,
        )
        return no_arm
    finally:
        stream.flush(timeout_sec=FLUSH_TIMEOUT_S)
        stream.disconnect()
        close_blueprint()
        del stream
        # a dropped stream's threads end only in this sweep (rerun-sdk 0.41)
        rr_bindings.flush_and_cleanup_orphaned_recordings()


# Views whose y range is set (:func:`readable_range`): the errors and efforts, whose
# auto range often gets a single tick; positions and velocities span whole decades.
_RANGED = ("error", "effort")
# ... of these, the ones whose range holds 0 (an error axis is read against 0)
_FROM_ZERO = ("error",)


def _ranges(series: list[_Series]) -> dict[str, tuple[float, float]]:
    """Each ranged view's y range, from every series drawn in it."""
    tcp = {ent.tcp_quantity_path(q) for q in ent.TCP_QUANTITIES}
    lows: dict[str, float] = {}
    highs: dict[str, float] = {}
    for s in series:
        if s.view not in tcp and s.view.rsplit("/", 1)[-1] not in _RANGED:
            continue
        finite = s.values[np.isfinite(s.values)]
        if finite.size:
            lows[s.view] = min(lows.get(s.view, np.inf), float(finite.min()))
            highs[s.view] = max(highs.get(s.view, -np.inf), float(finite.max()))
    out = {}
    for view, lo in lows.items():
        hi = highs[view]
        if view in tcp or view.rsplit("/", 1)[-1] in _FROM_ZERO:
            lo, hi = min(lo, 0.0), max(hi, 0.0)
        out[view] = readable_range(lo, hi)
    return out


def _plan(
    data: ReportData, layout: list[tuple[str, list[Recording]]]
) -> tuple[list[_Series], list[_Arm], list[str]]:
    """Everything the .rrd draws: the series, the arms, and the episodes without an arm."""
    series: list[_Series] = []
    arms: list[_Arm] = []
    no_arm: list[str] = []
    roles = data.sample_roles
    row = -1
    for group, recs in layout:
        ref = recs[0]
        t_ref = cs_times_s(ref)
        q_ref = cs_wide(ref, "reference_position_rad")
        for j, joint in enumerate(_drawn(ref.joint_names)):
            series.append(
                _Series(
                    ent.reference_path(joint, group),
                    ent.quantity_path(joint, "position"),
                    t_ref,
                    q_ref[:, j],
                    f"reference ({group})",
                    REFERENCE_RGB,
                    2.0,
                )
            )
        series += _band_series(data, group)
        for k, rec in enumerate(recs):
            column = k % ROW_LENGTH
            if column == 0:  # each group starts a row
                row += 1
            t = times_s(rec)
            color = data.color(rec.episode)
            role = roles.get(rec.episode, "")
            who = f"{rec.controller}{f' ({role})' if role else ''}"
            if rec.salvaged:  # read up to the damage of its file
                who += " (salvaged)"
            label = f"{who} {rec.episode} [{group}]"
            for quantity, column_name in _COLUMNS.items():
                # The error at the /controller_state rate, as the metrics use it.
                full_rate = quantity == "error"
                values = cs_wide(rec, column_name) if full_rate else wide(rec, column_name)
                values = values * ent.QUANTITY_SCALES.get(quantity, 1.0)
                for j, joint in enumerate(_drawn(rec.joint_names)):
                    series.append(
                        _Series(
                            ent.series_path(joint, quantity, rec.episode),
                            ent.quantity_path(joint, quantity),
                            cs_times_s(rec) if full_rate else t,
                            values[:, j],
                            label,
                            color,
                        )
                    )
            series += _tcp_series(data, rec, color, label=label)
            arm = _arm(
                rec,
                color,
                offset=_offset(row, column),
                label=_arm_label(rec, role),
                # alternate label heights, so neighbours' labels do not overlap
                label_z_m=-0.08 - LABEL_STAGGER_M * (column % 2),
            )
            if arm is None:
                no_arm.append(rec.episode)
            else:
                arms.append(arm)
    return series, arms, no_arm


def _arm_label(rec: Recording, role: str) -> str:
    """``episode (role)``; the controller too when the episode's name does not hold it."""
    name = rec.episode if rec.controller in rec.episode else f"{rec.episode}: {rec.controller}"
    extra = [x for x in (role, "salvaged" if rec.salvaged else "") if x]
    return f"{name} ({', '.join(extra)})" if extra else name


def _eye(points: list[NDArray[np.float64]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A camera that frames every arm (``points``: corners of what is drawn): looking at
    the centre of their box from the front-right and above (:data:`VIEW_DIRECTION`), just
    far enough for every corner of the box to be inside :data:`VIEW_HALF_ANGLE_DEG` of
    the view's axis, sideways and up-down."""
    if not points:
        return np.array([2.0, -2.0, 1.5]), np.zeros(3)
    allp = np.vstack(points)
    low, high = allp.min(axis=0), allp.max(axis=0)
    centre = (low + high) / 2
    back = np.asarray(VIEW_DIRECTION, dtype=np.float64)
    back /= np.linalg.norm(back)  # from the target towards the camera
    right = np.cross(back, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, back)
    tan = np.tan(np.radians(VIEW_HALF_ANGLE_DEG))
    box = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                    for z in (low[2], high[2])]) - centre  # fmt: skip
    # a corner p is in view from distance D when max(|p.right|, |p.up|) <= (D - p.back) tan
    need = box @ back + np.maximum(np.abs(box @ right), np.abs(box @ up)) / tan
    distance = max(float(need.max()) * FRAME_MARGIN, 0.5)
    return centre + back * distance, centre
