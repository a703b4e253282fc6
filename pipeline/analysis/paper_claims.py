"""The paper's published numbers, in one place, with where each comes from, and our
runs put beside them (pairs, paired reductions, whether each claim holds).

Source: the journal paper reproduced here (``shared/seeds/000_cd5ffea3b5428791.txt``,
UR5 under ROS: default effort PID vs computed-torque control, planned with
RRTConnect, simulated in Gazebo), section 4.3 "experimental results":

- Fig. 6 text: joint 1 maximum tracking error CTC e1 = 1.81E-3 rad,
  PID e2 = 3.348E-3 rad, "reduced by 45.9 %" = (PID - CTC) / PID.
- Table 3: joint error at the target position, x1e-5 rad, joints 1..6, and the
  printed reduction per joint, which is (PID - CTC) / CTC.
- Conclusion 2): peak joint velocities, CTC joint 4 -2.30 rad/s, joint 1
  -0.30 rad/s; PID joint 4 -0.83 rad/s, joint 1 -0.21 rad/s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import polars as pl

from pipeline.analysis.aggregate import MeanCI, mean_ci
from pipeline.analysis.catalog import BY_NAME, DRIFT_FLOOR_RAD, FINAL_DRIFT_REL
from pipeline.analysis.findings import nominal_plant
from pipeline.analysis.metrics import ERROR_FLOOR_RAD, pairs
from pipeline.analysis.protocol import ProtocolView
from pipeline.analysis.verdict import Outcome, compare
from pipeline.analysis.verdict import Verdict as RuleVerdict
from pipeline.log.reader import Recording

PAPER_CITATION = (
    'Wang Hao, Fan Pingqing, Wang Yansong, Li Cong, "基于ROS平台的机械臂精确控制研究" '
    "(Research on precise control of a manipulator based on ROS), Shanghai University of "
    "Engineering Science, 2019"
)
PAPER_SOURCE = (
    f"{PAPER_CITATION}; section 4.3 (UR5, ROS PID vs CTC): Fig. 6 text, Table 3, conclusion 2)"
)

PAPER_BASELINE = "pid"
PAPER_CANDIDATE = "ctc"

# Fig. 6 text: joint 1 maximum tracking error [rad].
PAPER_JOINT1_MAX_ERROR_RAD = {"ctc": 1.81e-3, "pid": 3.348e-3}
# Printed "45.9 %": (PID - CTC) / PID x 100.
PAPER_JOINT1_MAX_ERROR_REDUCTION_PCT = 45.9

# Table 3: error at the target position [rad] (printed x1e-5), joints 1..6.
PAPER_FINAL_ERROR_RAD = {
    "ctc": (4.2397e-5, 2.3842e-5, 2.8337e-5, 5.0445e-5, 5.9948e-5, 0.0),
    "pid": (6.2498e-5, 4.6516e-5, 4.7873e-5, 6.2799e-5, 8.8528e-5, 0.0),
}
# Table 3's printed reduction [%]: (PID - CTC) / CTC x 100.
PAPER_FINAL_ERROR_REDUCTION_PCT = (47.4, 95.1, 68.9, 24.5, 47.6, 0.0)

# Conclusion 2): peak joint velocity [rad/s] by joint number (1-based).
PAPER_PEAK_VELOCITY_RAD_S = {
    "ctc": {1: -0.30, 4: -2.30},
    "pid": {1: -0.21, 4: -0.83},
}
# The paper's claims are about joints 1-5.
PAPER_CLAIM_JOINTS = 5
# The metrics put beside the paper's.
PAPER_METRICS = ("max_abs_error", "final_error", "peak_velocity")


def reduction_pct(base: Any, cand: Any, by: Any) -> float | None:
    """(base - cand) / by x 100; None when a value is missing or |by| is below
    :data:`pipeline.analysis.metrics.ERROR_FLOOR_RAD` (numerical noise)."""
    if base is None or cand is None or by is None or abs(float(by)) < ERROR_FLOOR_RAD:
        return None
    return (float(base) - float(cand)) / float(by) * 100.0


# The paper's joint-1 reduction in Table 3's convention, (PID - CTC) / CTC x 100.
PAPER_JOINT1_MAX_ERROR_REDUCTION_BY_CANDIDATE_PCT = reduction_pct(
    PAPER_JOINT1_MAX_ERROR_RAD[PAPER_BASELINE],
    PAPER_JOINT1_MAX_ERROR_RAD[PAPER_CANDIDATE],
    PAPER_JOINT1_MAX_ERROR_RAD[PAPER_CANDIDATE],
)
# Table 3 recomputed in the joint-1 figure's convention, (PID - CTC) / PID x 100.
PAPER_FINAL_ERROR_REDUCTION_BY_BASELINE_PCT = tuple(
    reduction_pct(b, c, b)
    for b, c in zip(
        PAPER_FINAL_ERROR_RAD[PAPER_BASELINE], PAPER_FINAL_ERROR_RAD[PAPER_CANDIDATE], strict=True
    )
)

Verdict = Literal[
    "holds",
    "does not hold",
    "inconclusive",
    "equivalent",
    "holds (one pair, no test)",
    "does not hold (one pair, no test)",
    "too few pairs for a test",
    "n/a",
    "not settled",
]
"""A claim "the candidate is below the baseline" by the report's one rule
(:func:`pipeline.analysis.verdict.compare`): tested (holds, does not hold,
inconclusive) from :data:`pipeline.analysis.verdict.MIN_PAIRS` pairs; *equivalent*
within the practical margin; the single (deterministic) pair's sign said as one pair
without a test; else too few pairs for a test; *not settled* when a run's error at the
target is not a steady state (no verdict from it)."""


def verdict(rule: RuleVerdict | None) -> Verdict:
    """The paper-claim wording of the report's one rule's verdict."""
    if rule is None or rule.outcome == "n/a":
        return "n/a"
    if rule.outcome == "too few pairs":
        if rule.n == 1 and rule.mean_diff:
            return (
                "holds (one pair, no test)"
                if rule.mean_diff > 0
                else "does not hold (one pair, no test)"
            )
        return "too few pairs for a test"
    return _CLAIM_WORDS[rule.outcome]


_CLAIM_WORDS: dict[Outcome, Verdict] = {
    "better": "holds",
    "worse": "does not hold",
    "no clear difference": "inconclusive",
    "equivalent": "equivalent",
}


_EMPTY = MeanCI(0, None, None, None)


@dataclass(frozen=True)
class JointComparison:
    """One metric on one joint over the paired runs.

    Attributes:
        baseline: mean ± CI over the baseline runs.
        candidate: mean ± CI over the candidate runs.
        by_baseline: (baseline - candidate) / baseline x 100 of each pair, summarised.
        by_candidate: (baseline - candidate) / candidate x 100 of each pair, summarised.
        rule: the report's one rule on the pairs' values
            (:func:`pipeline.analysis.verdict.compare`).
        settled: every run's value is a settled one (:func:`final_error_settled`; always
            True for metrics other than the error at the target).
    """

    baseline: MeanCI = _EMPTY
    candidate: MeanCI = _EMPTY
    by_baseline: MeanCI = _EMPTY
    by_candidate: MeanCI = _EMPTY
    rule: RuleVerdict | None = None
    settled: bool = True

    @property
    def verdict(self) -> Verdict:
        """Whether "candidate below baseline" holds, by the report's one rule; "not settled"
        when a run's value is not a steady state: no verdict from it."""
        if not self.settled:
            return "not settled"
        return verdict(self.rule)


