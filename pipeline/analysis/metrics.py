"""Tracking metrics per episode and joint, and reductions between controllers.

Definitions (also in docs/report.md and in every report):

- error e(t) = reference - measured position [rad], as the controller recorded it.
- max_abs_error = max |e| over the whole episode; rms_error = sqrt(mean e^2).
- final_error ("error at the target") = mean |e| over the last
  ``min(FINAL_WINDOW_S, hold/2)`` of the episode, hold = end - motion end
  (the last sample alone when there is no hold; the last FINAL_WINDOW_S when
  the motion end is unknown).
- settling_time = time from the motion end until |e| stays within
  ``SETTLING_TOLERANCE_RAD`` for the rest of the episode (the first sample after
  the last violation; 0 when |e| never leaves the band after the motion end);
  null when it never settles or the motion end is unknown.
- overshoot = how far the measured position passes the goal in the direction
  of travel (max over the episode, clipped at 0) [rad]; null for a joint that
  does not move.
- peak_velocity = the measured velocity with the largest magnitude, with its sign.
- rms_effort = sqrt(mean applied effort^2) [N m].
- saturation_fraction = share of samples where |applied effort| is at the
  joint's effort limit (within 1e-6 relative) or |commanded| exceeds |applied|.
- reduction % = (baseline - candidate) / baseline x 100; null when the
  baseline value is 0 or missing.
"""

from __future__ import annotations

from collections.abc import Sequence

import polars as pl

from pipeline.constants import FINAL_WINDOW_S
from pipeline.errors import ReportError

SETTLING_TOLERANCE_RAD = 1e-3
SATURATION_REL_TOL = 1e-6
MIN_TRAVEL_RAD = 1e-9

METRIC_COLUMNS = (
    "max_abs_error",
    "rms_error",
    "final_error",
    "settling_time",
    "overshoot",
    "peak_velocity",
    "peak_velocity_time",
    "rms_effort",
    "saturation_fraction",
)
COMPARED_METRICS = ("max_abs_error", "rms_error", "final_error")


def joint_metrics(
    samples: pl.DataFrame,
    episodes: pl.DataFrame,
    limits: pl.DataFrame | None = None,
    *,
    settling_tolerance_rad: float = SETTLING_TOLERANCE_RAD,
    final_window_s: float = FINAL_WINDOW_S,
) -> pl.DataFrame:
    """Metrics per episode and joint (columns ``episode``, ``joint``, :data:`METRIC_COLUMNS`).

    Args:
        samples: tidy samples (:data:`pipeline.log.reader.SAMPLE_COLUMNS`), time-sorted per
            episode and joint.
        episodes: :func:`pipeline.analysis.episodes.episode_table` (``motion_end_s``, ``end_s``).
        limits: ``episode, joint, effort_limit_nm`` (null where unknown); None = unknown.
        settling_tolerance_rad: band |e| must stay in to count as settled [rad].
        final_window_s: longest window at the end used for the final error [s].
    """
    if limits is None:
        limits = pl.DataFrame(
            schema={"episode": pl.String, "joint": pl.String, "effort_limit_nm": pl.Float64}
        )
    ep = episodes.select("episode", "motion_end_s", "end_s").with_columns(
        pl.when(pl.col("motion_end_s").is_null())
        .then(pl.lit(final_window_s))
        .otherwise(
            pl.min_horizontal(
                pl.lit(final_window_s),
                ((pl.col("end_s") - pl.col("motion_end_s")) / 2).clip(lower_bound=0.0),
            )
        )
        .alias("final_window_s")
    )
    key = ["episode", "joint"]
    e = pl.col("error_rad")
    t = pl.col("time_s")
    v = pl.col("velocity_rad_s")
    eff = pl.col("effort_nm")
    cmd = pl.col("commanded_effort_nm")
    limit = pl.col("effort_limit_nm")
    ref = pl.col("reference_position_rad")
    df = (
        samples.join(ep, on="episode", how="left")
        .join(limits, on=key, how="left")
        .with_columns(
            after_motion=(t >= pl.col("motion_end_s")),
            in_final=(t >= pl.col("end_s") - pl.col("final_window_s") - 1e-9),
            saturated=(
                (limit.is_not_null() & (eff.abs() >= limit * (1 - SATURATION_REL_TOL)))
                | (
                    cmd.is_not_null()
                    & cmd.is_not_nan()
                    & (cmd.abs() > eff.abs() * (1 + SATURATION_REL_TOL) + 1e-9)
                )
            ).fill_null(False),
        )
        .with_columns(
            violating=(pl.col("after_motion") & (e.abs() > settling_tolerance_rad)),
        )
        .with_columns(
            # True where this and every later sample of the group is within tolerance.
            settled=(pl.col("violating").cast(pl.Int8).reverse().cum_max().reverse().over(key) == 0)
        )
    )
    goal = ref.last()
    travel = goal - ref.first()
    direction = pl.when(travel > 0).then(1.0).otherwise(-1.0)
    peak = v.abs().arg_max()
    out = df.group_by(key, maintain_order=True).agg(
        max_abs_error=e.abs().max(),
        rms_error=(e * e).mean().sqrt(),
        final_error=e.abs().filter(pl.col("in_final")).mean(),
        settling_time=pl.when(pl.col("motion_end_s").first().is_null())
        .then(None)
        .when(~pl.col("violating").any())
        .then(0.0)
        .otherwise(
            t.filter(pl.col("after_motion") & pl.col("settled")).min()
            - pl.col("motion_end_s").first()
        ),
        overshoot=pl.when(travel.abs() > MIN_TRAVEL_RAD)
        .then(((pl.col("position_rad") - goal) * direction).max().clip(lower_bound=0.0))
        .otherwise(None),
        peak_velocity=v.get(peak),
        peak_velocity_time=t.get(peak),
        rms_effort=(eff * eff).mean().sqrt(),
        saturation_fraction=pl.col("saturated").cast(pl.Float64).mean(),
    )
    return out.select(*key, *METRIC_COLUMNS)


