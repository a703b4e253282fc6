"""A campaign's summary in the report: distributions, metric vs swept parameter, win/loss.

Read from the campaign's table (``campaigns/<name>.parquet``, scanned lazily), so the
summary is the table's numbers; the size of what is written does not grow with N:
figures are fixed in number, tables list conditions (at most
:data:`MAX_CONDITIONS_SHOWN`) and the labelled sample of episodes, and everything else is
in the Parquet and CSV files beside the report.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np
import polars as pl
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from pipeline.analysis import catalog
from pipeline.analysis.campaign_tables import (
    ALPHA,
    MIN_PAIRS,
    SWEPT_PREFIX,
    TABLE_DIR,
    TOO_FEW,
    by_parameter,
    swept_axes,
    win_loss,
)
from pipeline.analysis.headline import HEADLINE_TASK_METRICS
from pipeline.analysis.verdict import EQUIVALENCE_REL, resolution_text
from pipeline.report import md
from pipeline.report.colors import controller_colors, mpl
from pipeline.report.figures import (
    FigureFile,
    readable_scale,
    save_figure,
    subplot_grid,
    unit_label,
)
from pipeline.report.flips import flip_lines

# Conditions drawn in a figure / listed in a Markdown table (all are in the CSV files).
MAX_CONDITIONS_SHOWN = 12
# Up to this many values per box the individual episodes are drawn as points too.
MAX_POINTS_PER_BOX = 40
# Figures are drawn for at most this many swept axes per campaign.
MAX_AXES_DRAWN = 4


@dataclass(frozen=True)
class CampaignSection:
    """What the report writes for one campaign.

    Attributes:
        name: the campaign.
        table_path: its Parquet table, relative to the report folder.
        lines: the Markdown section.
        files: every file written for it (figures, CSVs), relative to the report folder.
    """

    name: str
    table_path: str
    lines: tuple[str, ...]
    files: tuple[str, ...]


def _values(rows: pl.DataFrame, metric: catalog.Metric) -> NDArray[np.float64]:
    """The metric's recorded values in ``rows`` (nulls dropped; only positive ones on a
    log scale)."""
    vals = np.asarray(rows.get_column(metric.name).drop_nulls().to_numpy(), dtype=np.float64)
    return vals[vals > 0] if metric.log_scale else vals


def _concat(parts: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    return np.concatenate(parts) if parts else np.zeros(0)


def _n_range(counts: pl.Series) -> str:
    """``n = 5`` or ``n = 3-5`` (the smallest and largest of ``counts``)."""
    values = [int(c) for c in counts.to_list()] or [0]
    low, high = min(values), max(values)
    return f"n = {low}" if low == high else f"n = {low}–{high}"


def _joints(table: pl.DataFrame) -> list[str]:
    return list(dict.fromkeys(table.get_column("joint").to_list()))


def _conditions(table: pl.DataFrame) -> list[str]:
    return sorted(set(table.get_column("condition").to_list()))


def _short(condition: str) -> str:
    """A condition as a tick label: swept values without their params path
    (``plant.payload_kg=0.5,gains.kp=9`` -> ``payload_kg=0.5, kp=9``)."""
    if not condition:
        return "(all)"
    out = []
    for part in condition.split(","):
        key, sep, value = part.partition("=")
        out.append(f"{key.rsplit('.', 1)[-1]}={value}" if sep else part)
    return ", ".join(out)


def _axes(n: int, *, width: float = 4.2, height: float = 3.0) -> tuple[Figure, list[Axes]]:
    rows, cols = subplot_grid(n)
    fig = Figure(figsize=(width * cols, height * rows + 0.6))
    grid = fig.subplots(rows, cols, squeeze=False)
    axes = [grid[k // cols][k % cols] for k in range(rows * cols)]
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.14, top=0.86, wspace=0.3, hspace=0.75)
    return fig, axes[:n]


def drawing_order(controllers: Sequence[str], baseline: str) -> list[str]:
    """Controllers in the order they are drawn and listed: the baseline first (below the
    others, leftmost in a group of boxes, first in the legend), then the rest sorted."""
    names = sorted(set(controllers))
    return [baseline, *(c for c in names if c != baseline)] if baseline in names else names


def _title(ax: Axes, text: str) -> None:
    # Plain text above the axes: set_title re-measures every tick label on each draw.
    ax.text(0.5, 1.02, text, transform=ax.transAxes, ha="center", va="bottom", fontsize=8)


def _legend(fig: Figure, colors: dict[str, tuple[int, int, int]], names: Sequence[str]) -> None:
    """Controllers' colours above the panels: never on the data."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=mpl(colors[c]), lw=2) for c in names]
    fig.legend(handles, list(names), loc="upper right", ncols=len(names), fontsize=8, frameon=False)


