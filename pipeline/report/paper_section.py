"""The report's "Versus the paper" sections: :class:`pipeline.analysis.paper_claims.PaperComparison`
beside the paper's numbers (:mod:`pipeline.analysis.paper_claims`), in words and tables."""

from __future__ import annotations

from pipeline.analysis import paper_claims as paper
from pipeline.analysis.aggregate import CONFIDENCE, MeanCI
from pipeline.analysis.paper_claims import JointComparison, PaperComparison
from pipeline.analysis.verdict import ALPHA, MIN_PAIRS
from pipeline.constants import FINAL_WINDOW_S
from pipeline.report import md
from pipeline.report.inputs import ReportData


def versus_paper(data: ReportData) -> list[str]:
    """One section per group marked as reproducing the paper (or a line saying none is)."""
    marked = paper.paper_groups(data.episodes, data.recordings, data.protocol)
    if not marked:
        return [
            "## Versus the paper",
            "",
            "No scenario here is marked as the paper's experiment (`reproduces_paper: true` "
            f"in params; the paper: {paper.PAPER_CITATION}), so nothing is compared with the "
            "paper's numbers.",
            "",
        ]
    out: list[str] = []
    for group in marked:
        comparison = paper.paper_comparison(
            group,
            episodes=data.episodes,
            metrics=data.metrics,
            recordings=data.recordings,
            views=data.protocol,
        )
        out += _versus_paper_one(comparison)
    return out


