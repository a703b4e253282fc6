"""Report figures (matplotlib, Agg, no pyplot state): the paper's Figs. 5-8 plus efforts.

One set per scenario, one line per episode. Long series are thinned to at most
:data:`MAX_PLOT_POINTS` points per line for drawing only; metrics use every sample.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import (
    FuncFormatter,
    LogLocator,
    MaxNLocator,
    NullFormatter,
    NullLocator,
    ScalarFormatter,
)
from numpy.typing import NDArray

from pipeline.analysis.measure import cs_times_s, cs_wide, times_s, wide
from pipeline.log.reader import Recording
from pipeline.report.inputs import ReportData

FIGURES_DIR = "figures"
MAX_PLOT_POINTS = 4000
DPI = 100
# Figures are drawn for at most this many scenarios (the report says which are left out).
MAX_FIGURE_SCENARIOS = 6
# Joints drawn per figure (and per .rrd): a panel each; a bag of 10,000 joints would take
# hours to draw. The rest are in the CSV files and metrics.json; the caption says so.
MAX_FIGURE_JOINTS = 32


@dataclass(frozen=True)
class FigureFile:
    """A written figure: path relative to the report folder, and a caption."""

    relpath: str
    caption: str


def slug(name: str) -> str:
    """A file-name-safe form of a scenario name."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "scenario"


def scenario_slugs(names: Iterable[str]) -> dict[str, str]:
    """A distinct file-name stem per scenario name.

    :func:`slug` alone maps "a b" and "a/b" (and, on case-insensitive file systems,
    "A" and "a") to one name, so their figures would overwrite each other: names
    whose slugs collide get a short hash of the full name appended.
    """
    names = sorted(set(names))
    by_slug: dict[str, list[str]] = {}
    for name in names:
        by_slug.setdefault(slug(name).lower(), []).append(name)
    out = {}
    for name in names:
        stem = slug(name)
        if len(by_slug[stem.lower()]) > 1:
            stem = f"{stem}-{hashlib.sha256(name.encode('utf-8')).hexdigest()[:8]}"
        out[name] = stem
    return out


def _thin(t: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray[Any], NDArray[Any]]:
    step = max(1, int(np.ceil(t.size / MAX_PLOT_POINTS)))
    return t[::step], y[::step]


def _rgb(color: tuple[int, int, int]) -> tuple[float, float, float]:
    return (color[0] / 255, color[1] / 255, color[2] / 255)


# A log axis needs its positive values to span at least this ratio (a decade): under it a
# log axis shows one tick label or none, so the axis is linear.
LOG_MIN_RATIO = 10.0
# Up to this many decades a log axis labels 1, 2 and 5 of each decade, beyond it decades.
LOG_LABEL_SUBS_DECADES = 3.0
# A linear axis in rad whose values stay under this is labelled in mrad.
MRAD_BELOW_RAD = 0.1