def distribution_figure(
    table: pl.DataFrame,
    metric: catalog.Metric,
    conditions: list[str],
    colors: dict[str, tuple[int, int, int]],
    title: str,
    *,
    baseline: str,
) -> Figure:
    """Box per (condition, controller) and joint, with the episodes as points for small n
    (the baseline's box first in each group)."""
    joints = _joints(table)
    controllers = drawing_order(table.get_column("controller").to_list(), baseline)
    fig, axes = _axes(len(joints), width=max(4.2, 0.5 * len(conditions) * len(controllers)))
    ok = table.filter(pl.col("status") == "ok")
    rng = np.random.default_rng(0)  # jitter only; fixed so figures are reproducible
    width = 0.8 / max(len(controllers), 1)
    for ax, joint in zip(axes, joints, strict=True):
        sub = ok.filter(pl.col("joint") == joint)
        drawn: list[NDArray[np.float64]] = []
        for ci, cond in enumerate(conditions):
            for k, ctrl in enumerate(controllers):
                vals = _values(
                    sub.filter((pl.col("condition") == cond) & (pl.col("controller") == ctrl)),
                    metric,
                )
                if vals.size == 0:
                    continue
                drawn.append(vals)
                x = ci + (k - (len(controllers) - 1) / 2) * width
                color = mpl(colors[ctrl])
                box = ax.boxplot(
                    [vals], positions=[x], widths=width * 0.8, patch_artist=True,
                    showfliers=vals.size > MAX_POINTS_PER_BOX, manage_ticks=False,
                )  # fmt: skip
                for patch in box["boxes"]:
                    patch.set(facecolor=(*color, 0.25), edgecolor=color)
                for part in ("medians", "whiskers", "caps"):
                    for line in box[part]:
                        line.set(color=color)
                if vals.size <= MAX_POINTS_PER_BOX:
                    jitter = rng.uniform(-width * 0.3, width * 0.3, vals.size)
                    ax.plot(x + jitter, vals, "o", ms=2.5, color=color, alpha=0.8)
        unit = readable_scale(ax, "y", _concat(drawn), log=metric.log_scale, unit=metric.unit)
        ax.set_xticks(range(len(conditions)))
        ax.set_xticklabels([_short(c) for c in conditions], rotation=25, ha="right", fontsize=7)
        _title(ax, joint)
        ax.tick_params(labelsize=7)
        ax.grid(True, axis="y", lw=0.3)
        ax.set_ylabel(unit_label(metric.label, unit), fontsize=7)
    _legend(fig, colors, controllers)
    fig.suptitle(title, fontsize=10, x=0.02, ha="left")
    return fig


def ecdf_figure(
    table: pl.DataFrame,
    metric: catalog.Metric,
    colors: dict[str, tuple[int, int, int]],
    title: str,
    *,
    baseline: str,
) -> Figure:
    """Empirical CDF per joint and controller (every condition pooled), each step rising
    from 0 at its smallest value; the baseline drawn first."""
    joints = _joints(table)
    controllers = drawing_order(table.get_column("controller").to_list(), baseline)
    fig, axes = _axes(len(joints))
    ok = table.filter(pl.col("status") == "ok")
    for ax, joint in zip(axes, joints, strict=True):
        drawn: list[NDArray[np.float64]] = []
        for ctrl in controllers:
            vals = np.sort(
                _values(
                    ok.filter((pl.col("joint") == joint) & (pl.col("controller") == ctrl)), metric
                )
            )
            if vals.size == 0:
                continue
            drawn.append(vals)
            # (v0, 0), (v0, 1/n), (v1, 2/n), ...: the share of episodes at or below x
            ax.step(np.concatenate([vals[:1], vals]), np.arange(vals.size + 1) / vals.size,
                    where="post", color=mpl(colors[ctrl]), lw=1.2)  # fmt: skip
        unit = readable_scale(ax, "x", _concat(drawn), log=metric.log_scale, unit=metric.unit)
        ax.set_ylim(0.0, 1.02)
        _title(ax, joint)
        ax.set_xlabel(unit_label(metric.label, unit), fontsize=7)
        ax.set_ylabel("share of episodes", fontsize=7)
        ax.tick_params(labelsize=7)
        ax.grid(True, lw=0.3)
    _legend(fig, colors, controllers)
    fig.suptitle(title, fontsize=10, x=0.02, ha="left")
    return fig


