"""One verdict rule per report (issue 28): the Verdicts sentence, the win/loss cells and the
paper's claims are all decided by :func:`pipeline.analysis.verdict.compare`; below
MIN_PAIRS pairs none of them shows a verdict from a test, and a difference within the
practical margin is *equivalent*, never higher or lower."""

from __future__ import annotations

import re
from pathlib import Path

import polars as pl
import pytest

from pipeline.analysis import catalog
from pipeline.analysis import headline as summary
from pipeline.analysis import paper_claims as paper
from pipeline.analysis.aggregate import reduction_aggregates
from pipeline.analysis.campaign_tables import WIN_LOSS_WORDS, win_loss
from pipeline.analysis.metrics import comparisons
from pipeline.analysis.verdict import (
    ENCODER_RESOLUTION_RAD,
    EQUIVALENCE_REL,
    MIN_PAIRS,
    compare,
    equivalence_margin,
)
from pipeline.stages.report import run_report
from tests.report.campaignfactory import campaign_episodes, table_frame, table_row, write_campaign


@pytest.mark.parametrize("n", [1, 3, MIN_PAIRS, 20])
def test_a_microradian_difference_on_a_joint_that_never_moved_is_equivalent(n: int) -> None:
    base = {s: 0.28 + 1e-9 * s for s in range(n)}
    cand = {s: v + 1e-6 for s, v in base.items()}
    v = compare(base, cand, unit="rad")
    assert v.outcome == "equivalent"
    assert v.margin == pytest.approx(EQUIVALENCE_REL * 0.28, rel=1e-6)
    # near zero the encoder's resolution is the margin, not 2 % of nothing
    assert equivalence_margin("rad", 1e-7) == ENCODER_RESOLUTION_RAD
    tiny = compare({s: 1e-7 for s in range(n)}, {s: 2e-6 for s in range(n)}, unit="rad")
    assert tiny.outcome == "equivalent"


def test_every_compared_error_has_a_resolution_in_its_own_unit() -> None:
    # the margin's floor is looked up by the catalog's unit: a unit missing from the table
    # would judge a TCP difference against 2 % of its mean alone
    for m in (catalog.metric(name) for name in catalog.COMPARED_METRICS):
        if m.name.endswith("_error"):
            assert equivalence_margin(m.unit, 0.0) > 0.0, m.name
    assert equivalence_margin("mm", 0.0) == pytest.approx(1e3 * ENCODER_RESOLUTION_RAD)
    assert equivalence_margin("mrad", 0.0) == pytest.approx(1e3 * ENCODER_RESOLUTION_RAD)
    tiny = compare({s: 1e-4 for s in range(6)}, {s: 4e-3 for s in range(6)}, unit="mm")
    assert tiny.outcome == "equivalent"  # 4 um at the flange: below a 1 m reach's step


def test_a_real_difference_is_tested_only_from_the_minimum_pairs() -> None:
    for n in range(1, MIN_PAIRS):
        v = compare({s: 2e-3 for s in range(n)}, {s: 1e-3 for s in range(n)}, unit="rad")
        assert (v.outcome, v.p) == ("too few pairs", None)
        assert v.untested_sign == "better (untested)"
    v = compare(
        {s: 2e-3 for s in range(MIN_PAIRS)}, {s: 1e-3 for s in range(MIN_PAIRS)}, unit="rad"
    )
    assert v.outcome == "better" and v.p is not None and v.p < 0.05
    # a difference beyond the margin on some pairs, within noise overall: tested, not "equal"
    mixed = compare(
        {s: 1e-3 for s in range(8)},
        {s: 1e-3 * (1.5 if s % 2 else 0.5) for s in range(8)},
        unit="rad",
    )
    assert mixed.outcome == "no clear difference"


def test_the_paper_claim_of_one_pair_says_it_is_one_pair_without_a_test() -> None:
    assert paper.verdict(compare({0: 2e-3}, {0: 1e-3}, unit="rad")) == "holds (one pair, no test)"
    three = compare({s: 2e-3 for s in range(3)}, {s: 1e-3 for s in range(3)}, unit="rad")
    assert paper.verdict(three) == "too few pairs for a test"
    assert paper.verdict(None) == "n/a"


