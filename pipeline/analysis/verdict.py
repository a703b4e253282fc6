"""The one rule that decides every candidate-vs-baseline comparison of a report.

The Verdicts sentence (:mod:`pipeline.analysis.headline`), the campaign win/loss cells
(:func:`pipeline.analysis.campaign_tables.win_loss`, and the flips drawn from them) and the
paper's claims (:mod:`pipeline.analysis.paper_claims`) all call :func:`compare`, so one page
cannot hold two rules (issue 28):

1. **Equivalent** (practical equivalence, TOST-style): the difference is within the
   margin :func:`equivalence_margin`, the larger of the quantity's resolution
   (:data:`RESOLUTION_BY_UNIT`: a 20-bit joint encoder's step) and
   :data:`EQUIVALENCE_REL` of the baseline's mean. Every pair within it (any n), or, with
   :data:`MIN_PAIRS` pairs or more, the 90 % Student-t interval of the mean difference
   within it (two one-sided tests at 5 %).
2. **A test** of the sign only with :data:`MIN_PAIRS` pairs or more: the two-sided exact
   Wilcoxon signed-rank test of the per-seed differences (Mann-Whitney U when the runs do
   not share seeds: with at least :data:`MIN_PAIRS` runs each), p < :data:`ALPHA` (Holm-
   corrected where a table tests a family: :meth:`Verdict.with_p`): *better* / *worse*,
   else *no clear difference*.
3. **Too few pairs** below that: no verdict from a test anywhere; the sign of the mean
   difference may be shown, marked untested (one pair: the sign of one run).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.analysis.intervals import mean_ci

ALPHA = 0.05
MIN_PAIRS = 6
"""The fewest pairs at which the two-sided exact signed-rank test can reach p < ALPHA
(2 / 2^n < 0.05 from n = 6); also the fewest runs per side for the unpaired test."""
EQUIVALENCE_REL = 0.02
"""Practical-equivalence margin as a fraction of the baseline's mean (2 %)."""
ENCODER_RESOLUTION_RAD = 2.0 * math.pi / 2**20
"""A 20-bit absolute joint encoder's step, 6.0e-6 rad (UR e-Series, Franka: 19-20 bits)."""
RESOLUTION_BY_UNIT = {
    "rad": ENCODER_RESOLUTION_RAD,
    "mrad": 1e3 * ENCODER_RESOLUTION_RAD,
    "m": 1.0 * ENCODER_RESOLUTION_RAD,
    "mm": 1e3 * ENCODER_RESOLUTION_RAD,
}
"""The smallest difference of a quantity that is resolved [its unit]: a joint angle's,
at the TCP the encoder step as an orientation and times 1 m of reach as a position, in
the units the catalog's metrics are in (``mrad``, ``mm``)."""

WILCOXON = "Wilcoxon signed-rank (paired by seed)"
MANN_WHITNEY = "Mann-Whitney U (unpaired: seeds do not pair)"
TOO_FEW = "too few pairs for a test"

Outcome = Literal["better", "worse", "no clear difference", "equivalent", "too few pairs", "n/a"]
TESTED: tuple[Outcome, ...] = ("better", "worse", "no clear difference")


def resolution_text() -> str:
    """The resolutions of :data:`RESOLUTION_BY_UNIT` as a report states them ("6.0e-06 rad
    at a joint and, at the TCP, ..."): one wording for every sentence giving the rule."""
    r = RESOLUTION_BY_UNIT
    return (
        f"{r['rad']:.1e} rad at a joint and, at the TCP, {r['mm']:.1e} mm and "
        f"{r['mrad']:.1e} mrad (1 m of reach)"
    )


def equivalence_margin(unit: str, baseline_mean: float | None) -> float:
    """The practical-equivalence margin [the metric's unit]: the larger of the unit's
    resolution (0 for a unit without one) and :data:`EQUIVALENCE_REL` x |baseline mean|."""
    rel = EQUIVALENCE_REL * abs(baseline_mean) if baseline_mean is not None else 0.0
    return max(RESOLUTION_BY_UNIT.get(unit, 0.0), rel)