@dataclass(frozen=True)
class PaperComparison:
    """Our runs of a group that reproduces the paper, beside the paper's numbers.

    Attributes:
        group: the scenario (or campaign condition).
        exact: whether its plant is the nominal model (None: unknown).
        baseline, candidate: the paper's two controllers, as our controllers are named.
        pairs: (baseline episode, candidate episode), as in the comparisons; empty when
            no pair completed.
        joints: the joints of the first baseline episode.
        seeds: the candidate runs' seeds, sorted.
        metrics: per metric of :data:`PAPER_METRICS`, one :class:`JointComparison` per joint.
    """

    group: str
    exact: bool | None
    baseline: str = PAPER_BASELINE
    candidate: str = PAPER_CANDIDATE
    pairs: tuple[tuple[str, str], ...] = ()
    joints: tuple[str, ...] = ()
    seeds: tuple[str, ...] = ()
    metrics: Mapping[str, tuple[JointComparison, ...]] = field(default_factory=dict)

    @property
    def baseline_episodes(self) -> list[str]:
        """The paired baseline runs, in pair order, each once."""
        return list(dict.fromkeys(b for b, _ in self.pairs))

    @property
    def candidate_episodes(self) -> list[str]:
        """The paired candidate runs, in pair order, each once."""
        return list(dict.fromkeys(c for _, c in self.pairs))

    def at(self, metric: str, k: int) -> JointComparison:
        """``metric`` on the joint of index ``k`` (empty beyond the recorded joints)."""
        rows = self.metrics.get(metric, ())
        return rows[k] if k < len(rows) else JointComparison()

    def claim_verdicts(self, metric: str) -> dict[Verdict, list[int]]:
        """Joint numbers (1-based) of the paper's claim joints, by verdict on ``metric``."""
        groups: dict[Verdict, list[int]] = {}
        for k in range(min(PAPER_CLAIM_JOINTS, len(self.joints))):
            groups.setdefault(self.at(metric, k).verdict, []).append(k + 1)
        return groups


