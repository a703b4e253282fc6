"""Versus the paper: paired reductions and claim verdicts, decided in analysis/."""

from __future__ import annotations

from pipeline.analysis import paper_claims as paper
from pipeline.analysis.findings import DeadBandFinding
from pipeline.analysis.metrics import ERROR_FLOOR_RAD
from pipeline.analysis.verdict import MIN_PAIRS, compare


def test_a_claim_is_decided_by_the_reports_one_rule() -> None:
    """Tested only from MIN_PAIRS pairs; one pair keeps its sign, said as one pair."""

    def claim(base: list[float], cand: list[float]) -> paper.Verdict:
        return paper.verdict(compare(dict(enumerate(base)), dict(enumerate(cand)), unit="rad"))

    assert paper.verdict(None) == "n/a"
    assert claim([2e-3], [1e-3]) == "holds (one pair, no test)"
    assert claim([1e-3], [2e-3]) == "does not hold (one pair, no test)"
    assert claim([2e-3] * 3, [1e-3] * 3) == "too few pairs for a test"
    assert claim([2e-3] * MIN_PAIRS, [1e-3] * MIN_PAIRS) == "holds"
    assert claim([1e-3] * MIN_PAIRS, [2e-3] * MIN_PAIRS) == "does not hold"
    alternating = [1e-3 * (1.5 if k % 2 else 0.5) for k in range(8)]
    assert claim([1e-3] * 8, alternating) == "inconclusive"
    assert claim([0.28] * 3, [0.28 + 1e-6] * 3) == "equivalent"


def test_reduction_is_none_below_the_noise_floor_or_when_missing() -> None:
    assert paper.reduction_pct(2.0, 1.0, 2.0) == 50.0
    assert paper.reduction_pct(2.0, 1.0, 1.0) == 100.0
    assert paper.reduction_pct(1e-3, 0.0, ERROR_FLOOR_RAD / 2) is None
    assert paper.reduction_pct(None, 1.0, 1.0) is None


def test_the_papers_own_reductions_match_what_it_printed() -> None:
    # Table 3 prints (PID - CTC) / CTC; recomputing it from its own values agrees to 0.1 %.
    base = paper.PAPER_FINAL_ERROR_RAD[paper.PAPER_BASELINE]
    cand = paper.PAPER_FINAL_ERROR_RAD[paper.PAPER_CANDIDATE]
    for k, printed in enumerate(paper.PAPER_FINAL_ERROR_REDUCTION_PCT[:5]):
        assert abs(paper.reduction_pct(base[k], cand[k], cand[k]) - printed) < 0.1  # type: ignore[operator]


def test_an_empty_comparison_has_no_joint_values() -> None:
    cmp = paper.PaperComparison("paper", None)
    assert not cmp.pairs
    assert cmp.at("max_abs_error", 0) == paper.JointComparison()
    assert cmp.claim_verdicts("max_abs_error") == {}


def test_dead_band_is_friction_over_stiffness() -> None:
    f = DeadBandFinding("e", "j", "pid", stiffness_nm_per_rad=200.0, friction_nm=1.0)
    assert f.width_rad == 0.005


def test_an_unsettled_error_at_the_target_gives_no_verdict() -> None:
    base = {s: 1.0 + 0.01 * s for s in range(MIN_PAIRS + 2)}
    cand = {s: 0.5 + 0.01 * s for s in range(MIN_PAIRS + 2)}
    clear = compare(base, cand, unit="rad", lower_is_better=True)
    assert paper.JointComparison(rule=clear).verdict == "holds"
    assert paper.JointComparison(rule=clear, settled=False).verdict == "not settled"


def test_without_a_recorded_hold_flag_the_drift_decides_settled() -> None:
    # 1.6e-4 rad still falling by 20 % across the final window: a transient
    moving = {"final_error": 1.6e-4, "final_drift": -3.2e-5}
    steady = {"final_error": 1.6e-4, "final_drift": -1e-9}
    assert not paper.final_error_settled("e", "j", None, moving)
    assert paper.final_error_settled("e", "j", None, steady)
    assert paper.final_error_settled("e", "j", None, {})  # n/a: nothing to flag
