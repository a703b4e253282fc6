"""Repeated runs: distributions over seeds instead of single numbers.

A scenario run under one controller with several seeds gives several values of each
metric; they are summarised as the mean with a Student-t confidence interval
(:data:`CONFIDENCE`), with n. Reductions are computed per seed pair (baseline and
candidate of the same seed, when the scenario has such pairs) and summarised the
same way, so a seed-to-seed spread that both controllers share cancels out.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import polars as pl

from pipeline.analysis.catalog import BY_NAME, COMPARED_METRICS
from pipeline.analysis.episodes import comparable
from pipeline.analysis.intervals import CONFIDENCE as CONFIDENCE
from pipeline.analysis.intervals import MeanCI as MeanCI
from pipeline.analysis.intervals import mean_ci as mean_ci

AGGREGATE_SCHEMA: dict[str, pl.DataType | type[pl.DataType]] = {
    "scenario": pl.String,
    "controller": pl.String,
    "joint": pl.String,
    "metric": pl.String,
    "n": pl.Int64,
    "mean": pl.Float64,
    "std": pl.Float64,
    "ci95_half_width": pl.Float64,
}
REDUCTION_SCHEMA: dict[str, pl.DataType | type[pl.DataType]] = {
    "scenario": pl.String,
    "baseline": pl.String,
    "controller": pl.String,
    "pairing": pl.String,
    "joint": pl.String,
    "metric": pl.String,
    "n": pl.Int64,
    "mean": pl.Float64,
    "std": pl.Float64,
    "ci95_half_width": pl.Float64,
    # the report's one rule (pipeline.analysis.verdict.compare) on the pairs' values
    "verdict": pl.String,
    "equivalence_margin": pl.Float64,
}


def _ok(episodes: pl.DataFrame) -> pl.DataFrame:
    """Completed episodes (not a salvaged one cut before its motion end), with
    ``scenario`` = the group they are compared in (the scenario, or
    ``campaign/condition``: :func:`pipeline.analysis.episodes.group_key`)."""
    ok = episodes.filter(comparable(episodes))
    if "group" in ok.columns:
        ok = ok.with_columns(pl.col("group").alias("scenario"))
    return ok


def runs_per_controller(episodes: pl.DataFrame) -> dict[tuple[str, str], int]:
    """Completed ("ok") episodes per (scenario, controller)."""
    counts = _ok(episodes).group_by("scenario", "controller").len()
    return {(r["scenario"], r["controller"]): int(r["len"]) for r in counts.iter_rows(named=True)}


def _applying(compared: Sequence[str], joint: str) -> list[str]:
    """The compared metrics with a value in the rows of ``joint`` (a joint or the TCP)."""
    return [m for m in compared if m not in BY_NAME or BY_NAME[m].applies_to(joint)]


def metric_aggregates(
    metrics: pl.DataFrame,
    episodes: pl.DataFrame,
    *,
    compared: Sequence[str] = COMPARED_METRICS,
) -> pl.DataFrame:
    """Per (scenario, controller, joint, metric) over the "ok" episodes: n, mean, std and
    the 95 % half width (columns :data:`AGGREGATE_SCHEMA`)."""
    joined = metrics.join(
        _ok(episodes).select("episode", "scenario", "controller"),
        on="episode",
        how="inner",
        maintain_order="left",
    )
    rows: list[dict[str, Any]] = []
    for (scenario, controller, joint), group in joined.group_by(
        "scenario", "controller", "joint", maintain_order=True
    ):
        for metric in _applying(compared, str(joint)):
            ci = mean_ci(group.get_column(metric).to_list())
            rows.append(
                {
                    "scenario": scenario,
                    "controller": controller,
                    "joint": joint,
                    "metric": metric,
                    "n": ci.n,
                    "mean": ci.mean,
                    "std": ci.std,
                    "ci95_half_width": ci.half_width,
                }
            )
    return pl.DataFrame(rows, schema=AGGREGATE_SCHEMA, orient="row")


def seed_pairs(comparisons: pl.DataFrame, episodes: pl.DataFrame) -> pl.DataFrame:
    """The comparison rows a repeated-run summary uses, with a ``pairing`` column.

    Per (scenario, candidate controller): the pairs whose baseline and candidate share a
    seed ("seed") when there are any; else every pair (``pairing`` "all": the runs cannot
    be matched, so each candidate is compared with every baseline run).
    """
    info = episodes.select("episode", "controller", "seed")
    rows = comparisons.join(
        info.rename({"episode": "baseline", "controller": "baseline_controller", "seed": "bs"}),
        on="baseline",
        how="left",
        maintain_order="left",
    ).join(
        info.rename({"episode": "candidate", "seed": "cs"}),
        on="candidate",
        how="left",
        maintain_order="left",
    )
    rows = rows.with_columns(same_seed=(pl.col("bs") == pl.col("cs")).fill_null(False))
    any_matched = pl.col("same_seed").any().over("scenario", "controller")
    return (
        rows.filter(pl.col("same_seed") | ~any_matched)
        .with_columns(pairing=pl.when(any_matched).then(pl.lit("seed")).otherwise(pl.lit("all")))
        .drop("bs", "cs", "same_seed")
    )


def reduction_aggregates(
    comparisons: pl.DataFrame,
    episodes: pl.DataFrame,
    *,
    compared: Sequence[str] = COMPARED_METRICS,
) -> pl.DataFrame:
    """Per (scenario, candidate controller, joint, metric): the reduction % of each seed pair
    (see :func:`seed_pairs`) summarised as n, mean, std, 95 % half width (columns
    :data:`REDUCTION_SCHEMA`; ``metric`` is e.g. ``max_abs_error_reduction_pct``)."""
    from pipeline.analysis.verdict import compare

    rows: list[dict[str, Any]] = []
    pairs = seed_pairs(comparisons, episodes)
    seed_of = dict(episodes.select("episode", "seed").iter_rows())
    for (scenario, base, controller, pairing, joint), group in pairs.group_by(
        "scenario", "baseline_controller", "controller", "pairing", "joint", maintain_order=True
    ):
        for metric in _applying(compared, str(joint)):
            key = f"{metric}_reduction_pct"
            ci = mean_ci(group.get_column(key).to_list())
            verdict = compare(
                *_keyed(group, metric, seed_of, paired=pairing == "seed"),
                unit=BY_NAME[metric].unit if metric in BY_NAME else "",
                lower_is_better=BY_NAME[metric].lower_is_better if metric in BY_NAME else True,
            )
            rows.append(
                {
                    "scenario": scenario,
                    "baseline": base,
                    "controller": controller,
                    "pairing": pairing,
                    "joint": joint,
                    "metric": key,
                    "n": ci.n,
                    "mean": ci.mean,
                    "std": ci.std,
                    "ci95_half_width": ci.half_width,
                    "verdict": verdict.outcome,
                    "equivalence_margin": verdict.margin,
                }
            )
    return pl.DataFrame(rows, schema=REDUCTION_SCHEMA, orient="row")


def _keyed(
    group: pl.DataFrame, metric: str, seed_of: dict[str, Any], *, paired: bool
) -> tuple[dict[Any, Any], dict[Any, Any]]:
    """The pairs' baseline and candidate values keyed by seed (paired), else by episode."""
    base: dict[Any, Any] = {}
    cand: dict[Any, Any] = {}
    cols = ("baseline", "candidate", f"{metric}_baseline", f"{metric}_candidate")
    for b, c, vb, vc in group.select(*cols).iter_rows():
        base[seed_of.get(b) if paired else ("b", b)] = vb
        cand[seed_of.get(c) if paired else ("c", c)] = vc
    return base, cand