@dataclass(frozen=True)
class Verdict:
    """One comparison decided by the rule.

    Attributes:
        outcome: see the module docstring; *better* means the candidate is better (lower
            where lower is better).
        n: pairs (paired) or the smaller side's runs (unpaired).
        paired: whether the runs pair by seed.
        test: :data:`WILCOXON`, :data:`MANN_WHITNEY` or :data:`TOO_FEW`.
        p: the test's two-sided p (None without a test).
        margin: the equivalence margin [the metric's unit].
        mean_diff: mean improvement (baseline - candidate, sign-adjusted: > 0 = the
            candidate better) [the metric's unit]; the medians' difference when unpaired.
        equivalent: whether the difference is within the margin.
    """

    outcome: Outcome
    n: int
    paired: bool
    test: str
    p: float | None
    margin: float
    mean_diff: float | None
    equivalent: bool

    def with_p(self, p: float | None) -> Verdict:
        """The verdict with a corrected p (Holm over a table's family)."""
        return replace(self, p=p, outcome=_decide(self.equivalent, self.test, p, self.mean_diff))

    @property
    def untested_sign(self) -> str | None:
        """``better (untested)`` / ``worse (untested)`` when too few pairs, else None."""
        if self.outcome != "too few pairs" or not self.mean_diff:
            return None
        return "better (untested)" if self.mean_diff > 0 else "worse (untested)"


def _decide(equivalent: bool, test: str, p: float | None, mean_diff: float | None) -> Outcome:
    if mean_diff is None:
        return "n/a"
    if equivalent:
        return "equivalent"
    if test == TOO_FEW or p is None:
        return "too few pairs"
    if p < ALPHA:
        return "better" if mean_diff > 0 else "worse" if mean_diff < 0 else "no clear difference"
    return "no clear difference"


def compare(
    base: Mapping[Any, float | None],
    cand: Mapping[Any, float | None],
    *,
    unit: str,
    lower_is_better: bool = True,
) -> Verdict:
    """Decide candidate vs baseline: values keyed by seed (equal keys pair; with fewer
    than two common keys the runs are compared unpaired). None/NaN values are dropped."""
    b = {k: float(v) for k, v in base.items() if v is not None and math.isfinite(float(v))}
    c = {k: float(v) for k, v in cand.items() if v is not None and math.isfinite(float(v))}
    sign = 1.0 if lower_is_better else -1.0
    common = [k for k in b if k in c]
    if len(common) >= 2 or (len(common) == 1 and len(b) == len(c) == 1):
        diffs = [sign * (b[k] - c[k]) for k in common]
        n = len(diffs)
        margin = equivalence_margin(unit, math.fsum(b[k] for k in common) / n)
        mean = math.fsum(diffs) / n
        equivalent = all(abs(d) < margin for d in diffs) or (
            n >= MIN_PAIRS and _tost(diffs, margin)
        )
        if n < MIN_PAIRS:
            return _verdict(equivalent, TOO_FEW, None, n, True, margin, mean)
        p = 1.0 if all(d == 0 for d in diffs) else signed_rank_p(diffs)
        return _verdict(equivalent, WILCOXON, p, n, True, margin, mean)
    bs, cs = list(b.values()), list(c.values())
    n = min(len(bs), len(cs))
    if n == 0:
        return Verdict("n/a", 0, False, TOO_FEW, None, 0.0, None, False)
    mb, mc = _median(bs), _median(cs)
    margin = equivalence_margin(unit, mb)
    diff = sign * (mb - mc)
    equivalent = all(abs(x - y) < margin for x in bs for y in cs)
    if n < MIN_PAIRS:
        return _verdict(equivalent, TOO_FEW, None, n, False, margin, diff)
    from scipy import stats

    p = float(stats.mannwhitneyu(bs, cs, alternative="two-sided").pvalue)
    return _verdict(equivalent, MANN_WHITNEY, p, n, False, margin, diff)


