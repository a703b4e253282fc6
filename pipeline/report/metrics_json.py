"""metrics.json (stable keys, deterministic bytes) and the series CSVs for ``dvc plots``."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl

from pipeline.analysis import headline as summary
from pipeline.analysis.aggregate import CONFIDENCE
from pipeline.analysis.catalog import BY_NAME, COMPARED_METRICS, METRIC_SOURCES, METRICS
from pipeline.analysis.measure import cs_times_s, cs_wide, times_s, wide
from pipeline.analysis.metrics import ERROR_FLOOR_RAD, SETTLING_TOLERANCE_RAD
from pipeline.constants import FINAL_WINDOW_S
from pipeline.report.inputs import ReportData

METRICS_FILE = "metrics.json"
# The declared DVC metric: the headline reductions only (metrics.json is a plain output).
HEADLINE_FILE = "headline.json"
PLOTS_DIR = "plots"
# Series CSVs are thinned to at most this many samples per episode and joint.
MAX_CSV_POINTS = 1000
SIGNIFICANT_DIGITS = 9
# Times are rounded to a fixed number of decimals (1 ns), not significant digits: 9 digits
# of a 1.7e9 s wall-clock time would be whole seconds.
TIME_DECIMALS = 9
_FLOOR = f"{ERROR_FLOOR_RAD:.0e}".replace("e-0", "e-")  # "1e-9"


def number(value: Any) -> float | None:
    """A float rounded to :data:`SIGNIFICANT_DIGITS` digits; None for null/NaN/inf."""
    if value is None:
        return None
    x = float(value)
    if not math.isfinite(x):
        return None
    return float(f"{x:.{SIGNIFICANT_DIGITS}g}") + 0.0  # + 0.0 turns -0.0 into 0.0


def seconds(value: Any) -> float | None:
    """A time [s] rounded to :data:`TIME_DECIMALS` decimals; None for null/NaN/inf."""
    if value is None:
        return None
    x = float(value)
    if not math.isfinite(x):
        return None
    return round(x, TIME_DECIMALS) + 0.0


def _rounded(key: str, value: Any) -> float | None:
    """Times [s] to decimals, everything else to significant digits."""
    return seconds(value) if BY_NAME[key].is_time else number(value)


def _aggregates(data: ReportData) -> dict[str, Any]:
    """Groups (scenarios, campaign conditions) with repeated runs (a controller run more than
    once, e.g. several seeds):
    scenario -> {"controllers": controller -> joint -> metric -> stats,
    "reductions": "<candidate> vs <baseline>" -> {"pairing", "joints": joint ->
    <metric>_reduction_pct -> stats}}. Single runs are in "episodes" / "comparisons"."""

    def stats(row: dict[str, Any]) -> dict[str, Any]:
        mean, hw = row["mean"], row["ci95_half_width"]
        return {
            "n": row["n"],
            "mean": number(mean),
            "std": number(row["std"]),
            "ci95_half_width": number(hw),
            "ci95_low": number(None if mean is None or hw is None else mean - hw),
            "ci95_high": number(None if mean is None or hw is None else mean + hw),
        }

    out: dict[str, Any] = {}
    repeated = {g for g in data.groups() if data.repeated(g)}
    for row in data.metric_summary.filter(pl.col("scenario").is_in(repeated)).iter_rows(named=True):
        node = out.setdefault(row["scenario"], {"controllers": {}, "reductions": {}})
        joint = node["controllers"].setdefault(row["controller"], {}).setdefault(row["joint"], {})
        joint[row["metric"]] = stats(row)
    for row in data.reduction_summary.filter(pl.col("scenario").is_in(repeated)).iter_rows(
        named=True
    ):
        node = out.setdefault(row["scenario"], {"controllers": {}, "reductions": {}})
        pair = node["reductions"].setdefault(
            f"{row['controller']} vs {row['baseline']}", {"pairing": row["pairing"], "joints": {}}
        )
        pair["joints"].setdefault(row["joint"], {})[row["metric"]] = stats(row)
    return out


def _stats_ci(mean: Any, half_width: Any) -> tuple[float | None, float | None]:
    if mean is None or half_width is None:
        return None, None
    return number(mean - half_width), number(mean + half_width)


def headline(data: ReportData) -> dict[str, Any]:
    """Flat scalars for ``dvc metrics diff`` / ``dvc exp show`` (DVC skips lists):
    ``<group>.<candidate>_vs_<baseline>.<joint>.<metric>.{reduction_pct, ci95_low,
    ci95_high, n}``; group = scenario, or ``campaign/condition``. ``reduction_pct`` is the
    mean over the pairs (seed pairs where seeds pair), the CI bounds are the Student-t
    95 % interval of that mean (null for a single pair)."""
    out: dict[str, Any] = {}
    for row in data.reduction_summary.iter_rows(named=True):
        low, high = _stats_ci(row["mean"], row["ci95_half_width"])
        pair = f"{row['controller']}_vs_{row['baseline']}"
        node = out.setdefault(row["scenario"], {}).setdefault(pair, {})
        node.setdefault(row["joint"], {})[row["metric"].removesuffix("_reduction_pct")] = {
            "reduction_pct": number(row["mean"]),
            "ci95_low": low,
            "ci95_high": high,
            "n": row["n"],
        }
    return out


def metrics_document(data: ReportData) -> dict[str, Any]:
    """The metrics.json content as plain data (see docs/report.md for every key)."""
    episodes: dict[str, Any] = {}
    by_episode = {
        key[0]: group for key, group in data.metrics.group_by("episode", maintain_order=True)
    }
    for row in data.episodes.iter_rows(named=True):
        ep = row["episode"]
        rec = data.recording(ep)
        group = by_episode.get(ep)
        joints: dict[str, Any] = {}
        if group is not None:
            for m in group.iter_rows(named=True):
                joints[m["joint"]] = {
                    x.name: _rounded(x.name, m[x.name]) for x in METRICS if x.applies_to(m["joint"])
                }
        episodes[ep] = {
            "controller": row["controller"],
            "scenario": row["scenario"],
            "robot": row["robot"],
            "seed": row["seed"],
            "status": row["status"],
            "reason": row["reason"],
            # read with --salvage up to the damage (lost: % of bytes, of a .db3's messages)
            "salvaged": row["salvaged"],
            "salvage_lost_pct": row["salvage_lost_pct"],
            "motion_end_s": seconds(row["motion_end_s"]),
            "end_s": seconds(row["end_s"]),
            "motion_completed": row["motion_completed"],
            "warnings": list(rec.notes),
            "recording": {
                "path": _relative(rec.source, data.recordings_dir),
                "sha256": rec.sha256 or None,  # None: a campaign episode without its bag
            },
            "joints": joints,
        }
    comparisons: list[dict[str, Any]] = []
    key = ["scenario", "baseline", "candidate"]
    for (scenario, base, cand), group in data.comparisons.sort(key).group_by(
        key, maintain_order=True
    ):
        joints = {}
        for m in group.iter_rows(named=True):
            joints[m["joint"]] = {
                f"{metric}_reduction_pct": number(m[f"{metric}_reduction_pct"])
                for metric in COMPARED_METRICS
                if BY_NAME[metric].applies_to(m["joint"])
            }
        comparisons.append(
            {"scenario": scenario, "baseline": base, "candidate": cand, "joints": joints}
        )
    return {
        "parameters": {
            "baseline_controller": data.baseline,
            "final_window_s": FINAL_WINDOW_S,
            "settling_tolerance_rad": SETTLING_TOLERANCE_RAD,
            "reduction": (
                "(baseline - candidate) / baseline * 100; null when |baseline| < "
                f"{_FLOOR} (reduction_floor_rad)"
            ),
            "reduction_floor_rad": ERROR_FLOOR_RAD,
            # per compared metric, in its unit (the TCP's: 1 nm, 1 nrad)
            "reduction_floors": {m.name: m.floor for m in METRICS if m.compared},
            "confidence": CONFIDENCE,
            "metric_sources": dict(METRIC_SOURCES),
            "metric_units": {m.name: m.unit for m in METRICS},
        },
        "episodes": episodes,
        "comparisons": comparisons,
        "aggregates": _aggregates(data),
        "headline": headline(data),
        "skipped": [{"path": s.source, "problem": s.problem} for s in data.skipped],
    }


def _relative(path: Path, root: Path) -> str:
    try:
        return path.resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return path.as_posix()


def dumps_metrics(doc: dict[str, Any]) -> str:
    """Deterministic JSON text: sorted keys, 2-space indent, trailing newline."""
    return json.dumps(doc, indent=2, sort_keys=True, allow_nan=False, ensure_ascii=False) + "\n"


def write_metrics(data: ReportData, out_dir: Path) -> str:
    """Write metrics.json into ``out_dir``; return its relative path."""
    (out_dir / METRICS_FILE).write_text(dumps_metrics(metrics_document(data)), encoding="utf-8")
    return METRICS_FILE


def headline_json(data: ReportData) -> dict[str, Any]:
    """headline.json's content: :func:`pipeline.analysis.headline.headline_document` of the
    report's questions."""
    joints = {g: list(r[0].joint_names) for g in data.groups() if (r := data.in_group(g))}
    return summary.headline_document(summary.questions(data.reduction_summary, joints))


