"""One table per campaign: every episode's swept settings and per-joint metrics.

``<reports>/campaigns/<campaign>.parquet``, one row per episode and joint: ``episode,
campaign, condition, controller, seed``, every swept axis as its own ``swept.<path>``
column (controller and seed included, as recorded), ``status``, ``joint`` and every
metric of :data:`pipeline.analysis.catalog.METRICS`. It is built from the same metric
frame as metrics.json (the recordings stay the source of truth); load it with
``pl.read_parquet("reports/campaigns/NAME.parquet")``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import polars as pl

from pipeline.analysis.catalog import BY_NAME, METRIC_COLUMNS
from pipeline.analysis.episodes import SALVAGED_CUT, comparable
from pipeline.settings import EpisodeSettings

TABLE_DIR = "campaigns"
SWEPT_PREFIX = "swept."
ID_COLUMNS = ("episode", "campaign", "condition", "controller", "seed")


def _column(values: list[Any]) -> pl.Series:
    """A swept axis as one typed column: bool, int, float or (anything else) string."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return pl.Series(values, dtype=pl.Boolean)
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pl.Series(values, dtype=pl.Int64)
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return pl.Series([None if v is None else float(v) for v in values], dtype=pl.Float64)
    return pl.Series([None if v is None else str(v) for v in values], dtype=pl.String)


def campaign_tables(
    metrics: pl.DataFrame,
    episodes: pl.DataFrame,
    settings: Mapping[str, EpisodeSettings | None],
) -> dict[str, pl.DataFrame]:
    """Campaign name -> its table (see the module doc), rows sorted by episode and joint
    order as recorded. Hand-listed episodes (no ``settings.campaign``) are in none.

    Args:
        metrics: :func:`pipeline.analysis.metrics.joint_metrics`.
        episodes: :func:`pipeline.analysis.episodes.episode_table`.
        settings: episode -> its typed settings (None when absent or not the contract).
    """
    by_campaign: dict[str, list[tuple[str, EpisodeSettings]]] = {}
    for episode, st in sorted(settings.items()):
        if st is not None and st.campaign is not None:
            by_campaign.setdefault(st.campaign.name, []).append((episode, st))
    out: dict[str, pl.DataFrame] = {}
    for name, members in sorted(by_campaign.items()):
        infos = [(e, st, st.campaign) for e, st in members if st.campaign is not None]
        axes = sorted({k for _, _, c in infos for k in c.swept})
        frame = pl.DataFrame(
            {
                "episode": [e for e, _, _ in infos],
                "campaign": [name] * len(infos),
                "condition": [c.condition for _, _, c in infos],
                "seed": [st.seed for _, st, _ in infos],
            },
            schema_overrides={"seed": pl.Int64},
        )
        frame = frame.with_columns(
            _column([c.swept.get(axis) for _, _, c in infos]).alias(f"{SWEPT_PREFIX}{axis}")
            for axis in axes
        )
        # a salvaged recording cut before its motion end is no completed run
        status = pl.when(comparable(episodes)).then(pl.col("status"))
        frame = frame.join(
            episodes.select(
                "episode",
                "controller",
                status.otherwise(pl.lit(SALVAGED_CUT)).alias("status"),
            ),
            on="episode",
            how="left",
        )
        table = frame.join(
            metrics.select("episode", "joint", *METRIC_COLUMNS),
            on="episode",
            how="inner",
            maintain_order="right",
        )
        swept = [f"{SWEPT_PREFIX}{a}" for a in axes]
        out[name] = table.select(*ID_COLUMNS, *swept, "status", "joint", *METRIC_COLUMNS).sort(
            "episode", maintain_order=True
        )
    return out


# --- summaries over a campaign table --------------------------------------------------------

ALPHA = 0.05
WILCOXON = "Wilcoxon signed-rank (paired by seed)"
MANN_WHITNEY = "Mann-Whitney U (unpaired: seeds do not pair)"

WIN_LOSS_SCHEMA: dict[str, pl.DataType | type[pl.DataType]] = {
    "condition": pl.String,
    "candidate": pl.String,
    "baseline": pl.String,
    "joint": pl.String,
    "metric": pl.String,
    "n": pl.Int64,
    "effect_pct": pl.Float64,
    "test": pl.String,
    "p_value": pl.Float64,
    "verdict": pl.String,
}


def swept_axes(table: pl.DataFrame) -> list[str]:
    """Numeric swept axes (not the seed) with at least two values: what a metric is drawn
    against."""
    out = []
    for col in table.columns:
        if not col.startswith(SWEPT_PREFIX) or col == f"{SWEPT_PREFIX}seed":
            continue
        if table.schema[col].is_numeric() and table.get_column(col).n_unique() > 1:
            out.append(col)
    return out