def readable_scale(
    ax: Axes, which: Literal["x", "y"], values: NDArray[np.float64], *, log: bool, unit: str
) -> str:
    """Scale one axis so that its ticks carry labels, and return the unit they are in.

    A log axis when ``log`` and the positive ``values`` span a decade or more, labelled at
    1, 2 and 5 of each decade up to :data:`LOG_LABEL_SUBS_DECADES` decades (at the decades
    beyond), its limits the values' with a margin; otherwise linear, in mrad when ``unit``
    is rad and every value is under :data:`MRAD_BELOW_RAD` (labels like "0.25", not
    "2.5e-4" or an offset).

    Args:
        which: the axis ("x" or "y").
        values: what is drawn along it (non-finite values ignored; only positive ones
            count for a log axis).
        log: the data call for a log axis (a metric's ``log_scale``).
        unit: the values' unit, as the axis label gives it.
    """
    axis = ax.xaxis if which == "x" else ax.yaxis
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    pos = v[v > 0]
    if log and pos.size and float(pos.max()) >= LOG_MIN_RATIO * float(pos.min()):
        low, high = float(pos.min()), float(pos.max())
        (ax.set_xscale if which == "x" else ax.set_yscale)("log")
        if np.log10(high / low) > LOG_LABEL_SUBS_DECADES:
            axis.set_major_locator(LogLocator(base=10.0, numticks=8))
            axis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0), numticks=8))
        else:
            axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0), numticks=12))
            axis.set_minor_locator(NullLocator())
        # "0.002", "5e-05": plain text (mathtext labels cost most of a figure's draw)
        axis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:.3g}"))
        axis.set_minor_formatter(NullFormatter())
        (ax.set_xlim if which == "x" else ax.set_ylim)(low / 1.3, high * 1.3)
        return unit
    (ax.set_xscale if which == "x" else ax.set_yscale)("linear")
    if unit == "rad" and v.size and float(np.abs(v).max()) < MRAD_BELOW_RAD:
        axis.set_major_formatter(FuncFormatter(lambda x, _: f"{x * 1e3:.3g}"))
        return "mrad"
    plain = ScalarFormatter()
    plain.set_powerlimits((-3, 4))
    axis.set_major_formatter(plain)
    return unit


def unit_label(label: str, unit: str) -> str:
    """``label`` (``title [old unit]``) with ``unit`` in its brackets."""
    title, sep, _ = label.rpartition(" [")
    return f"{title} [{unit}]" if sep else label


def subplot_grid(n: int) -> tuple[int, int]:
    """(rows, columns) of a grid of ``n`` subplots: up to 3 columns."""
    cols = 3 if n > 4 else 2 if n > 1 else 1
    return (n + cols - 1) // cols, cols


def _single() -> tuple[Figure, Axes]:
    fig = Figure(figsize=(7.5, 3.6))
    fig.subplots_adjust(left=0.11, right=0.98, bottom=0.14, top=0.86)
    ax = fig.subplots()
    # Small errors as "x 1e-3" on the axis, so tick labels stay short.
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
    return fig, ax


def save_figure(fig: Figure, out_dir: Path, name: str) -> str:
    """Write ``fig`` as ``figures/<name>`` under ``out_dir``; return the relative path."""
    rel = f"{FIGURES_DIR}/{name}"
    (out_dir / FIGURES_DIR).mkdir(parents=True, exist_ok=True)
    # No timestamp/software metadata: re-running gives the same bytes.
    fig.savefig(out_dir / rel, dpi=DPI, metadata={"Software": None})
    return rel


def _motion_end(ax: Axes, recs: list[Recording], *, label: bool = True) -> None:
    """A dotted line at each motion end, labelled at the top of the axes."""
    ends = sorted({r.trajectory_duration_s for r in recs if r.trajectory_duration_s is not None})
    for end in ends:
        ax.axvline(end, color="0.45", lw=0.9, ls=":", zorder=0)
        if label:
            ax.annotate(
                "motion end",
                xy=(end, 1.0),
                xycoords=("data", "axes fraction"),
                xytext=(3, -3),
                textcoords="offset points",
                ha="left",
                va="top",
                fontsize=7,
                color="0.35",
            )


def _legend(fig: Figure, data: ReportData, recs: list[Recording], *, reference: bool) -> None:
    """One entry per controller (and the reference), above the axes: never on the data."""
    from matplotlib.lines import Line2D

    controllers = list(dict.fromkeys(r.controller for r in recs))
    handles = [Line2D([], [], color="k", lw=1.4, ls="--")] if reference else []
    labels = ["reference"] if reference else []
    for c in controllers:
        n = sum(1 for r in recs if r.controller == c)
        handles.append(Line2D([], [], color=_rgb(data.controller_color(c)), lw=1.6))
        labels.append(c if n == 1 else f"{c} ({n} runs)")
    fig.legend(
        handles, labels, loc="upper right", ncols=len(labels), fontsize=8, frameon=False,
        bbox_to_anchor=(0.99, 0.995),
    )  # fmt: skip


