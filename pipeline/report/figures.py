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
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from pipeline.log.reader import Recording
from pipeline.report.inputs import ReportData, cs_times_s, cs_wide, times_s, wide

FIGURES_DIR = "figures"
MAX_PLOT_POINTS = 4000
DPI = 100
# Figures are drawn for at most this many scenarios (the report says which are left out).
MAX_FIGURE_SCENARIOS = 6


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


def _grid(n: int) -> tuple[int, int]:
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


def _motion_end(ax: Axes, recs: list[Recording]) -> None:
    ends = {r.motion_end_s for r in recs if r.motion_end_s is not None}
    for end in sorted(ends):
        ax.axvline(end, color="0.6", lw=0.8, ls=":", zorder=0)


def _per_joint(
    data: ReportData,
    recs: list[Recording],
    column: str,
    ylabel: str,
    title: str,
    *,
    limits: bool = False,
    controller_state: bool = False,
) -> Figure:
    joints = recs[0].joint_names
    rows, cols = _grid(len(joints))
    fig = Figure(figsize=(4.2 * cols, 2.6 * rows))
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True)
    for k, joint in enumerate(joints):
        ax = axes[k // cols][k % cols]
        for rec in recs:
            if joint not in rec.joint_names:
                continue
            j = rec.joint_names.index(joint)
            if controller_state:
                t, y = _thin(cs_times_s(rec), cs_wide(rec, column)[:, j])
            else:
                t, y = _thin(times_s(rec), wide(rec, column)[:, j])
            ax.plot(
                t, y, lw=1.0, color=_rgb(data.color(rec.episode)), label=data.label(rec.episode)
            )
        if limits:
            lim = _effort_limit(data, recs[0], joint)
            if lim is not None:
                for sign in (1, -1):
                    ax.axhline(sign * lim, color="0.3", lw=0.8, ls="--")
        _motion_end(ax, recs)
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
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
            ax.set_ylabel(ylabel, fontsize=8)
        if k // cols == rows - 1:
            ax.set_xlabel("time [s]", fontsize=8)
    for k in range(len(joints), rows * cols):
        axes[k // cols][k % cols].set_visible(False)
    axes[0][0].legend(fontsize=7, loc="lower right")
    fig.suptitle(title, fontsize=10)
    # Fixed margins: a layout engine would draw every figure twice.
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.1, top=0.89, wspace=0.25, hspace=0.3)
    return fig


def _effort_limit(data: ReportData, rec: Recording, joint: str) -> float | None:
    from pipeline.analysis.episodes import effort_limits, robot_spec

    return effort_limits(rec, robot_spec(rec)).get(joint)


def scenario_figures(
    data: ReportData, scenario: str, out_dir: Path, *, stem: str | None = None
) -> list[FigureFile]:
    """Draw and write the figure set of one scenario; return what was written.

    Errors and the reference are drawn from ``/controller_state`` (its full rate),
    measured positions, velocities and efforts from ``/joint_states``.

    Args:
        stem: file-name stem (default :func:`slug` of the scenario; pass the one from
            :func:`scenario_slugs` when drawing several scenarios).
    """
    recs = data.in_scenario(scenario)
    stem = stem or slug(scenario)
    first_joint = recs[0].joint_names[0]
    out: list[FigureFile] = []

    # Fig. 5: joint 1 reference vs each controller.
    fig, ax = _single()
    t_ref, y_ref = _thin(cs_times_s(recs[0]), cs_wide(recs[0], "reference_position_rad")[:, 0])
    ax.plot(t_ref, y_ref, color="k", lw=1.4, ls="--", label="reference")
    for rec in recs:
        t, y = _thin(times_s(rec), wide(rec, "position_rad")[:, 0])
        ax.plot(t, y, lw=1.0, color=_rgb(data.color(rec.episode)), label=data.label(rec.episode))
    _motion_end(ax, recs)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position [rad]")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8)
    fig.suptitle(f"{scenario}: joint 1 ({first_joint}) reference and actual (cf. paper Fig. 5)")
    out.append(
        FigureFile(
            save_figure(fig, out_dir, f"{stem}_fig5_joint1_position.png"),
            "Joint 1: reference and measured position per controller (paper Fig. 5)",
        )
    )

    # Fig. 6: joint 1 error.
    fig, ax = _single()
    for rec in recs:
        t, y = _thin(cs_times_s(rec), cs_wide(rec, "error_rad")[:, 0])
        ax.plot(t, y, lw=1.0, color=_rgb(data.color(rec.episode)), label=data.label(rec.episode))
    _motion_end(ax, recs)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("error [rad]")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8)
    fig.suptitle(f"{scenario}: joint 1 tracking error, reference - actual (cf. paper Fig. 6)")
    out.append(
        FigureFile(
            save_figure(fig, out_dir, f"{stem}_fig6_joint1_error.png"),
            "Joint 1: tracking error per controller (paper Fig. 6)",
        )
    )

    panels = (
        (
            "error_rad",
            "error [rad]",
            "tracking error of every joint (cf. paper Fig. 7)",
            "fig7_errors",
            "Tracking error of every joint (paper Fig. 7)",
            False,
        ),
        (
            "velocity_rad_s",
            "velocity [rad/s]",
            "measured joint velocities (cf. paper Fig. 8)",
            "fig8_velocities",
            "Measured joint velocities (paper Fig. 8)",
            False,
        ),
        (
            "effort_nm",
            "effort [N m]",
            "applied joint efforts (dashed: effort limits)",
            "efforts",
            "Applied joint efforts, with the effort limits dashed",
            True,
        ),
    )
    for column, ylabel, title, name, caption, limits in panels:
        fig = _per_joint(
            data,
            recs,
            column,
            ylabel,
            f"{scenario}: {title}",
            limits=limits,
            controller_state=column == "error_rad",
        )
        out.append(FigureFile(save_figure(fig, out_dir, f"{stem}_{name}.png"), caption))
    return out