def _test(
    base: dict[int, float], cand: dict[int, float], lower_is_better: bool
) -> tuple[int, float | None, str, float | None]:
    """(n, effect %, test, p): paired by seed when seeds pair, else unpaired."""
    from scipy import stats

    sign = 1.0 if lower_is_better else -1.0
    common = sorted(set(base) & set(cand))
    if len(common) >= 2:
        b = [base[s] for s in common]
        c = [cand[s] for s in common]
        diffs = [sign * (x - y) for x, y in zip(b, c, strict=True)]
        red = [sign * (x - y) / abs(x) * 100.0 for x, y in zip(b, c, strict=True) if x != 0]
        effect = float(sorted(red)[len(red) // 2]) if red else None
        if all(d == 0 for d in diffs):
            return len(common), effect, WILCOXON, 1.0
        p = float(stats.wilcoxon(diffs).pvalue)
        return len(common), effect, WILCOXON, p
    b = list(base.values())
    c = list(cand.values())
    if len(b) < 2 or len(c) < 2:
        return min(len(b), len(c)), None, MANN_WHITNEY, None
    mb, mc = sorted(b)[len(b) // 2], sorted(c)[len(c) // 2]
    effect = sign * (mb - mc) / abs(mb) * 100.0 if mb != 0 else None
    p = float(stats.mannwhitneyu(b, c, alternative="two-sided").pvalue)
    return min(len(b), len(c)), effect, MANN_WHITNEY, p


def win_loss(table: pl.DataFrame, *, baseline: str, metrics: tuple[str, ...]) -> pl.DataFrame:
    """Each candidate controller against ``baseline`` per condition, joint and metric.

    Completed ("ok") episodes only. Where both controllers ran the same seeds (at least
    two), the per-seed differences take a two-sided Wilcoxon signed-rank test and the
    effect is the median paired reduction (baseline - candidate) / baseline x 100; else a
    two-sided Mann-Whitney U test and the reduction of the medians. ``verdict``: "wins"
    / "loses" when p < :data:`ALPHA` (by the effect's sign), else "no difference"
    ("n/a" without a test). Columns :data:`WIN_LOSS_SCHEMA`.
    """
    ok = table.filter(pl.col("status") == "ok")
    rows: list[dict[str, Any]] = []
    controllers = sorted(set(ok.get_column("controller").to_list()) - {baseline})
    if baseline not in set(ok.get_column("controller").to_list()):
        return pl.DataFrame(schema=WIN_LOSS_SCHEMA)
    for (condition, joint), grp in ok.group_by("condition", "joint", maintain_order=True):
        for metric in metrics:
            per: dict[str, dict[int, float]] = {}
            for r in grp.select("controller", "seed", metric).iter_rows():
                if r[2] is not None:
                    per.setdefault(r[0], {})[int(r[1])] = float(r[2])
            for cand in controllers:
                if cand not in per or baseline not in per:
                    continue
                lower = BY_NAME[metric].lower_is_better
                n, effect, test, p = _test(per[baseline], per[cand], lower)
                verdict = (
                    "n/a"
                    if p is None or effect is None
                    else ("wins" if effect > 0 else "loses")
                    if p < ALPHA
                    else "no difference"
                )
                rows.append(
                    {
                        "condition": condition,
                        "candidate": cand,
                        "baseline": baseline,
                        "joint": joint,
                        "metric": metric,
                        "n": n,
                        "effect_pct": effect,
                        "test": test,
                        "p_value": p,
                        "verdict": verdict,
                    }
                )
    return pl.DataFrame(rows, schema=WIN_LOSS_SCHEMA, orient="row").sort(
        "metric", "candidate", "condition", "joint", maintain_order=True
    )


def by_parameter(table: pl.DataFrame, axis: str, metric: str) -> pl.DataFrame:
    """Mean and 95 % Student-t CI of ``metric`` per value of one swept ``axis``, controller
    and joint (completed episodes, every other axis pooled): ``value, controller, joint,
    n, mean, ci95_low, ci95_high``."""
    from pipeline.analysis.aggregate import mean_ci

    ok = table.filter((pl.col("status") == "ok") & pl.col(metric).is_not_null())
    rows = []
    for (value, controller, joint), grp in ok.group_by(
        axis, "controller", "joint", maintain_order=True
    ):
        ci = mean_ci(grp.get_column(metric).to_list())
        rows.append(
            {
                "value": float(value),
                "controller": controller,
                "joint": joint,
                "n": ci.n,
                "mean": ci.mean,
                "ci95_low": ci.low,
                "ci95_high": ci.high,
            }
        )
    schema = {
        "value": pl.Float64,
        "controller": pl.String,
        "joint": pl.String,
        "n": pl.Int64,
        "mean": pl.Float64,
        "ci95_low": pl.Float64,
        "ci95_high": pl.Float64,
    }
    return pl.DataFrame(rows, schema=schema, orient="row").sort("controller", "joint", "value")