def write_headline(data: ReportData, out_dir: Path) -> str:
    """Write headline.json into ``out_dir``; return its relative path."""
    (out_dir / HEADLINE_FILE).write_text(dumps_metrics(headline_json(data)), encoding="utf-8")
    return HEADLINE_FILE


def series_frame(data: ReportData, column: str, *, controller_state: bool = False) -> pl.DataFrame:
    """Long form ``time_s, controller, episode, joint, value`` of one sample column
    (thinned), for the episodes :meth:`ReportData.sample` keeps (every hand-listed episode
    of a small scenario; median and worst per controller and condition otherwise).

    Args:
        controller_state: take the column from ``/controller_state`` (full rate) instead
            of the ``/joint_states`` samples.
    """
    parts = []
    for rec in data.sample():
        t = cs_times_s(rec) if controller_state else times_s(rec)
        step = max(1, int(np.ceil(t.size / MAX_CSV_POINTS)))
        idx = np.arange(0, t.size, step)
        values = (cs_wide(rec, column) if controller_state else wide(rec, column))[idx]
        n = len(rec.joint_names)
        parts.append(
            pl.DataFrame(
                {
                    "time_s": np.repeat(np.round(t[idx], 9), n),
                    "controller": [rec.controller] * (idx.size * n),
                    "episode": [rec.episode] * (idx.size * n),
                    "joint": list(rec.joint_names) * idx.size,
                    # + 0.0 writes -0.0 as 0.0
                    "value": values.reshape(-1) + 0.0,
                },
                # typed: an episode with no samples (diverged before its motion) is empty
                schema={
                    "time_s": pl.Float64,
                    "controller": pl.String,
                    "episode": pl.String,
                    "joint": pl.String,
                    "value": pl.Float64,
                },
            ).with_columns(pl.col("value").fill_nan(None))  # not recorded: an empty cell
        )
    return pl.concat(parts) if parts else pl.DataFrame()


