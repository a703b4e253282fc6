"""One table per campaign: every episode's swept settings and per-joint metrics.

``<reports>/campaigns/<campaign>.parquet``, one row per episode and joint: ``episode,
campaign, condition, controller, seed``, every swept axis as its own ``swept.<path>``
column (controller and seed included, as recorded), ``status``, ``joint`` and every
metric of :data:`pipeline.analysis.catalog.METRICS`. It is built from the same metric
frame as metrics.json (the recordings stay the source of truth); load it with
``pl.read_parquet("reports/campaigns/NAME.parquet")``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import polars as pl

from pipeline.analysis.aggregate import MeanCI, mean_ci
from pipeline.analysis.catalog import BY_NAME, METRIC_COLUMNS, Metric
from pipeline.analysis.episodes import SALVAGED_CUT, comparable
from pipeline.analysis.verdict import ALPHA as ALPHA  # the rule's, re-exported
from pipeline.analysis.verdict import MANN_WHITNEY as MANN_WHITNEY
from pipeline.analysis.verdict import MIN_PAIRS as MIN_PAIRS
from pipeline.analysis.verdict import TOO_FEW as TOO_FEW
from pipeline.analysis.verdict import WILCOXON as WILCOXON
from pipeline.analysis.verdict import Outcome, Verdict, compare
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

HOLM = "Holm"

WIN_LOSS_SCHEMA: dict[str, pl.DataType | type[pl.DataType]] = {
    "condition": pl.String,
    "candidate": pl.String,
    "baseline": pl.String,
    "joint": pl.String,
    "metric": pl.String,
    "n": pl.Int64,
    "effect_pct": pl.Float64,
    "effect_ci95_half_width": pl.Float64,
    "abs_diff": pl.Float64,
    "abs_diff_ci95_half_width": pl.Float64,
    "baseline_mean": pl.Float64,
    "test": pl.String,
    "p_value": pl.Float64,
    "p_holm": pl.Float64,
    "tests": pl.Int64,
    "verdict": pl.String,
    "equivalence_margin": pl.Float64,
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


def smallest_p(test: str, n: int, m: int = 0) -> float:
    """The smallest two-sided p the exact test can give: ``2 / 2^n`` for the signed-rank
    test of n pairs, ``2 / C(n + m, n)`` for the Mann-Whitney U test of n and m runs."""
    if test == WILCOXON:
        return min(1.0, 2.0 / 2.0**n)
    return min(1.0, 2.0 / math.comb(n + m, n))


@dataclass(frozen=True)
class Effect:
    """One candidate-vs-baseline cell: the size of the effect and the rule's verdict.

    Attributes:
        n: pairs (paired) or the smaller group (unpaired).
        effect: the mean per-pair reduction (baseline − candidate) / baseline [%] with its
            paired 95 % interval; the reduction of the medians when seeds do not pair.
        abs_diff: the mean per-pair difference baseline − candidate [the metric's unit]
            with its interval (the medians' difference when unpaired).
        baseline_mean: the baseline's mean (how near the noise the percentage's divisor is).
        verdict: :func:`pipeline.analysis.verdict.compare` (test, p, equivalence).
    """

    n: int
    effect: MeanCI
    abs_diff: MeanCI
    baseline_mean: float | None
    verdict: Verdict


def _test(base: dict[int, float], cand: dict[int, float], metric: Metric) -> Effect:
    """The size (paired by seed when seeds pair, at least two, else unpaired) and the
    report's one rule (:func:`pipeline.analysis.verdict.compare`)."""
    lower_is_better, floor = metric.lower_is_better, metric.floor
    v = compare(base, cand, unit=metric.unit, lower_is_better=lower_is_better)
    sign = 1.0 if lower_is_better else -1.0
    common = sorted(set(base) & set(cand))
    if len(common) >= 2:
        b = [base[s] for s in common]
        c = [cand[s] for s in common]
        diffs = [sign * (x - y) for x, y in zip(b, c, strict=True)]
        red = [
            sign * (x - y) / abs(x) * 100.0 for x, y in zip(b, c, strict=True) if abs(x) >= floor
        ]
        n = len(common)
        return Effect(n, mean_ci(red), mean_ci(diffs), math.fsum(b) / n, v)
    bs, cs = list(base.values()), list(cand.values())
    n = min(len(bs), len(cs))
    if n == 0:
        return Effect(0, mean_ci([]), mean_ci([]), None, v)
    mb, mc = float(np.median(bs)), float(np.median(cs))
    effect = sign * (mb - mc) / abs(mb) * 100.0 if abs(mb) >= floor else None
    return Effect(n, mean_ci([effect]), mean_ci([sign * (mb - mc)]), mb, v)


WIN_LOSS_WORDS: dict[Outcome, str] = {
    "better": "wins",
    "worse": "loses",
    "no clear difference": "n.s.",
    "equivalent": "equivalent",
    "too few pairs": "too few pairs",
    "n/a": "n/a",
}
"""The rule's outcomes as a win/loss cell says them."""


def holm(p_values: list[float | None]) -> list[float | None]:
    """Holm's step-down adjusted p values of one family (None stays None: no test)."""
    order = sorted((p, k) for k, p in enumerate(p_values) if p is not None)
    m = len(order)
    out: list[float | None] = [None] * len(p_values)
    running = 0.0
    for rank, (p, k) in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p))
        out[k] = running
    return out