def _alpha(recs: list[Recording], controller: str) -> float:
    """Lighter lines when a controller has many runs, so seeds do not hide each other."""
    n = sum(1 for r in recs if r.controller == controller)
    return 1.0 if n <= 1 else max(0.25, 1.0 / np.sqrt(n))


# Draw |error| on a log axis when controllers' largest errors differ by more than this.
LOG_ERROR_RATIO = 30.0


def _log_error(recs: list[Recording], joint_index: int | None = None) -> bool:
    """Whether the controllers' errors are orders of magnitude apart (log |error| reads)."""
    worst: dict[str, float] = {}
    for rec in recs:
        e = np.abs(cs_wide(rec, "error_rad"))
        if joint_index is not None:
            e = e[:, joint_index : joint_index + 1]
        if e.size and np.isfinite(e).any():
            worst[rec.controller] = max(worst.get(rec.controller, 0.0), float(np.nanmax(e)))
    positive = [v for v in worst.values() if v > 0]
    return len(positive) > 1 and max(positive) / min(positive) > LOG_ERROR_RATIO


def _joint_grid_figure(
    data: ReportData,
    recs: list[Recording],
    column: str,
    ylabel: str,
    title: str,
    *,
    limits: bool = False,
    controller_state: bool = False,
) -> Figure:
    joints = recs[0].joint_names[:MAX_FIGURE_JOINTS]
    rows, cols = subplot_grid(len(joints))
    fig = Figure(figsize=(4.2 * cols, 2.6 * rows + 0.4))
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True)
    log = column == "error_rad" and _log_error(recs)
    # each recording's (times, samples x joints) once, not once per joint
    series = [
        (cs_times_s(rec), cs_wide(rec, column))
        if controller_state
        else (times_s(rec), wide(rec, column))
        for rec in recs
    ]
    for k, joint in enumerate(joints):
        ax = axes[k // cols][k % cols]
        lows: list[float] = []
        highs: list[float] = []
        smallest: list[float] = []  # the smallest positive value (log axes)
        for rec, (times, values) in zip(recs, series, strict=True):
            if joint not in rec.joint_names:
                continue
            j = rec.joint_names.index(joint)
            t, y = _thin(times, values[:, j])
            if log:
                y = np.abs(y)
            if np.isfinite(y).any():
                lows.append(float(np.nanmin(y)))
                highs.append(float(np.nanmax(y)))
                if (y > 0).any():
                    smallest.append(float(np.nanmin(y[y > 0])))
            ax.plot(
                t, y, lw=1.0, color=_rgb(data.color(rec.episode)),
                alpha=_alpha(recs, rec.controller),
            )  # fmt: skip
        if log:
            top = max(highs, default=1.0)
            if top > 0:
                # at most 6 decades: below that is integration noise, not tracking
                _log_error_axis(ax, max(top * 1e-6, min(smallest, default=top * 1e-6)), top)
            else:
                ax.set_yscale("log")
        else:
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
        if limits:
            lim = _effort_limit(data, recs[0], joint)
            if lim is not None:
                _limit_note(ax, lim, lows, highs)
        _motion_end(ax, recs, label=k == 0)
        # Plain text above the top-right corner: set_title re-measures every tick label on
        # each draw (3x slower figures).
        ax.text(
            1.0,
            1.01,
            f"joint {k + 1}: {joint}",
            transform=ax.transAxes,
            ha="right",
            va="bottom",
            fontsize=8,
        )
        ax.tick_params(labelsize=8)
        ax.grid(True, lw=0.3)
        if k % cols == 0:
            ax.set_ylabel(f"|{ylabel.split(' [')[0]}| [rad] (log)" if log else ylabel, fontsize=8)
        if k // cols == rows - 1:
            ax.set_xlabel("time [s]", fontsize=8)
    for k in range(len(joints), rows * cols):
        axes[k // cols][k % cols].set_visible(False)
    _legend(fig, data, recs, reference=False)
    fig.suptitle(title, fontsize=10, x=0.01, ha="left")
    # Fixed margins: a layout engine would draw every figure twice.
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.1, top=0.86, wspace=0.25, hspace=0.3)
    return fig


def _log_error_axis(ax: Axes, low: float, high: float) -> None:
    """A log |error| y axis from ``low`` to ``high`` [rad], at least a decade (so that two
    or more of its ticks are labelled)."""
    readable_scale(ax, "y", np.array([min(low, high / LOG_MIN_RATIO), high]), log=True, unit="rad")


def _limit_note(ax: Axes, limit: float, lows: list[float], highs: list[float]) -> None:
    """The effort limit: a dashed line when the data come near it (within 80 %), else a
    note; the axis stays scaled to the data either way."""
    peak = max([abs(v) for v in (*lows, *highs)], default=0.0)
    if peak >= 0.8 * limit:
        for sign in (1, -1):
            ax.axhline(sign * limit, color="0.3", lw=0.8, ls="--")
        text = f"limit ±{limit:g} N m (dashed)"
    else:
        text = f"limit ±{limit:g} N m ({peak / limit * 100:.0f} % used)"
    ax.text(
        0.01, 0.97, text, transform=ax.transAxes, ha="left", va="top", fontsize=7,
        color="0.3",
    )  # fmt: skip


def _effort_limit(data: ReportData, rec: Recording, joint: str) -> float | None:
    from pipeline.log.robot_facts import robot_facts

    return robot_facts(rec).effort_limits_nm.get(joint)


def _position_with_inset(data: ReportData, recs: list[Recording], scenario: str) -> Figure:
    """Paper Fig. 5: joint 1's reference and positions, with a zoomed inset where the
    tracking error is largest (at full scale the curves lie on top of each other)."""
    fig, ax = _single()
    t_ref, y_ref = _thin(cs_times_s(recs[0]), cs_wide(recs[0], "reference_position_rad")[:, 0])
    # the inset goes where the curve is not: after the motion, above a falling curve and
    # below a rising one
    falling = bool(y_ref.size and y_ref[-1] < y_ref[0])
    inset = ax.inset_axes((0.6, 0.42, 0.37, 0.42) if falling else (0.6, 0.1, 0.37, 0.42))
    for target in (ax, inset):
        target.plot(t_ref, y_ref, color="k", lw=1.4, ls="--", zorder=3)
    t_star, e_star = 0.0, -1.0
    for rec in recs:
        t, y = _thin(times_s(rec), wide(rec, "position_rad")[:, 0])
        color = _rgb(data.color(rec.episode))
        for target in (ax, inset):
            target.plot(t, y, lw=1.0, color=color, alpha=_alpha(recs, rec.controller))
        e = np.abs(cs_wide(rec, "error_rad")[:, 0])
        if e.size and np.isfinite(e).any() and float(np.nanmax(e)) > e_star:
            e_star = float(np.nanmax(e))
            t_star = float(cs_times_s(rec)[int(np.nanargmax(e))])
    centre = float(np.interp(t_star, t_ref, y_ref)) if t_ref.size else 0.0
    duration = max(float(t_ref[-1] - t_ref[0]) if t_ref.size else 1.0, 1e-6)
    slope = 0.0
    if t_ref.size > 1:
        with np.errstate(all="ignore"):  # repeated stamps (a bag with duplicates)
            slope = abs(float(np.interp(t_star, t_ref, np.gradient(y_ref, t_ref))))
        slope = slope if np.isfinite(slope) else 0.0
    # a window where the reference runs at 45 degrees and the lag is a few widths across
    pad = max(e_star, 1e-9) * 3.0
    span = min(pad / slope, duration * 0.05) if slope > 0 else duration * 0.05
    inset.set_xlim(t_star - span, t_star + span)
    inset.set_ylim(centre - pad, centre + pad)
    inset.tick_params(labelsize=6)
    inset.ticklabel_format(axis="both", style="plain", useOffset=False)
    inset.xaxis.set_major_locator(MaxNLocator(3))
    inset.yaxis.set_major_locator(MaxNLocator(3))
    inset.set_title(f"zoom: largest error ({e_star:.2g} rad)", fontsize=7)
    ax.indicate_inset_zoom(inset, edgecolor="0.4")
    _motion_end(ax, recs)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position [rad]")
    ax.grid(True, lw=0.3)
    _legend(fig, data, recs, reference=True)
    first_joint = recs[0].joint_names[0]
    fig.suptitle(f"{scenario}: joint 1 ({first_joint}) reference and actual{_cf(data, recs, '5')}",
                 fontsize=10, x=0.01, ha="left", y=0.9)  # fmt: skip
    fig.subplots_adjust(top=0.8)
    return fig


def _error_joint1(data: ReportData, recs: list[Recording], scenario: str) -> Figure:
    """Paper Fig. 6: joint 1's tracking error (|error| on a log axis when the controllers
    are orders of magnitude apart)."""
    fig, ax = _single()
    log = _log_error(recs, 0)
    drawn: list[NDArray[np.float64]] = []
    for rec in recs:
        t, y = _thin(cs_times_s(rec), cs_wide(rec, "error_rad")[:, 0])
        y = np.abs(y) if log else y
        drawn.append(y)
        ax.plot(
            t, y, lw=1.0, color=_rgb(data.color(rec.episode)),
            alpha=_alpha(recs, rec.controller),
        )  # fmt: skip
    if log:
        values = np.concatenate(drawn)
        values = values[np.isfinite(values) & (values > 0)]
        if values.size:
            top = float(values.max())
            _log_error_axis(ax, max(float(values.min()), top * 1e-6), top)
        else:
            ax.set_yscale("log")
    _motion_end(ax, recs)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("|error| [rad] (log)" if log else "error [rad]")
    ax.grid(True, lw=0.3)
    _legend(fig, data, recs, reference=False)
    fig.suptitle(f"{scenario}: joint 1 tracking error, reference - actual{_cf(data, recs, '6')}",
                 fontsize=10, x=0.01, ha="left", y=0.9)  # fmt: skip
    fig.subplots_adjust(top=0.8)
    return fig


def _tcp_errors(data: ReportData, recs: list[Recording], scenario: str) -> Figure | None:
    """The TCP position [mm] and orientation [mrad] errors per episode (None when no
    episode has a robot model)."""
    series = [(rec, data.tcp_series(rec.episode)) for rec in recs]
    series = [(rec, s) for rec, s in series if s.height]
    if not series:
        return None
    fig = Figure(figsize=(7.5, 5.2))
    axes = fig.subplots(2, 1, sharex=True)
    for ax, column, label in (
        (axes[0], "position_error_mm", "position error [mm]"),
        (axes[1], "orientation_error_mrad", "orientation error [mrad]"),
    ):
        for rec, frame in series:
            t, y = _thin(frame.get_column("time_s").to_numpy(), frame.get_column(column).to_numpy())
            ax.plot(t, y, lw=1.0, color=_rgb(data.color(rec.episode)),
                    alpha=_alpha(recs, rec.controller))  # fmt: skip
        _motion_end(ax, recs, label=ax is axes[0])
        ax.set_ylabel(label)
        ax.set_ylim(bottom=0.0)
        ax.grid(True, lw=0.3)
    axes[1].set_xlabel("time [s]")
    _legend(fig, data, recs, reference=False)
    fig.suptitle(f"{scenario}: tool centre point error, FK(reference) vs FK(true state)",
                 fontsize=10, x=0.01, ha="left", y=0.95)  # fmt: skip
    fig.subplots_adjust(left=0.11, right=0.98, bottom=0.09, top=0.88, hspace=0.12)
    return fig


def _cites_paper(data: ReportData, recs: list[Recording]) -> bool:
    """Whether the scenario is the paper's experiment (its captions cite the paper's
    figures); an external bag's never is."""
    views = [data.protocol.get(r.episode) for r in recs]
    return bool(views) and all(
        v is not None and v.settings is not None and v.settings.protocol.reproduces_paper
        for v in views
    )


def _cf(data: ReportData, recs: list[Recording], fig: str) -> str:
    """`` (cf. paper Fig. N)`` in a title of the paper's experiment, else nothing."""
    return f" (cf. paper Fig. {fig})" if _cites_paper(data, recs) else ""


def scenario_figures(
    data: ReportData, scenario: str, out_dir: Path, *, stem: str | None = None
) -> list[FigureFile]:
    """Draw and write the figure set of one scenario; return what was written.

    Errors and the reference are drawn from ``/controller_state`` (its full rate),
    measured positions, velocities and efforts from ``/joint_states``. One colour per
    controller (:mod:`pipeline.report.colors`); legends above the axes.

    Args:
        stem: file-name stem (default :func:`slug` of the scenario; pass the one from
            :func:`scenario_slugs` when drawing several scenarios).
    """
    recs = data.in_scenario(scenario)
    stem = stem or slug(scenario)
    paper = _cites_paper(data, recs)

    def cite(text: str, fig: str) -> str:
        return f"{text} (paper Fig. {fig})" if paper else text

    out = [
        FigureFile(
            save_figure(
                _position_with_inset(data, recs, scenario),
                out_dir,
                f"{stem}_fig5_joint1_position.png",
            ),
            cite(
                "Joint 1: reference and actual position per controller, with a zoom where the "
                "error is largest",
                "5",
            ),
        ),
        FigureFile(
            save_figure(
                _error_joint1(data, recs, scenario), out_dir, f"{stem}_fig6_joint1_error.png"
            ),
            cite("Joint 1: tracking error per controller", "6"),
        ),
    ]
    panels = (
        (
            "error_rad",
            "error [rad]",
            f"tracking error of every joint{_cf(data, recs, '7')}",
            "fig7_errors",
            cite("Tracking error of every joint", "7"),
            False,
        ),
        (
            "velocity_rad_s",
            "velocity [rad/s]",
            f"measured joint velocities{_cf(data, recs, '8')}",
            "fig8_velocities",
            cite("Measured joint velocities", "8"),
            False,
        ),
        (
            "effort_nm",
            "effort [N m]",
            "applied joint efforts (scaled to the data; limits noted)",
            "efforts",
            "Applied joint efforts, scaled to the data, with each joint's effort limit noted "
            "(dashed where the data come near it)",
            True,
        ),
    )
    n = len(recs[0].joint_names)
    cut = (
        f" (the first {MAX_FIGURE_JOINTS} of {n:,} joints; all are in the CSV files)"
        if n > MAX_FIGURE_JOINTS
        else ""
    )
    for column, ylabel, title, name, caption, limits in panels:
        fig = _joint_grid_figure(
            data,
            recs,
            column,
            ylabel,
            f"{scenario}: {title}{cut}",
            limits=limits,
            controller_state=column == "error_rad",
        )
        caption += cut
        out.append(FigureFile(save_figure(fig, out_dir, f"{stem}_{name}.png"), caption))
    tcp = _tcp_errors(data, recs, scenario)
    if tcp is not None:
        out.append(
            FigureFile(
                save_figure(tcp, out_dir, f"{stem}_tcp_errors.png"),
                "Tool centre point: position and orientation error per controller "
                "(FK of the reference against FK of the true state, measured where not recorded)",
            )
        )
    return out
