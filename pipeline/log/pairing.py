"""Pairing a recording's topics by stamp, and the tidy frames the pairs make.

The whole read (:mod:`pipeline.log.whole`) pairs a recording's rows at once; the windowed
read (:mod:`pipeline.log.windowed`) pairs a window's rows with the whole recording's
period, so both give the same pairs.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline.log.recording import F64

__all__ = ["error_feedback", "match_stamps", "paired_at", "stamp_period_ns", "tidy"]


def match_stamps(
    js_t: NDArray[np.int64], cs_t: NDArray[np.int64], *, period_ns: float | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Row pairs (joint_states, controller_state) at the same instant (nearest, < half a period).

    ``period_ns``: the ``js_t`` period (default: the median step of ``js_t``); a windowed
    read passes the whole recording's, so a window pairs rows as the whole read does.
    """
    if js_t.shape == cs_t.shape and np.array_equal(js_t, cs_t):
        idx = np.arange(js_t.size)
        return idx, idx
    if cs_t.size == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    period = period_ns if period_ns is not None else stamp_period_ns(js_t)
    j = np.searchsorted(cs_t, js_t).clip(1, max(cs_t.size - 1, 1))
    left = (j - 1).clip(0, cs_t.size - 1)
    right = j.clip(0, cs_t.size - 1)
    pick = np.where(np.abs(cs_t[left] - js_t) <= np.abs(cs_t[right] - js_t), left, right)
    ok = np.abs(cs_t[pick] - js_t) <= period / 2
    return np.flatnonzero(ok), pick[ok]


def stamp_period_ns(stamps: NDArray[np.int64]) -> float:
    """Median step of sorted ``stamps`` [ns] (1.0 for fewer than two)."""
    return float(np.median(np.diff(stamps))) if stamps.size > 1 else 1.0


def tidy(
    stamps: NDArray[np.int64],
    columns: dict[str, F64],
    *,
    names: tuple[str, ...],
    t0_ns: int,
    episode: str,
) -> pl.DataFrame:
    """A tidy frame: one row per stamp and joint, ``time_s`` from ``t0_ns``, NaN -> null."""
    n = len(names)
    m = stamps.size
    frame = pl.DataFrame(
        {
            "stamp_ns": np.repeat(stamps, n),
            "time_s": np.repeat((stamps - t0_ns).astype(np.float64) * 1e-9, n),
            "joint": pl.Series("joint", names, dtype=pl.String).gather(
                np.tile(np.arange(n, dtype=np.int64), m)
            ),
            **{k: np.ascontiguousarray(v).reshape(-1) for k, v in columns.items()},
        }
    )
    return frame.select(
        pl.lit(episode, dtype=pl.String).alias("episode"),
        pl.col("stamp_ns", "time_s", "joint"),
        pl.col(*columns).fill_nan(None),
    )


def error_feedback(cs: dict[str, F64]) -> tuple[F64, F64]:
    """error = reference - feedback: whichever of the two the controller left out."""
    error = np.where(
        np.isnan(cs["error"]), cs["reference_position"] - cs["feedback_position"], cs["error"]
    )
    feedback = np.where(
        np.isnan(cs["feedback_position"]), cs["reference_position"] - error, cs["feedback_position"]
    )
    return error, feedback


def paired_at(
    cs_t: NDArray[np.int64],
    found: tuple[NDArray[np.int64], dict[str, F64]] | None,
    perm: list[int],
    columns: Mapping[str, str],
    like: F64,
    *,
    period_ns: float | None = None,
) -> tuple[dict[str, F64], NDArray[np.intp]]:
    """A paired topic's ``columns`` (column -> its array's key) at each controller-state
    row (NaN where none), and the rows that have one."""
    out = {c: np.full_like(like, np.nan) for c in columns}
    if found is None:
        return out, np.zeros(0, dtype=np.intp)
    t, arrays = found
    rows_cs, rows = match_stamps(cs_t, t, period_ns=period_ns)
    for column, key in columns.items():
        out[column][rows_cs] = arrays[key][rows][:, perm]
    return out, rows_cs
