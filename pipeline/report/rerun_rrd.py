"""reports/recording.rrd: per-joint time series and the arm in 3D, with a default blueprint.

Bounded whatever N is: the episodes shown one by one are :meth:`ReportData.sample_roles`
(every episode of a small group; the median and the worst per controller and condition
otherwise), each labelled with its role, plus the error's 5/50/95 % percentile band over
every episode of a large group. Colours are per controller (:mod:`pipeline.report.colors`),
the reference is light grey (visible on the viewer's dark theme), legends are hidden in
the plots and given once as a text panel.

The 3D scene (:mod:`pipeline.report.rrd_scene`) draws each episode's arm from the robot's
geometry, posed by forward kinematics of its recorded joints, on its own base: a group's
episodes side by side in rows, and the 3D view's camera frames them all; with no robot
model in any bag there is no 3D view. Errors are plotted in mrad, and the error, effort
and TCP views get a y range with readable ticks (:func:`readable_range`). The colour key
is plain Markdown with the colours named. Series are sent as whole columns
(``send_columns``). Nothing is spawned or
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

from pipeline.analysis.measure import cs_times_s, cs_wide, times_s, wide
from pipeline.log.reader import Recording
from pipeline.report import entities as ent
from pipeline.report import rrd_scene as scene
from pipeline.report.colors import REFERENCE_RGB, color_name, hex_color
from pipeline.report.figures import MAX_FIGURE_JOINTS
from pipeline.report.inputs import ReportData

RRD_FILE = "recording.rrd"
APPLICATION_ID = "armlab_report"
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
    digest = "".join(sorted(r.sha256 or r.episode for r in data.recordings))  # no bag: key
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
    layout_bp = blueprint(data, eye=scene.eye(corners) if arms else None, ranges=_ranges(series))
    stream = rr.RecordingStream(
        APPLICATION_ID, recording_id=_recording_id(data), send_properties=False
    )
    close_blueprint = _save(stream, path, layout_bp)
    try:
        for s in series:
            _send_series(stream, s.path, s.t, s.values, name=s.name, color=s.color,
                         width=s.width)  # fmt: skip
        for arm in arms:
            scene.send_arm(stream, arm)
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
) -> tuple[list[_Series], list[scene.Arm], list[str]]:
    """Everything the .rrd draws: the series, the arms, and the episodes without an arm."""
    series: list[_Series] = []
    arms: list[scene.Arm] = []
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
            column = k % scene.ROW_LENGTH
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
            arm = scene.make_arm(
                rec,
                color,
                offset=scene.offset(row, column),
                label=_arm_label(rec, role),
                # alternate label heights, so neighbours' labels do not overlap
                label_z_m=-0.08 - scene.LABEL_STAGGER_M * (column % 2),
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
