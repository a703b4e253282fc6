"""The tables of the issue-28 studies (docs/control.md, "Fair footing"): each law on the CAD
and on the identified nominal, paired by seed, decided by the report's one verdict rule.

    python studies/study_table.py REPORT/campaigns/CAMPAIGN.parquet [--markdown]

Reads the campaign table ``pipeline report`` writes. Controllers are named ``LAW`` (the
CAD nominal), ``LAW_id`` (the identified nominal) and ``LAW_fric`` (the identified nominal
with its friction fed forward). Every comparison goes through
``pipeline.analysis.verdict.compare`` (equivalence margin: the larger of the encoder step,
times 1 m at the TCP, and 2 % of the baseline's mean; from 6 pairs the two-sided exact
Wilcoxon signed-rank test of the per-seed differences), with the p Holm-corrected over
each printed table's family of tests, as the report's win/loss tables do. Changes are the
mean over seeds of ``(x - x_ref) / x_ref`` [%] with its two-sided 95 % Student-t interval
(which assumes the per-seed changes are roughly normal; the verdict's signed-rank test
assumes only that they are symmetric about their median).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

import polars as pl

from pipeline.analysis.intervals import mean_ci
from pipeline.analysis.verdict import Verdict, compare

NOMINALS = {
    "": "CAD",
    "_id": "identified",
    "_fric": "identified + friction ff",
    "_own": "own plant's model",
    "_fric_own": "own plant's model + friction ff",
}
SUFFIXES = ("_fric_own", "_own", "_fric", "_id")
UR5_ORDER = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
             "wrist_2_joint", "wrist_3_joint")  # fmt: skip
WORD = {"better": "lower", "worse": "higher", "no clear difference": "n.s."}


def holm(ps: list[float | None]) -> list[float | None]:
    """Holm's step-down correction of the p values that are not None."""
    idx = sorted((p, i) for i, p in enumerate(ps) if p is not None)
    out: list[float | None] = [None] * len(ps)
    running = 0.0
    for rank, (p, i) in enumerate(idx):
        running = max(running, min(1.0, (len(idx) - rank) * p))
        out[i] = running
    return out


def pct(values: list[float]) -> str:
    ci = mean_ci(values)
    if ci.mean is None:
        return "n/a"
    if ci.half_width is None:
        return f"{ci.mean:+.0f}"
    return f"{ci.mean:+.0f} ± {ci.half_width:.0f}"


class Study:
    def __init__(self, frame: pl.DataFrame) -> None:
        ok = frame.filter(pl.col("status") == "ok")
        self.failed = frame.filter(pl.col("status") != "ok")["episode"].unique().to_list()
        self.joints = [j for j in dict.fromkeys(ok["joint"].to_list()) if j != "tcp"]
        self.value: dict[tuple[str, str], dict[int, float]] = {}
        for r in ok.iter_rows(named=True):
            if r["joint"] == "tcp":
                # the report's TCP position error is in mm; the verdict rule takes metres
                self._put(r["controller"], "tcp", r["seed"], r["tcp_max_position_error"] * 1e-3)
            else:
                self._put(r["controller"], r["joint"], r["seed"], r["max_abs_error"])
        self.controllers = sorted(dict.fromkeys(ok["controller"].to_list()), key=_rank)
        self.seeds = sorted({s for v in self.value.values() for s in v})
        self.min_p = 0.0

    def order(self, quantities: list[str]) -> list[str]:
        known = [j for j in UR5_ORDER if j in quantities]
        return known + sorted(q for q in quantities if q not in known)

    def _put(self, controller: str, quantity: str, seed: int, value: float | None) -> None:
        if value is not None and math.isfinite(value):
            self.value.setdefault((controller, quantity), {})[int(seed)] = float(value)

    def get(self, controller: str, quantity: str) -> dict[int, float]:
        return self.value.get((controller, quantity), {})

    def rel(self, cand: str, base: str, quantity: str) -> list[float]:
        b, c = self.get(base, quantity), self.get(cand, quantity)
        return [(c[s] - b[s]) / b[s] * 100 for s in sorted(b) if s in c and b[s]]

    def verdict(self, cand: str, base: str, quantity: str) -> Verdict:
        unit = "m" if quantity == "tcp" else "rad"
        return compare(self.get(base, quantity), self.get(cand, quantity), unit=unit)


LAW_ORDER = ("pid", "pid_ff", "ctc", "ctc_pid")


def _rank(controller: str) -> tuple[int, int, str]:
    suffix = next((x for x in SUFFIXES if controller.endswith(x)), "")
    law = controller[: len(controller) - len(suffix)]
    where = LAW_ORDER.index(law) if law in LAW_ORDER else len(LAW_ORDER)
    return list(NOMINALS).index(suffix), where, controller


def label(controller: str) -> str:
    for suffix in SUFFIXES:
        if controller.endswith(suffix):
            return f"`{controller[: -len(suffix)]}`, {NOMINALS[suffix]}"
    return f"`{controller}`, CAD"