def _campaign_table(pairs: int) -> pl.DataFrame:
    """j1: the candidate halves the error; j2: it doubles it; j3: 1e-6 rad apart on 0.28 rad."""
    rows = []
    for seed in range(pairs):
        jitter = 1 + 0.01 * seed
        for controller, values in (
            ("pid", (2e-3 * jitter, 1e-3 * jitter, 0.28)),
            ("ctc", (1e-3 * jitter, 2e-3 * jitter, 0.28 + 1e-6)),
        ):
            for joint, value in zip(("j1", "j2", "j3"), values, strict=True):
                rows.append(table_row("a", controller, seed, joint, value))
    return table_frame(rows)


@pytest.mark.parametrize("pairs", [3, 8])
def test_win_loss_and_the_verdicts_agree_on_a_constructed_campaign(pairs: int) -> None:
    table = _campaign_table(pairs)
    wl = win_loss(table, baseline="pid", metrics=("max_abs_error",))
    cells = dict(zip(wl["joint"].to_list(), wl["verdict"].to_list(), strict=True))
    # the same values through the Verdicts' path (comparisons -> reduction_aggregates)
    episodes = (
        table.select("episode", "controller", "seed", "status")
        .unique("episode", maintain_order=True)
        .with_columns(scenario=pl.lit("a"), group=pl.lit("a"), robot=pl.lit("ur5"))
    )
    metrics = table.select("episode", "joint", *catalog.COMPARED_METRICS)
    comp = comparisons(metrics, episodes, baseline="pid")
    (q,) = summary.questions(reduction_aggregates(comp, episodes), {"a": ["j1", "j2", "j3"]})
    directions = {e.joint: e.direction for e in q.joint_space}
    expected = (
        {"j1": "wins", "j2": "loses", "j3": "equivalent"}
        if pairs >= MIN_PAIRS
        else {"j1": "too few pairs", "j2": "too few pairs", "j3": "equivalent"}
    )
    assert cells == expected
    as_direction = {
        "wins": "lower",
        "loses": "higher",
        "equivalent": "equivalent",
        "too few pairs": None,
    }
    for joint, cell in cells.items():
        want = as_direction[cell]
        if want is None:  # too few pairs: the sign only, marked untested
            assert directions[joint].endswith("(untested)")
        else:
            assert directions[joint] == want
    assert set(WIN_LOSS_WORDS.values()) >= set(cells.values())


_TESTED = re.compile(
    r"\*\*(wins|loses)\*\* [-+\d]|Holm p =|\| n\.s\. |"
    r"(?<![*(])\b(lower|higher) on joint|no clear difference on joint|"
    r"\| (holds|does not hold|inconclusive)(?! \(one pair)|"
    r"(?<!\*)(holds|does not hold|inconclusive) on joint"
)


def _report(root: Path, seeds: int) -> str:
    episodes = campaign_episodes("sweep", seeds=seeds, payloads=(0.0,))
    for ep in episodes:
        ep.reproduces_paper = True  # the paper's claims appear on the same page
    write_campaign(root / "recordings", episodes)
    run_report(recordings_dir=root / "recordings", out_dir=root / "reports", baseline="pid")
    return (root / "reports" / "report.md").read_text(encoding="utf-8")


@pytest.mark.slow
def test_at_three_pairs_report_md_shows_no_verdict_from_a_test_anywhere(tmp_path: Path) -> None:
    text = _report(tmp_path, seeds=3)
    assert "### Verdicts" in text and "Win/loss" in text and "paper's claims here" in text
    found = [m.group(0) for m in _TESTED.finditer(text)]
    assert found == [], found
    verdict = next(line for line in text.splitlines() if line.startswith("- **ctc vs pid**"))
    assert "too few pairs for a test" in verdict
    assert "equivalent on joint 6" in verdict  # joint 6 never moved: both ~1e-7 rad
    assert "too few pairs for a test" in text.split("paper's claims here", 1)[1]
    # the margin's figures are stated where the rule is, in the Verdicts and the win/loss
    stated = f"{ENCODER_RESOLUTION_RAD:.1e} rad at a joint and, at the TCP, 6.0e-03 mm"
    rule_lines = [line for line in text.splitlines() if "within the practical margin" in line]
    win_loss = [line for line in rule_lines if line.startswith("Each cell, the size")]
    verdicts = [line for line in rule_lines if line.startswith("Does the candidate")]
    assert win_loss and verdicts
    assert all(stated in line for line in win_loss + verdicts), rule_lines