def win_loss(table: pl.DataFrame, *, baseline: str, metrics: tuple[str, ...]) -> pl.DataFrame:
    """Each candidate controller against ``baseline`` per condition, joint and metric.

    One method per question. The size: where both controllers ran the same seeds (at
    least two), the mean per-pair reduction (baseline − candidate) / baseline × 100 with
    its paired 95 % Student-t interval, and the mean absolute difference in the metric's
    unit beside it; else the reduction of the medians. The verdict: the report's one rule
    (:func:`pipeline.analysis.verdict.compare`: *equivalent* within the practical
    margin; a two-sided Wilcoxon signed-rank test, Mann-Whitney U when seeds do not pair,
    only from :data:`MIN_PAIRS` pairs, else "too few pairs"), its p Holm-corrected over
    the tests of one table (one metric and candidate: every joint and condition),
    ``tests`` says how many. ``verdict``: "wins" / "loses" / "n.s." / "equivalent" /
    "too few pairs" / "n/a" (:data:`WIN_LOSS_WORDS`).
    Columns :data:`WIN_LOSS_SCHEMA`.
    """
    ok = table.filter(pl.col("status") == "ok")
    rows: list[dict[str, Any]] = []
    verdicts: list[Verdict] = []
    controllers = sorted(set(ok.get_column("controller").to_list()) - {baseline})
    if baseline not in set(ok.get_column("controller").to_list()):
        return pl.DataFrame(schema=WIN_LOSS_SCHEMA)
    for (condition, joint), grp in ok.group_by("condition", "joint", maintain_order=True):
        for metric in metrics:
            if not BY_NAME[metric].applies_to(str(joint)):
                continue
            per: dict[str, dict[int, float]] = {}
            for r in grp.select("controller", "seed", metric).iter_rows():
                if r[2] is not None:
                    per.setdefault(r[0], {})[int(r[1])] = float(r[2])
            for cand in controllers:
                if cand not in per or baseline not in per:
                    continue
                e = _test(per[baseline], per[cand], BY_NAME[metric])
                verdicts.append(e.verdict)
                rows.append(
                    {
                        "condition": condition,
                        "candidate": cand,
                        "baseline": baseline,
                        "joint": joint,
                        "metric": metric,
                        "n": e.n,
                        "effect_pct": e.effect.mean,
                        "effect_ci95_half_width": e.effect.half_width,
                        "abs_diff": e.abs_diff.mean,
                        "abs_diff_ci95_half_width": e.abs_diff.half_width,
                        "baseline_mean": e.baseline_mean,
                        "test": e.verdict.test,
                        "p_value": e.verdict.p,
                    }
                )
    # Holm over each table's family (one metric and candidate: every joint and condition)
    families: dict[tuple[str, str], list[int]] = {}
    for k, row in enumerate(rows):
        families.setdefault((row["metric"], row["candidate"]), []).append(k)
    for members in families.values():
        adjusted = holm([verdicts[k].p for k in members])
        tests = sum(verdicts[k].p is not None for k in members)
        for k, p in zip(members, adjusted, strict=True):
            decided = verdicts[k].with_p(p)
            rows[k].update(
                p_holm=p,
                tests=tests,
                verdict=WIN_LOSS_WORDS[decided.outcome]
                if rows[k]["effect_pct"] is not None or decided.outcome == "equivalent"
                else "n/a",
                equivalence_margin=decided.margin,
            )
    out = pl.DataFrame(rows, schema=WIN_LOSS_SCHEMA, orient="row")
    return out.select(list(WIN_LOSS_SCHEMA)).sort(
        "metric", "candidate", "condition", "joint", maintain_order=True
    )