def cell(study: Study, cand: str, base: str, q: str, verdict: Verdict, p: float | None) -> str:
    outcome = verdict.with_p(p).outcome
    word = WORD.get(outcome, outcome)
    # p shown where it is not the smallest the row's correction allows (every pair one sign)
    shown = p is not None and outcome != "equivalent" and p > 1.01 * study.min_p
    ptxt = f", p {p:.2g}" if shown else ""
    return f"{pct(study.rel(cand, base, q))} ({word}{ptxt})"


def comparison_table(
    study: Study,
    title: str,
    pairs: list[tuple[str, str, str]],
    quantities: list[str],
    out: Callable[[str], None],
) -> None:
    have = set(study.controllers)
    pairs = [(lab, c, b) for lab, c, b in pairs if c in have and b in have]
    if not pairs:
        return
    verdicts = [[study.verdict(c, b, q) for q in quantities] for _, c, b in pairs]
    # one comparison's row is one family, as one candidate's win/loss table in the report
    flat = [p for row in verdicts for p in holm([v.p for v in row])]
    out(
        f"\n**{title}**: change of max error [%], mean ± 95 % t half width "
        f"(verdict, Wilcoxon p Holm-corrected over the row's {len(quantities)} tests)\n"
    )
    out("| comparison | " + " | ".join(short(q) for q in quantities) + " |")
    out("|---" * (len(quantities) + 1) + "|")
    k = 0
    for (lab, c, b), row in zip(pairs, verdicts, strict=True):
        cells = []
        for q, v in zip(quantities, row, strict=True):
            cells.append(cell(study, c, b, q, v, flat[k]))
            k += 1
        out(f"| {lab} | " + " | ".join(cells) + " |")


def short(q: str) -> str:
    return "TCP" if q == "tcp" else q.replace("panda_", "").replace("_joint", "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("parquet", type=Path, nargs="+", help="campaign tables of the same seeds")
    args = parser.parse_args()
    study = Study(pl.concat([pl.read_parquet(p) for p in args.parquet], how="diagonal_relaxed"))
    out = print
    quantities = ["tcp", *study.order(study.joints)]
    n = len(study.seeds)
    study.min_p = min(1.0, len(quantities) * 2.0 / 2**n)  # exact two-sided, Holm x row
    out(f"n = {n} seeds {study.seeds}, paired by seed; failed: {study.failed or 'none'}")
    out(f"a verdict without p: p = {study.min_p:.2g} after Holm (every pair of one sign)")
    out("\n**Mean max error** (TCP [mm], joints [mrad]; ± 95 % t half width):\n")
    out("| law, nominal | " + " | ".join(short(q) for q in quantities) + " |")
    out("|---" * (len(quantities) + 1) + "|")
    for c in study.controllers:
        cells = []
        for q in quantities:
            ci = mean_ci(list(study.get(c, q).values()))
            if ci.mean is None:
                cells.append("n/a")
                continue
            hw = f" ± {ci.half_width * 1e3:.2f}" if ci.half_width is not None else ""
            cells.append(f"{ci.mean * 1e3:.2f}{hw}")
        out(f"| {label(c)} | " + " | ".join(cells) + " |")
    laws = [c for c in study.controllers if not c.endswith(SUFFIXES)]
    comparison_table(
        study, "Each law vs `pid`, same nominal",
        [(label(c), c, "pid") for c in laws if c != "pid"]
        + [(label(f"{c}_id"), f"{c}_id", "pid_id") for c in laws if c != "pid"],
        quantities, out,
    )  # fmt: skip
    comparison_table(
        study, "Computed torque vs `pid_ff` (the JTC's PID + the same model's feed-forward)",
        [(label(c), c, "pid_ff") for c in ("ctc", "ctc_pid")]
        + [(label(f"{c}_id"), f"{c}_id", "pid_ff_id") for c in ("ctc", "ctc_pid")]
        + [("`ctc` vs `pid_ff`, both + friction ff", "ctc_fric", "pid_ff_fric")],
        quantities, out,
    )  # fmt: skip
    comparison_table(
        study, "Identified vs CAD nominal, same law",
        [(f"`{c}`", f"{c}_id", c) for c in laws]
        + [(f"`{c}` + friction ff vs `{c}` identified", f"{c}_fric", f"{c}_id") for c in laws],
        quantities, out,
    )  # fmt: skip
    comparison_table(
        study, "Each plant's own model vs the one model identified on another plant",
        [(f"`{c}`", f"{c}_own", f"{c}_id") for c in laws]
        + [(f"`{c}` + friction ff", f"{c}_fric_own", f"{c}_fric") for c in laws]
        + [("`ctc` vs `pid_ff`, own model + friction ff", "ctc_fric_own", "pid_ff_fric_own")],
        quantities, out,
    )  # fmt: skip
    comparison_table(
        study, "With an identified model and its friction vs `pid` on CAD",
        [(label(c), c, "pid") for c in study.controllers if c.endswith(("_fric", "_fric_own"))],
        quantities, out,
    )  # fmt: skip


if __name__ == "__main__":
    main()