def check_baseline(episodes: pl.DataFrame, baseline: str) -> None:
    """Raise a one-line error when no episode ran the baseline controller."""
    present = sorted(set(episodes.get_column("controller").to_list()))
    if baseline not in present:
        raise ReportError(
            f"unknown baseline controller '{baseline}'; controllers in the recordings: "
            f"{', '.join(present) or 'none'} (choose one with --baseline)"
        )


def pairs(episodes: pl.DataFrame, *, baseline: str) -> list[tuple[str, str, str]]:
    """(scenario, baseline episode, candidate episode) for every comparable pair.

    Episodes pair within a scenario and robot; only "ok" episodes take part. When
    a scenario holds several baseline runs, a candidate pairs with the ones of
    its own seed if there are any, else with all of them.
    """
    ok = episodes.filter(pl.col("status") == "ok").sort("episode")
    out: list[tuple[str, str, str]] = []
    for (scenario, robot), group in ok.group_by(["scenario", "robot"], maintain_order=True):
        rows = group.to_dicts()
        bases = [r for r in rows if r["controller"] == baseline]
        for cand in (r for r in rows if r["controller"] != baseline):
            same_seed = [b for b in bases if b["seed"] == cand["seed"]]
            for b in same_seed or bases:
                out.append((str(scenario), b["episode"], cand["episode"]))
        del robot
    return sorted(out)


def reduction_pct(baseline: pl.Expr, candidate: pl.Expr) -> pl.Expr:
    """(baseline - candidate) / baseline x 100, null when the baseline is 0 or missing."""
    valid = baseline.is_not_null() & baseline.is_not_nan() & (baseline != 0)
    return pl.when(valid).then((baseline - candidate) / baseline * 100.0).otherwise(None)


def comparisons(
    metrics: pl.DataFrame,
    episodes: pl.DataFrame,
    *,
    baseline: str,
    compared: Sequence[str] = COMPARED_METRICS,
) -> pl.DataFrame:
    """One row per (pair, joint): baseline and candidate values and reduction % per metric."""
    schema: dict[str, pl.DataType | type[pl.DataType]] = {
        "scenario": pl.String,
        "baseline": pl.String,
        "candidate": pl.String,
    }
    pair_df = pl.DataFrame(pairs(episodes, baseline=baseline), schema=schema, orient="row")
    cols = ["joint", *compared]
    b = metrics.select("episode", *cols).rename({m: f"{m}_baseline" for m in compared})
    c = metrics.select("episode", *cols).rename({m: f"{m}_candidate" for m in compared})
    out = pair_df.join(b, left_on="baseline", right_on="episode", how="inner").join(
        c, left_on=["candidate", "joint"], right_on=["episode", "joint"], how="inner"
    )
    out = out.with_columns(
        [
            reduction_pct(pl.col(f"{m}_baseline"), pl.col(f"{m}_candidate")).alias(
                f"{m}_reduction_pct"
            )
            for m in compared
        ]
    )
    return out
