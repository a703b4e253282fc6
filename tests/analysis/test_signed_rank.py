"""The report's own signed-rank p and Student-t quantile against scipy.stats: the same
bits, so metrics.json does not move when the report skips importing scipy.stats."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from pipeline.analysis.intervals import mean_ci, t_quantile
from pipeline.analysis.verdict import EXACT_MAX_PAIRS, signed_rank_p


@pytest.mark.parametrize("n", [6, 7, 13, 14, 30, EXACT_MAX_PAIRS, EXACT_MAX_PAIRS + 1, 120])
def test_signed_rank_p_is_scipys_wilcoxon_bit_for_bit(n: int) -> None:
    rng = np.random.default_rng(n)
    for shift in (0.0, 0.3, 1.5, -0.8):
        for _ in range(20):
            diffs = [float(x) for x in rng.normal(shift, 1.0, n)]
            assert signed_rank_p(diffs) == float(stats.wilcoxon(diffs).pvalue)


@pytest.mark.parametrize("n", [6, 20, 60])
def test_one_sided_extremes_match_scipy(n: int) -> None:
    up = [float(k) + 0.5 for k in range(n)]
    down = [-x for x in up]
    for diffs in (up, down, [*up[:-1], -up[-1]], [-up[0], *up[1:]]):
        assert signed_rank_p(diffs) == float(stats.wilcoxon(diffs).pvalue)
    if n == 6:
        assert signed_rank_p(up) == pytest.approx(2 / 2**6)  # the smallest exact p at n = 6


def test_zeros_and_ties_take_scipys_own_paths() -> None:
    zero = [0.0, 1.0, -2.0, 3.0, 4.0, 5.0, 6.5]
    tied = [1.0, -1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
    tied_many = [float(k % 7) + 1.0 for k in range(40)]
    for diffs in (zero, tied, tied_many):
        assert signed_rank_p(diffs) == float(stats.wilcoxon(diffs).pvalue)


def test_t_quantile_is_scipys_t_ppf_bit_for_bit() -> None:
    for df in [*range(1, 200), 500, 1000, 10_000]:
        for q in (0.95, 0.975, 0.995, 0.5, 0.9):
            assert t_quantile(q, df) == float(stats.t.ppf(q, df))


def test_mean_ci_half_width_is_the_two_sided_95_percent_t_interval() -> None:
    ci = mean_ci([1.0, 2.0, 4.0])
    assert ci.half_width == pytest.approx(4.302652729749464 * ci.std / 3**0.5, rel=1e-12)