def condition_values(condition: str) -> dict[str, str]:
    """A condition key's swept values: ``payload_kg=0.5,goal=r1`` -> {label: text}."""
    out: dict[str, str] = {}
    for part in condition.split(",") if condition else []:
        key, _, value = part.partition("=")
        out[key] = value
    return out


def _stance(row: Mapping[str, Any]) -> str | None:
    """A win/loss row's answer: its verdict (tested, or equivalent), else the sign of its
    size (untested)."""
    verdict, effect = row["verdict"], row["effect_pct"]
    if verdict in ("wins", "loses", "n.s.", "equivalent"):
        return str(verdict)
    if verdict == "too few pairs" and isinstance(effect, float) and effect != 0:
        return "better (untested)" if effect > 0 else "worse (untested)"
    return None


FLIP_SCHEMA = {
    "assumption": pl.String,
    "metric": pl.String,
    "candidate": pl.String,
    "baseline": pl.String,
    "joint": pl.String,
    "others": pl.String,
    "answers": pl.String,
}


def verdict_flips(wl: pl.DataFrame) -> pl.DataFrame:
    """The verdicts of a win/loss table (:func:`win_loss`) that change within the swept
    range of one axis, the other axes held: one row per (axis, metric, candidate, joint,
    other axes' values), ``answers`` = ``value: answer`` per swept value.

    An answer is the tested verdict (wins / loses / n.s.); where there are too few pairs
    for a test, the sign of the size, marked untested. A row is a flip when two values of
    the axis give different answers. Columns :data:`FLIP_SCHEMA`.
    """
    rows: list[dict[str, Any]] = []
    parsed = [(condition_values(str(r["condition"] or "")), r) for r in wl.iter_rows(named=True)]
    labels = sorted({k for values, _ in parsed for k in values})
    for label in labels:
        groups: dict[tuple[Any, ...], dict[str, str]] = {}
        for values, r in parsed:
            if label not in values:
                continue
            stance = _stance(r)
            if stance is None:
                continue
            others = ",".join(f"{k}={v}" for k, v in values.items() if k != label)
            key = (r["metric"], r["candidate"], r["baseline"], r["joint"], others)
            groups.setdefault(key, {})[values[label]] = stance
        for (metric, cand, base, joint, others), answers in groups.items():
            if len(set(answers.values())) < 2:
                continue
            ordered = sorted(answers.items(), key=lambda kv: _as_number(kv[0]))
            rows.append(
                {
                    "assumption": label,
                    "metric": metric,
                    "candidate": cand,
                    "baseline": base,
                    "joint": joint,
                    "others": others,
                    "answers": "; ".join(f"{label}={v}: {a}" for v, a in ordered),
                }
            )
    return pl.DataFrame(rows, schema=FLIP_SCHEMA, orient="row")


def _as_number(text: str) -> tuple[float, str]:
    try:
        return (float(text), text)
    except ValueError:
        return (math.inf, text)


def by_parameter(table: pl.DataFrame, axis: str, metric: str) -> pl.DataFrame:
    """Mean and 95 % Student-t CI of ``metric`` per value of one swept ``axis``, controller
    and joint (completed episodes, every other axis pooled): ``value, controller, joint,
    n, mean, ci95_low, ci95_high``."""
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