def parameter_figure(
    table: pl.DataFrame,
    stats: pl.DataFrame,
    axis: str,
    metric: catalog.Metric,
    colors: dict[str, tuple[int, int, int]],
    title: str,
    *,
    baseline: str,
) -> Figure:
    """Mean with its 95 % CI band against one swept parameter, per joint and controller
    (``stats``: :func:`~pipeline.analysis.campaign_tables.by_parameter` of ``table``): where the
    bands cross is where one controller stops winning. The baseline is drawn first."""
    joints = _joints(table)
    controllers = drawing_order(stats.get_column("controller").to_list(), baseline)
    fig, axes = _axes(len(joints))
    log = metric.log_scale and bool((stats.get_column("mean") > 0).all())
    for ax, joint in zip(axes, joints, strict=True):
        drawn: list[NDArray[np.float64]] = []
        for ctrl in controllers:
            s = stats.filter((pl.col("joint") == joint) & (pl.col("controller") == ctrl))
            if not s.height:
                continue
            x = s.get_column("value").to_numpy()
            mean = s.get_column("mean").to_numpy()
            low = s.get_column("ci95_low").fill_null(np.nan).to_numpy()
            high = s.get_column("ci95_high").fill_null(np.nan).to_numpy()
            color = mpl(colors[ctrl])
            ax.fill_between(x, low, high, color=color, alpha=0.25, lw=0)
            ax.plot(x, mean, "o-", color=color, ms=3, lw=1.2)
            drawn += [mean, low, high]
        unit = readable_scale(ax, "y", _concat(drawn), log=log, unit=metric.unit)
        _title(ax, joint)
        ax.set_xlabel(axis.removeprefix(SWEPT_PREFIX), fontsize=7)
        ax.set_ylabel(unit_label(metric.label, unit), fontsize=7)
        ax.tick_params(labelsize=7)
        ax.grid(True, lw=0.3)
    _legend(fig, colors, controllers)
    fig.suptitle(title, fontsize=10, x=0.02, ha="left")
    return fig


# A baseline below this many times its metric's noise floor is "near the noise": its
# cells give the absolute difference beside the percentage.
NEAR_NOISE_FLOORS = 1000.0


def _verdict_cell(row: dict[str, object], m: catalog.Metric) -> str:
    effect, hw, p, verdict = (
        row["effect_pct"],
        row["effect_ci95_half_width"],
        row["p_holm"],
        row["verdict"],
    )
    if verdict == "n/a" or not isinstance(effect, float):
        return "n/a"
    if effect < md.RATIO_BELOW_PCT:
        size = f"{1.0 - effect / 100.0:.3g}× the baseline's"
    else:
        size = f"{effect:+.0f} ± {hw:.0f} %" if isinstance(hw, float) else f"{effect:+.0f} %"
    base, diff = row["baseline_mean"], row["abs_diff"]
    if (
        isinstance(base, float)
        and isinstance(diff, float)
        and abs(base) < NEAR_NOISE_FLOORS * m.floor
    ):
        size += f" (Δ {diff:+.2g} {m.unit})"
    if verdict == "equivalent":
        margin = row["equivalence_margin"]
        within = f"|Δ| < {margin:.2g} {m.unit}" if isinstance(margin, float) else "within margin"
        return f"*equivalent* {size} ({within}, n = {row['n']})"
    if not isinstance(p, float):
        return f"{size} (n = {row['n']}; too few pairs for a test)"
    mark = {"wins": "**wins**", "loses": "**loses**"}.get(str(verdict), "n.s.")
    return f"{mark} {size} (Holm p = {p:.2g}, n = {row['n']})"