def _versus_paper_one(cmp: PaperComparison) -> list[str]:
    base, cand = cmp.baseline, cmp.candidate
    b_name, c_name = base.upper(), cand.upper()
    kind = (
        f"ideal plant: the nominal model is the plant, so {c_name}'s model terms are exact by "
        "construction"
        if cmp.exact
        else "realistic plant: it differs from the nominal model (see its setup)"
        if cmp.exact is False
        else "plant unknown"
    )
    lines = [f"## Versus the paper: `{cmp.group}` ({kind})", ""]
    if not cmp.pairs:
        return [
            *lines,
            f"No scenario has both a `{base}` and a `{cand}` episode that completed, so there "
            "is nothing to put beside the paper.",
            "",
        ]
    n_pairs = len(cmp.pairs)
    base_eps, cand_eps = cmp.baseline_episodes, cmp.candidate_episodes

    def pct(ci: MeanCI, by_candidate: bool = False) -> str:
        """A percentage, or, where one controller is more than twice the other, the ratio
        by name ("CTC 4.0× PID's"): -3600 % or +3600 % say less."""
        mean = ci.mean
        mean_of = "" if n_pairs == 1 else " (mean)"
        if mean is not None and not by_candidate and mean < md.RATIO_BELOW_PCT:
            return f"{c_name} {1.0 - mean / 100.0:.3g}× {b_name}'s" + mean_of
        if mean is not None and by_candidate and mean > -md.RATIO_BELOW_PCT:
            return f"{b_name} {1.0 + mean / 100.0:.3g}× {c_name}'s" + mean_of
        return md.pct(mean) if n_pairs == 1 else md.mean_ci_pct(ci)

    def val(ci: MeanCI, fmt: md.Format, hw_fmt: md.Format | None = None) -> str:
        if ci.mean is None:
            return md.NA
        return fmt(ci.mean) if n_pairs == 1 else md.mean_ci(ci, fmt, hw_fmt)

    if n_pairs == 1:
        ((b_ep, c_ep),) = cmp.pairs
        ours = f"episodes `{b_ep}` ({b_name}) and `{c_ep}` ({c_name})"
    else:
        ours = (
            f"{n_pairs} {b_name}/{c_name} pairs ({len(base_eps)} {b_name} and {len(cand_eps)} "
            f"{c_name} runs, seeds {', '.join(cmp.seeds)}): mean ± {CONFIDENCE * 100:.0f} % "
            "confidence interval (Student t) over the runs, reductions per pair"
        )

    def by_verdict(metric: str) -> str:
        return "; ".join(
            f"{v} on joint{'s' if len(js) > 1 else ''} {', '.join(str(j) for j in js)}"
            for v, js in cmp.claim_verdicts(metric).items()
        )

    j1 = cmp.at("max_abs_error", 0)
    claims = [
        [
            f"{c_name}'s max tracking error on joint 1 is smaller than {b_name}'s "
            f"({paper.PAPER_JOINT1_MAX_ERROR_REDUCTION_PCT:.1f} % smaller)",
            f"{j1.verdict}: {pct(j1.by_baseline)} smaller",
        ],
        [
            f"{c_name}'s max tracking error is smaller on joints 1-{paper.PAPER_CLAIM_JOINTS} "
            "(Figs. 6-7)",
            by_verdict("max_abs_error"),
        ],
        [
            f"{c_name}'s error at the target is smaller on joints 1-{paper.PAPER_CLAIM_JOINTS} "
            "(Table 3)",
            by_verdict("final_error"),
        ],
    ]
    lines += [
        f"Ours: scenario **{cmp.group}**, {ours}. Paper: {paper.PAPER_SOURCE}.",
        "",
        f"**The paper's claims here** (a claim *holds* when {c_name} is below {b_name}, by "
        "the report's one rule, as the Verdicts: *equivalent* within the practical margin; "
        f"from {MIN_PAIRS} seed pairs a two-sided Wilcoxon signed-rank test, *holds* / *does "
        f"not hold* when p < {ALPHA:g}, else *inconclusive*; with fewer pairs *too few pairs "
        "for a test*; a single pair's sign is said as one pair, no test):",
        "",
        md.table(["claim", "here"], claims),
        "",
        "Two reduction formulas appear in the paper: the joint-1 figure "
        f"({paper.PAPER_JOINT1_MAX_ERROR_REDUCTION_PCT:.1f} %) is "
        f"({b_name} − {c_name}) / {b_name} × 100, while Table 3's percentages are "
        f"({b_name} − {c_name}) / {c_name} × 100. "
        "Both are shown for our numbers; the rest of this report uses "
        "(baseline − candidate) / baseline × 100.",
        "",
        "#### Joint 1 maximum tracking error",
        "",
    ]
    p_base = paper.PAPER_JOINT1_MAX_ERROR_RAD[base]
    p_cand = paper.PAPER_JOINT1_MAX_ERROR_RAD[cand]
    rows = [
        [f"{c_name} max |e| [rad]", md.sci(p_cand), val(j1.candidate, md.sci)],
        [f"{b_name} max |e| [rad]", md.sci(p_base), val(j1.baseline, md.sci)],
        [
            f"({b_name} − {c_name}) / {b_name}",
            f"{paper.PAPER_JOINT1_MAX_ERROR_REDUCTION_PCT:.1f} % (printed)",
            pct(j1.by_baseline),
        ],
        [
            f"({b_name} − {c_name}) / {c_name}",
            md.pct(paper.PAPER_JOINT1_MAX_ERROR_REDUCTION_BY_CANDIDATE_PCT),
            pct(j1.by_candidate, by_candidate=True),
        ],
    ]
    lines += [md.table(["joint 1", "paper", "ours"], rows), ""]
    lines += ["#### Error at the target (paper Table 3), ×1e-5 rad", ""]

    def e5(x: float) -> str:
        return f"{x * 1e5:.4f}"

    rows = []
    for k in range(len(paper.PAPER_FINAL_ERROR_REDUCTION_PCT)):
        final: JointComparison = cmp.at("final_error", k)
        unsettled = "" if final.settled else " (not settled: no verdict)"
        rows.append(
            [
                str(k + 1),
                e5(paper.PAPER_FINAL_ERROR_RAD[cand][k]),
                e5(paper.PAPER_FINAL_ERROR_RAD[base][k]),
                f"{paper.PAPER_FINAL_ERROR_REDUCTION_PCT[k]:.1f} %",
                md.pct(paper.PAPER_FINAL_ERROR_REDUCTION_BY_BASELINE_PCT[k]),
                val(final.candidate, e5),
                val(final.baseline, e5),
                pct(final.by_candidate, by_candidate=True) + unsettled,
                pct(final.by_baseline) + unsettled,
            ]
        )
    lines += [
        md.table(
            [
                "joint",
                f"paper {c_name}",
                f"paper {b_name}",
                f"paper printed ({b_name}−{c_name})/{c_name}",
                f"paper recomputed ({b_name}−{c_name})/{b_name}",
                f"ours {c_name}",
                f"ours {b_name}",
                f"ours ({b_name}−{c_name})/{c_name}",
                f"ours ({b_name}−{c_name})/{b_name}",
            ],
            rows,
        ),
        "",
        f"Ours: mean |e| over the final window (≤ {FINAL_WINDOW_S} s, see Definitions). "
        "The paper does not say how its value was taken.",
        "",
        "#### Peak joint velocities [rad/s]",
        "",
    ]

    def vel(x: float) -> str:
        return md.signed(x, 2)

    def vel_hw(x: float) -> str:
        return f"{x:.2f}"

    rows = []
    for number in sorted(paper.PAPER_PEAK_VELOCITY_RAD_S[cand]):
        joint = cmp.joints[number - 1] if number - 1 < len(cmp.joints) else None
        peak = cmp.at("peak_velocity", number - 1)
        rows.append(
            [
                f"{number} {joint or ''}".strip(),
                f"{paper.PAPER_PEAK_VELOCITY_RAD_S[cand][number]:+.2f}",
                val(peak.candidate, vel, vel_hw),
                f"{paper.PAPER_PEAK_VELOCITY_RAD_S[base][number]:+.2f}",
                val(peak.baseline, vel, vel_hw),
            ]
        )
    header = ["joint", f"paper {c_name}", f"ours {c_name}", f"paper {b_name}", f"ours {b_name}"]
    lines += [md.table(header, rows), ""]
    return lines
