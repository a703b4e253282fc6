"""The mean of repeated values with its Student-t confidence interval: the one interval the
report states (:data:`CONFIDENCE`). Below :mod:`~pipeline.analysis.aggregate` and
:mod:`~pipeline.analysis.verdict`, which both use it."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, NamedTuple

CONFIDENCE = 0.95


class MeanCI(NamedTuple):
    """Mean of n values with a two-sided Student-t confidence interval.

    Attributes:
        n: finite values used.
        mean: their mean (None when n = 0).
        std: sample standard deviation, ddof = 1 (None when n < 2).
        half_width: t(1 - (1 - confidence) / 2, n - 1) * std / sqrt(n) (None when n < 2).
    """

    n: int
    mean: float | None
    std: float | None
    half_width: float | None

    @property
    def low(self) -> float | None:
        return None if self.mean is None or self.half_width is None else self.mean - self.half_width

    @property
    def high(self) -> float | None:
        return None if self.mean is None or self.half_width is None else self.mean + self.half_width


def mean_ci(values: Iterable[Any], *, confidence: float = CONFIDENCE) -> MeanCI:
    """Mean and Student-t confidence interval of the finite values (None/NaN skipped)."""
    xs = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    n = len(xs)
    if n == 0:
        return MeanCI(0, None, None, None)
    mean = math.fsum(xs) / n
    if n < 2:
        return MeanCI(n, mean, None, None)
    std = math.sqrt(math.fsum((x - mean) ** 2 for x in xs) / (n - 1))
    t = t_quantile(1.0 - (1.0 - confidence) / 2.0, n - 1)
    return MeanCI(n, mean, std, t * std / math.sqrt(n))


def t_quantile(q: float, df: int) -> float:
    """The ``q`` quantile of Student's t with ``df`` degrees of freedom: SciPy's
    ``special.stdtrit``, the function ``scipy.stats.t.ppf`` evaluates (the same bits), without
    importing ``scipy.stats`` (~1 s of a report's start; ``scipy.special`` ~0.4 s)."""
    from scipy import special  # loads when a statistic is asked for

    return float(special.stdtrit(df, q))