def campaign_section(
    table_path: Path,
    *,
    out_dir: Path,
    rel_table: str,
    name: str,
    stem: str,
    baseline: str,
    sample: dict[str, str],
    draw: bool = True,
) -> CampaignSection:
    """The Markdown section and figures of one campaign, from its Parquet table.

    Args:
        table_path: the campaign table to scan (written before, in the staging folder).
        out_dir: the (staging) report folder figures and CSVs go to.
        rel_table: the table's path relative to the report folder (for the text).
        name: the campaign.
        stem: file-name stem for its figures.
        baseline: the controller the others are compared with.
        sample: episode -> role ("median", "worst", ...) of the episodes shown one by one.
        draw: draw the figures (False: only the text and the CSVs).
    """
    table = pl.scan_parquet(table_path).collect()
    conditions = _conditions(table)
    shown = conditions[:MAX_CONDITIONS_SHOWN]
    controllers = drawing_order(table.get_column("controller").to_list(), baseline)
    colors = controller_colors(controllers)
    episodes = table.unique("episode", maintain_order=True)
    n_eps = episodes.height
    files: list[str] = []
    axes = swept_axes(table)
    lines = [
        f"## Campaign `{name}`",
        "",
        f"{n_eps} episodes, {len(conditions)} condition(s), controllers "
        f"{', '.join(controllers)}; swept: "
        + (
            ", ".join(
                f"`{c.removeprefix(SWEPT_PREFIX)}` ({table.get_column(c).n_unique()} values)"
                for c in table.columns
                if c.startswith(SWEPT_PREFIX)
            )
            or "nothing"
        )
        + ". Every episode's swept values and per-joint metrics: "
        f"[`{rel_table}`]({rel_table}), one row per episode and joint "
        f'(`pl.read_parquet("{rel_table}")`).',
        "",
    ]
    counts = (
        episodes.group_by("condition", "controller")
        .agg(n=pl.len(), failed=(pl.col("status") != "ok").sum())
        .sort("condition", "controller")
    )
    rows = []
    for cond in shown:
        c = counts.filter(pl.col("condition") == cond)
        per = {r["controller"]: r for r in c.iter_rows(named=True)}
        rows.append(
            [
                cond or "(all)",
                *[
                    str(per[k]["n"]) + (f" ({per[k]['failed']} failed)" if per[k]["failed"] else "")
                    if k in per
                    else "0"
                    for k in controllers
                ],
            ]
        )
    lines += [md.table(["condition", *controllers], rows), ""]
    if len(conditions) > len(shown):
        lines += [f"({len(conditions) - len(shown)} more conditions in the table.)", ""]

    compared = tuple(m.name for m in catalog.METRICS if m.compared)
    wl = win_loss(table, baseline=baseline, metrics=compared)
    if wl.height:
        wl_rel = f"{TABLE_DIR}/{stem}_win_loss.csv"
        wl.write_csv(out_dir / wl_rel)
        files.append(wl_rel)
        tests = sorted(set(wl.get_column("test").to_list()) - {TOO_FEW})
        n_tests = sorted(set(wl.get_column("tests").to_list()))
        lines += [
            f"### Win/loss against `{baseline}` (joint × condition)",
            "",
            "Each cell, the size: the mean per-pair reduction (baseline − candidate) / "
            "baseline with its paired 95 % Student-t interval where seeds pair (else the "
            "reduction of the medians), the absolute difference beside it where the "
            "baseline is near the noise, a ratio where the candidate is more than twice the "
            f"baseline. The verdict: the report's one rule (the Verdicts and the paper's "
            "claims use it too): *equivalent* when the difference is within the practical "
            f"margin (the larger of the encoder's resolution, {resolution_text()}, and "
            f"{EQUIVALENCE_REL * 100:.0f} % of the baseline); else a two-sided test "
            f"({'; '.join(tests) or 'none'}) only from "
            f"{MIN_PAIRS} pairs (where it can reach p < {ALPHA:g}), its p "
            "Holm-corrected over the tests of its table "
            f"({', '.join(str(c) for c in n_tests)} test(s) per table); **wins** / **loses** "
            f"when the corrected p < {ALPHA:g}, *n.s.* when not; with fewer pairs the cell "
            f"says *too few pairs for a test*. Every cell: [`{wl_rel}`]({wl_rel}).",
            "",
        ]
        for metric in compared:
            m = catalog.BY_NAME[metric]
            for cand in sorted(set(wl.get_column("candidate").to_list())):
                sub = wl.filter((pl.col("metric") == metric) & (pl.col("candidate") == cand))
                if not sub.height:
                    continue
                cells = {(r["joint"], r["condition"]): r for r in sub.iter_rows(named=True)}
                rows = [
                    [
                        joint if joint == catalog.TCP_JOINT else f"{k + 1} {joint}",
                        *[
                            _verdict_cell(cells[(joint, c)], m) if (joint, c) in cells else "n/a"
                            for c in shown
                        ],
                    ]
                    for k, joint in enumerate(_joints(table))
                    if m.applies_to(joint)
                ]
                lines += [
                    f"#### {m.title}: `{cand}` vs `{baseline}`",
                    "",
                    md.table(["joint", *[c or "(all)" for c in shown]], rows),
                    "",
                ]
        lines += flip_lines(wl, conditions, out_dir=out_dir, stem=stem, files=files)
    else:
        lines += [
            f"No win/loss matrix: the campaign has no completed `{baseline}` episodes and "
            "another controller to compare with.",
            "",
        ]

    if draw:
        figures: list[FigureFile] = []
        # the joints' compared metrics and the TCP's max errors (not its RMS and final)
        drawn = [
            x for x in compared
            if catalog.BY_NAME[x].space == "joint" or x in HEADLINE_TASK_METRICS
        ]  # fmt: skip
        ok = episodes.filter(pl.col("status") == "ok")
        per_box = _n_range(ok.group_by("condition", "controller").len().get_column("len"))
        per_controller = _n_range(ok.group_by("controller").len().get_column("len"))
        first = f"`{baseline}` (the baseline) drawn first" if baseline in controllers else ""
        for metric in drawn:
            m = catalog.BY_NAME[metric]
            sub = table.filter((pl.col("joint") == catalog.TCP_JOINT) == (m.space == "task"))
            fig = distribution_figure(
                sub, m, shown, colors, f"{name}: {m.title.lower()} per condition and controller",
                baseline=baseline,
            )  # fmt: skip
            figures.append(
                FigureFile(
                    save_figure(fig, out_dir, f"{stem}_{metric}_distribution.png"),
                    f"{m.title}: distribution per condition, joint and controller over the "
                    f"completed episodes ({per_box} per box). Shaded box: the 25th to 75th "
                    "percentile, line: the median, whiskers: the furthest episode within "
                    f"1.5 × the box's height; points: every episode (up to {MAX_POINTS_PER_BOX} "
                    "per box, else the outliers)" + (f"; {first}, leftmost" if first else ""),
                )
            )
            fig = ecdf_figure(sub, m, colors, f"{name}: {m.title.lower()}, ECDF", baseline=baseline)
            figures.append(
                FigureFile(
                    save_figure(fig, out_dir, f"{stem}_{metric}_ecdf.png"),
                    f"{m.title}: empirical CDF per joint and controller, every condition "
                    f"pooled ({per_controller} completed episodes per controller): the share "
                    "of episodes at or below each value, from 0" + (f"; {first}" if first else ""),
                )
            )
            for axis in axes[:MAX_AXES_DRAWN]:
                short = axis.removeprefix(SWEPT_PREFIX)
                stats = by_parameter(sub, axis, m.name)
                fig = parameter_figure(
                    sub, stats, axis, m, colors, f"{name}: {m.title.lower()} against {short}",
                    baseline=baseline,
                )  # fmt: skip
                figures.append(
                    FigureFile(
                        save_figure(fig, out_dir, f"{stem}_{metric}_vs_{short}.png"),
                        f"{m.title} against `{short}`, per joint and controller: points, the "
                        "mean over the completed episodes at that value (other swept values "
                        "pooled); shaded band, its 95 % Student-t confidence interval "
                        f"({_n_range(stats.get_column('n'))} per point; no band where n < 2). "
                        "Where the bands cross, the better controller changes"
                        + (f"; {first}" if first else ""),
                    )
                )
        files += [f.relpath for f in figures]
        lines += ["### Figures", ""]
        for f in figures:
            lines += [f"**{f.caption}**", "", f"![{f.caption}]({f.relpath})", ""]

    picked = episodes.filter(pl.col("episode").is_in(list(sample)))
    if picked.height:
        worst = (
            table.group_by("episode")
            .agg(
                max_abs_error=pl.col("max_abs_error").max(),
                final_error=pl.col("final_error").max(),
            )
            .join(
                picked.select("episode", "condition", "controller", "seed", "status"), on="episode"
            )
            .sort("condition", "controller", "episode")
        )
        rows = [
            [
                r["episode"],
                r["condition"] or "(all)",
                r["controller"],
                str(r["seed"]),
                sample.get(r["episode"]) or "all",
                r["status"],
                "n/a" if r["max_abs_error"] is None else f"{r['max_abs_error']:.3e}",
                "n/a" if r["final_error"] is None else f"{r['final_error']:.3e}",
            ]
            for r in worst.head(4 * MAX_CONDITIONS_SHOWN).iter_rows(named=True)
        ]
        lines += [
            "### Sampled episodes",
            "",
            "The episodes shown one by one in `recording.rrd` and the plot CSVs: per condition "
            "and controller the median and the worst by max |error| over joints (every "
            "episode where there are only a few). Worst joint shown.",
            "",
            md.table(
                [
                    "episode",
                    "condition",
                    "controller",
                    "seed",
                    "role",
                    "status",
                    "max |error| [rad]",
                    "error at the target [rad]",
                ],
                rows,
            ),
            "",
        ]
    return CampaignSection(name, rel_table, tuple(lines), tuple(files))