def _verdict(
    equivalent: bool, test: str, p: float | None, n: int, paired: bool, margin: float, diff: float
) -> Verdict:
    return Verdict(_decide(equivalent, test, p, diff), n, paired, test, p, margin, diff, equivalent)


def _tost(diffs: list[float], margin: float) -> bool:
    """Two one-sided t tests at ALPHA: the 1 - 2 ALPHA interval of the mean difference
    lies within (-margin, margin)."""
    ci = mean_ci(diffs, confidence=1.0 - 2.0 * ALPHA)
    if ci.mean is None or ci.half_width is None:
        return False
    return -margin < ci.mean - ci.half_width and ci.mean + ci.half_width < margin


# scipy.stats.wilcoxon's method="auto": the exact null distribution up to this many
# differences, the normal approximation above.
EXACT_MAX_PAIRS = 50


def signed_rank_p(diffs: list[float]) -> float:
    """Two-sided p of the Wilcoxon signed-rank test of ``diffs`` (finite, not all zero):
    ``scipy.stats.wilcoxon(diffs).pvalue``, the same bits.

    Without zeros or tied magnitudes (measured floats: the usual case) it is computed here
    with SciPy's own arithmetic: the exact null distribution of the positive rank sum
    (:func:`_signed_rank_pmf`) up to :data:`EXACT_MAX_PAIRS` differences, the normal
    approximation above. That spares a report the import of ``scipy.stats`` (~1 s of its
    start). Zeros or ties take SciPy's other paths (a permutation test for a few
    differences, tie-corrected otherwise), so SciPy computes those."""
    n = len(diffs)
    order = sorted(range(n), key=lambda i: abs(diffs[i]))
    magnitudes = [abs(diffs[i]) for i in order]
    if magnitudes[0] == 0.0 or any(a == b for a, b in itertools.pairwise(magnitudes)):
        from scipy import stats

        return float(stats.wilcoxon(diffs).pvalue)
    # ranks 1..n of |d|; the sum of the positive differences' ranks (an integer)
    r_plus = sum(rank for rank, i in enumerate(order, start=1) if diffs[i] > 0)
    if n > EXACT_MAX_PAIRS:
        from scipy import special

        count = float(n)
        mean = count * (count + 1.0) * 0.25
        se = math.sqrt(count * (count + 1.0) * (2.0 * count + 1.0) / 24)
        return float(2 * special.ndtr(-abs((r_plus - mean) / se)))
    pmf = _signed_rank_pmf(n)
    mean = n * (n + 1) / 4
    sf = pmf[r_plus:].sum() if r_plus <= mean else 1 - pmf[:r_plus].sum()
    cdf = pmf[: r_plus + 1].sum() if r_plus <= mean else 1 - pmf[r_plus + 1 :].sum()
    return float(min(max(2 * min(sf, cdf), 0.0), 1.0))


@functools.cache
def _signed_rank_pmf(n: int) -> NDArray[np.float64]:
    """P(positive rank sum = r), r = 0 .. n(n + 1)/2, under the null, for n differences
    without ties: SciPy's recursion (``scipy.stats._hypotests._get_wilcoxon_distr``), each
    rank in or out with probability 1/2."""
    c = np.ones(1, dtype=np.float64)
    for k in range(1, n + 1):
        prev = c
        c = np.zeros(k * (k + 1) // 2 + 1, dtype=np.float64)
        m = len(prev)
        c[:m] = prev * 0.5
        c[-m:] += prev * 0.5
    return c


def _median(xs: list[float]) -> float:
    s = sorted(xs)
    k = len(s) // 2
    return s[k] if len(s) % 2 else 0.5 * (s[k - 1] + s[k])