def write_series_csvs(data: ReportData, out_dir: Path) -> list[str]:
    """reports/plots/errors.csv and velocities.csv (columns time_s, controller, episode,
    joint, value; the DVC template colours by controller and dashes by revision)."""
    folder = out_dir / PLOTS_DIR
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, column, cs in (
        ("errors.csv", "error_rad", True),
        ("velocities.csv", "velocity_rad_s", False),
    ):
        frame = series_frame(data, column, controller_state=cs)
        frame.write_csv(folder / name)
        written.append(f"{PLOTS_DIR}/{name}")
    return written


EPISODES_CSV = "episodes.csv"
RECORDINGS_CSV = "recordings.csv"


def write_episode_csvs(data: ReportData, out_dir: Path) -> list[str]:
    """``episodes.csv`` (the episode table: identity, status, timing, campaign, condition)
    and ``recordings.csv`` (episode, file, bytes, SHA-256): every episode, however many,
    where report.md lists only a bounded number."""
    data.episodes.drop("source").write_csv(out_dir / EPISODES_CSV)
    pl.DataFrame(
        {
            "episode": [r.episode for r in data.recordings],
            "file": [_relative(r.mcap_path, data.recordings_dir) for r in data.recordings],
            # null: a campaign episode kept as its metric partial, without its bag
            "bytes": [r.size_bytes if r.sha256 else None for r in data.recordings],
            "sha256": [r.sha256 or None for r in data.recordings],
        },
        schema={"episode": pl.String, "file": pl.String, "bytes": pl.Int64, "sha256": pl.String},
    ).write_csv(out_dir / RECORDINGS_CSV)
    return [EPISODES_CSV, RECORDINGS_CSV]