def final_error_settled(
    episode: str, joint: str, view: ProtocolView | None, row: Mapping[str, Any]
) -> bool:
    """Whether ``episode``'s error at the target on ``joint`` is a steady state: its hold
    ended settled (``protocol.hold_settled``: the settling criterion of
    ``pipeline.sim.settling``, the pre-roll's) or, in a bag that does not record it, the
    error no longer drifts over the final window (``catalog.not_settled``)."""
    recorded = view.settings.protocol.hold_settled if view and view.settings else None
    if recorded is not None:
        return recorded
    final, drift = row.get("final_error"), row.get("final_drift")
    if final is None or drift is None:
        return True  # nothing says otherwise (the value is n/a then, or a legacy bag)
    return not abs(drift) > max(abs(final) * FINAL_DRIFT_REL, DRIFT_FLOOR_RAD)


def paper_groups(
    episodes: pl.DataFrame, recordings: Sequence[Recording], views: Mapping[str, ProtocolView]
) -> list[str]:
    """Groups (scenarios, campaign conditions) whose recordings say they reproduce the
    paper (settings contract), sorted."""
    group = episodes.select("episode", "group").rows_by_key("episode", unique=True)
    marked = {
        group[rec.episode][0]
        for rec in recordings
        if (view := views.get(rec.episode)) is not None
        and view.settings is not None
        and view.settings.protocol.reproduces_paper
    }
    return sorted(marked)


def paper_comparison(
    group: str,
    *,
    episodes: pl.DataFrame,
    metrics: pl.DataFrame,
    recordings: Sequence[Recording],
    views: Mapping[str, ProtocolView],
    baseline: str = PAPER_BASELINE,
    candidate: str = PAPER_CANDIDATE,
) -> PaperComparison:
    """The group's baseline/candidate pairs and their metrics, to put beside the paper.

    Pairs as in the comparisons: a candidate run with the baseline run of its seed when
    there is one, else with every baseline run.

    Args:
        group: the group (from :func:`paper_groups`).
        episodes: :func:`pipeline.analysis.episodes.episode_table`.
        metrics: :func:`pipeline.analysis.metrics.joint_metrics`.
        recordings: every recording.
        views: per episode, its protocol view.
        baseline, candidate: the controllers that stand for the paper's two.
    """
    group_of = dict(zip(episodes["episode"].to_list(), episodes["group"].to_list(), strict=True))
    exact = nominal_plant([r for r in recordings if group_of.get(r.episode) == group], views)
    eps = episodes.with_columns(pl.col("controller").str.to_lowercase())
    eps = eps.filter(pl.col("controller").is_in([baseline, candidate]))
    chosen = tuple((b, c) for g, b, c in pairs(eps, baseline=baseline) if g == group)
    if not chosen:
        return PaperComparison(group, exact, baseline, candidate)
    by_episode = {rec.episode: rec for rec in recordings}
    rows: dict[tuple[str, str], dict[str, Any]] = {
        (r["episode"], r["joint"]): r for r in metrics.iter_rows(named=True)
    }

    def value(episode: str, joint: str, metric: str) -> Any:
        return rows.get((episode, joint), {}).get(metric)

    bases = list(dict.fromkeys(b for b, _ in chosen))
    cands = list(dict.fromkeys(c for _, c in chosen))
    joints = tuple(by_episode[bases[0]].joint_names)

    seed_of = {rec.episode: rec.meta("seed") for rec in recordings}
    by_seed = all(seed_of.get(b) == seed_of.get(c) for b, c in chosen)

    def rule(joint: str, metric: str) -> RuleVerdict:
        """Keyed by seed when every pair shares its seed, else unpaired (by episode)."""
        base = {seed_of[b] if by_seed else b: value(b, joint, metric) for b, _ in chosen}
        cand = {seed_of[c] if by_seed else ("c", c): value(c, joint, metric) for _, c in chosen}
        m = BY_NAME[metric]
        return compare(base, cand, unit=m.unit, lower_is_better=m.lower_is_better)

    def compare_one(joint: str, metric: str) -> JointComparison:
        per_pair = [(value(b, joint, metric), value(c, joint, metric)) for b, c in chosen]
        settled = metric != "final_error" or all(
            final_error_settled(e, joint, views.get(e), rows.get((e, joint), {}))
            for e in (*bases, *cands)
        )
        return JointComparison(
            baseline=mean_ci(value(e, joint, metric) for e in bases),
            candidate=mean_ci(value(e, joint, metric) for e in cands),
            by_baseline=mean_ci(reduction_pct(vb, vc, vb) for vb, vc in per_pair),
            by_candidate=mean_ci(reduction_pct(vb, vc, vc) for vb, vc in per_pair),
            rule=rule(joint, metric),
            settled=settled,
        )

    seeds = sorted({by_episode[c].meta("seed") for c in cands}, key=lambda x: (len(x), x))
    return PaperComparison(
        group,
        exact,
        baseline,
        candidate,
        pairs=chosen,
        joints=joints,
        seeds=tuple(seeds),
        metrics={m: tuple(compare_one(j, m) for j in joints) for m in PAPER_METRICS},
    )
