"""The settled pre-roll does not move the metrics: the default experiment both ways.

Records every episode of the default experiment (params.yaml's hand-listed episodes and
its ``campaigns``: what ``make demo`` records) twice, in this process (``-j 1``, no DVC):

- ``fixed``: the pre-roll runs to its cap (``preroll_s``, 2 s), as before issue 31;
- ``settled``: the pre-roll ends at the first settled window (``pipeline.sim.settling``);
- ``fixed-0.1s``, a control: the fixed pre-roll 0.1 s shorter (how much a start 0.1 s
  earlier moves the metrics by itself).

Everything else is the same: the hold's rule, and the per-row random draws (sensor
noise, effort-sensor noise, loop jitter). Those are drawn for the cap and aligned to the
motion's start (``pipeline.sim.loop.align_to_motion``), so the motion and the hold of a
settled episode meet exactly the draws the fixed 2 s pre-roll's meet, row for row; only
the pre-roll's own rows differ (the first draws, fewer of them). The state at the
motion's start is what differs. Then ``pipeline report`` on each, and:

1. **The issue's rule** (first, counted as before): every number of the two
   ``metrics.json`` files. A number with a 95 % interval (the campaign aggregates: mean ±
   half width over seeds, their reductions, the headline) passes when |settled - fixed|
   < the fixed run's half width; one without (per-episode metrics, per-pair reductions,
   the hand-listed pair's) when |settled - fixed| < 1 % of |fixed|, or both are below the
   noise floor (1e-9: ``pipeline.analysis.metrics.ERROR_FLOOR_RAD``).
2. **The practical rule**, for every number the issue's rule fails: the report's own
   margin of practical equivalence (``pipeline.analysis.verdict.equivalence_margin``:
   the larger of the unit's resolution, a 20-bit encoder's step 6.0e-6 rad, and 2 % of
   |the fixed run's value|, in the metric's unit from ``pipeline.analysis.catalog``).
   A compared error (a metric the verdict rule judges: the catalog's ``compared``)
   passes when |settled - fixed| < max(its half width, the margin), or, without an
   interval, < max(1 % of |fixed|, the margin). A % reduction has no margin in its unit:
   it passes only when every error it is computed from (each side's campaign mean, or
   each paired episode's value) lies below its unit's resolution in both runs (the
   reduction of two unresolvable errors is not resolvable); otherwise the issue's rule
   stands. A metric the verdict rule does not judge (drift, effort, peak velocity and
   its time, overshoot) keeps the issue's rule.
3. **Verdict flips**: what the report tells a reader, fixed vs settled: every win/loss
   verdict (``campaigns/*_win_loss.csv``), the Verdicts sentences and the paper's claims
   of ``report.md`` (their words: decimals and percentages masked), the hand-listed
   episodes' error at the target (settled / not settled), and which episodes are shown
   as median / worst.

Prints a Markdown table (one row per metrics.json section, both counts), the numbers
that fail the issue's rule outside the per-episode and per-pair sections (each judged by
the practical rule), every number beyond the practical rule, and the verdicts that change.
Usage: nice python benches/preroll_invariance.py [--keep DIR] [--reuse]
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import pipeline.sim.runner as runner  # noqa: E402
from pipeline.analysis.catalog import BY_NAME, Metric  # noqa: E402
from pipeline.analysis.verdict import equivalence_margin  # noqa: E402
from pipeline.cli import app  # noqa: E402
from pipeline.params import load_params  # noqa: E402

NOISE_FLOOR = 1e-9
REL_TOL = 0.01
_SETTLED_PREROLL = runner._preroll


@dataclass(frozen=True)
class Move:
    """A number that moved more than the issue's rule allows; ``practical``: whether it
    stays within the practical rule (see the module docstring)."""

    name: str
    text: str
    practical: bool


def _fixed(short_s: float = 0.0) -> Any:
    """The pre-roll before issue 31: the whole cap (less ``short_s``), whatever the state."""

    def preroll(
        run_rows: Any, controller: Any, q_true: Any, qd_true: Any, q_ref: Any, cap: int, w: int,
        *, check: bool = True,
    ) -> tuple[int, bool, int, str]:  # fmt: skip
        rows = cap - round(short_s / 0.001) if cap else 0  # the default 1 kHz control
        if rows <= 0:
            return 0, True, 0, ""
        done, reason = run_rows(0, rows, final=False)
        return (done if reason else rows), not reason, done, reason

    return preroll


# mode -> the pre-roll: before issue 31, the settled one, and a control: the fixed one
# 0.1 s shorter (how much a start 0.1 s earlier or later moves the metrics by itself)
MODES = {"fixed": _fixed(), "settled": _SETTLED_PREROLL, "fixed-0.1s": _fixed(0.1)}


def _record(out: Path, *, mode: str) -> tuple[float, list[float]]:
    """Record the default experiment into ``out``; (wall s, per-episode pre-roll used s)."""
    starts: list[float] = []
    original = runner.run_episode

    def probe(*args: Any, **kwargs: Any) -> Any:
        result = original(*args, **kwargs)
        starts.append(result.motion_start_s)
        return result

    runner._preroll = MODES[mode]  # type: ignore[assignment]
    # pipeline.stages.episode imports run_episode at each call: the probe is what it gets
    runner.run_episode = probe  # type: ignore[assignment]
    params = str(REPO / "params.yaml")
    # what `make demo` records: the hand-listed episodes, then every campaign (-j 1: here)
    loaded = load_params(Path(params))
    demo = [c for c in loaded.campaigns if c not in loaded.extra_campaigns]
    runs = [[]] + [["--campaign", c] for c in demo]
    try:
        t0 = time.perf_counter()
        for extra in runs:
            app(["record", "--params", params, "--out", str(out), "-j", "1", "--force", *extra],
                standalone_mode=False)  # fmt: skip
        wall = time.perf_counter() - t0
    finally:
        runner._preroll = _SETTLED_PREROLL  # type: ignore[assignment]
        runner.run_episode = original  # type: ignore[assignment]
    return wall, starts


def _report(recordings: Path, out: Path) -> tuple[float, dict[str, Any]]:
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "pipeline", "report", "--recordings", str(recordings),
         "--out", str(out), "--baseline", "pid"],
        cwd=REPO, check=True, stdout=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    wall = time.perf_counter() - t0
    return wall, json.loads((out / "metrics.json").read_text())


def _numbers(node: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], Any]]:
    """Every leaf mapping that is a number or a {mean, ci95_half_width} interval."""
    if isinstance(node, dict):
        if "mean" in node and "ci95_half_width" in node:
            yield path, node
            return
        if "reduction_pct" in node:  # a headline reduction (its interval as low/high)
            yield path, node
            return
        for k, v in node.items():
            yield from _numbers(v, (*path, str(k)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _numbers(v, (*path, str(i)))
    elif isinstance(node, int | float) and not isinstance(node, bool):
        yield path, node


def _interval(node: dict[str, Any]) -> tuple[float | None, float | None]:
    """(value, half width) of an interval leaf."""
    if "mean" in node:
        return node["mean"], node.get("ci95_half_width")
    lo, hi = node.get("ci95_low"), node.get("ci95_high")
    half = (hi - lo) / 2 if lo is not None and hi is not None else None
    return node.get("reduction_pct"), half


def _value(metrics: dict[str, Any], path: tuple[str, ...]) -> float | None:
    """The number (an interval's mean) at ``path`` in a metrics.json, or None."""
    node: Any = metrics
    for key in path:
        if isinstance(node, list) and key.isdigit() and int(key) < len(node):
            node = node[int(key)]
        elif isinstance(node, dict) and key in node:
            node = node[key]
        else:
            return None
    if isinstance(node, dict):
        node = node.get("mean")
    ok = isinstance(node, int | float) and not isinstance(node, bool) and math.isfinite(node)
    return float(node) if ok else None


def _compared(quantity: str) -> Metric | None:
    """The catalog's metric when the verdict rule judges it (``compared``), else None."""
    m = BY_NAME.get(quantity)
    return m if m is not None and m.compared else None


def _sources(metrics: dict[str, Any], path: tuple[str, ...]) -> tuple[str, list[tuple[str, ...]]]:
    """A reduction's quantity and the paths of the errors it is computed from (each
    side's campaign mean, or each paired episode's value); ("", []) for a number that is
    not a reduction."""
    q = path[-1].removesuffix("_reduction_pct")
    sides = ("candidate", "baseline")
    eps = metrics.get("episodes", {})
    if path[0] == "aggregates" and len(path) == 7 and path[2] == "reductions":
        cand, _, base = path[3].partition(" vs ")
        return q, [("aggregates", path[1], "controllers", c, path[5], q) for c in (cand, base)]
    if path[0] == "headline" and len(path) == 5:
        cand, _, base = path[2].partition("_vs_")
        if path[1] in metrics.get("aggregates", {}):
            return q, [("aggregates", path[1], "controllers", c, path[3], q) for c in (cand, base)]
        out: list[tuple[str, ...]] = []
        for cmp in metrics.get("comparisons", []):
            controllers = [eps.get(cmp[k], {}).get("controller") for k in sides]
            if cmp.get("scenario") == path[1] and controllers == [cand, base]:
                out += [("episodes", cmp[k], "joints", path[3], q) for k in sides]
        return q, out
    if path[0] == "comparisons" and len(path) == 5 and path[-1].endswith("_reduction_pct"):
        cmp = metrics["comparisons"][int(path[1])]
        return q, [("episodes", cmp[k], "joints", path[3], q) for k in sides]
    return "", []


def _unresolved(metrics: tuple[dict[str, Any], ...], quantity: str, paths: list[Any]) -> bool:
    """Whether every error a reduction is computed from lies below its quantity's
    resolution (the verdict's margin with no baseline: the encoder step) in every run:
    the reduction of two unresolvable errors is not resolvable either."""
    m = _compared(quantity)
    resolution = equivalence_margin(m.unit, None) if m is not None else 0.0
    if not paths or resolution <= 0:
        return False
    values = [_value(run, p) for run in metrics for p in paths]
    return all(v is not None and abs(v) < resolution for v in values)


def compare(old: dict[str, Any], new: dict[str, Any]) -> tuple[list[dict[str, Any]], list[Move]]:
    """Per section: numbers compared, with an interval, worst ratios; and every number
    that moved more than the issue's rule allows, judged by the practical rule too."""
    skip = {"parameters", "skipped"}
    sections: dict[str, dict[str, Any]] = {}
    moves: list[Move] = []
    new_leaves = dict(_numbers(new))
    for path, a in _numbers(old):
        if path[0] in skip or path[-1] in ("n", "samples", "controller_samples"):
            continue
        s = sections.setdefault(
            path[0], {"section": path[0], "n": 0, "with_ci": 0, "worst_ci": 0.0, "worst_rel": 0.0}
        )
        b = new_leaves.get(path)
        name = "/".join(path)
        quantity, sources = _sources(old, path)
        # a reduction that appears or vanishes (its baseline crosses the 1e-9 floor) is
        # judged like one that moves: by whether its errors are resolvable
        gone = _unresolved((old, new), quantity, sources)
        tail = "; its errors all below the resolution" if gone else ""
        if b is None:
            moves.append(Move(name, f"missing in the other run{tail}", practical=gone))
            continue
        s["n"] += 1
        half = None
        if isinstance(a, dict):
            (va, half), (vb, _) = _interval(a), _interval(b)
            if va is None or vb is None:
                if (va is None) != (vb is None):
                    moves.append(Move(name, f"{va} -> {vb}{tail}", practical=gone))
                continue
            a, b = va, vb
        if not (isinstance(b, int | float) and math.isfinite(a) and math.isfinite(b)):
            continue
        delta = abs(b - a)
        if half:
            s["with_ci"] += 1
            ratio = delta / half
            s["worst_ci"] = max(s["worst_ci"], ratio)
            if ratio < 1:
                continue
            text = f"{a:.6g} -> {b:.6g} (interval ± {half:.3g})"
        else:
            if abs(a) < NOISE_FLOOR and abs(b) < NOISE_FLOOR:
                continue
            rel = delta / max(abs(a), NOISE_FLOOR)
            s["worst_rel"] = max(s["worst_rel"], rel)
            if rel < REL_TOL:
                continue
            text = f"{a:.6g} -> {b:.6g} ({rel * 100:.2f} %)"
        # the practical rule: a compared error within the verdict's equivalence margin; a
        # reduction of errors that all lie below the resolution
        if sources:
            practical = _unresolved((old, new), quantity, sources)
            why = "its errors all below the resolution" if practical else "a reduction"
        elif (m := _compared(path[-1])) is not None:
            margin = equivalence_margin(m.unit, a)
            practical = delta < margin
            why = f"|Δ| {delta:.2g} {'<' if practical else '>='} margin {margin:.2g} {m.unit}"
        else:
            practical, why = False, "not a compared metric: the strict rule"
        moves.append(Move(name, f"{text}; {why}", practical=practical))
    return list(sections.values()), moves


_DECIMAL = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?= ?[%×])|[-+]?\d+\.\d+(?:e[-+]?\d+)?")


def verdicts(report: Path) -> dict[str, str]:
    """What a reader of ``report`` is told, keyed by question: every win/loss verdict
    (``campaigns/*_win_loss.csv``), the Verdicts sentences and the paper's claims of
    ``report.md`` (their sizes masked: only the words count), and each episode's error
    at the target (settled / not settled)."""
    out: dict[str, str] = {}
    for path in sorted((report / "campaigns").glob("*_win_loss.csv")):
        with path.open(newline="") as f:
            for r in csv.DictReader(f):
                pair = f"{r['candidate']} vs {r['baseline']}"
                key = f"win/loss {path.stem.removesuffix('_win_loss')} {r['condition']} {pair}"
                out[" ".join(f"{key} {r['joint']} {r['metric']}".split())] = r["verdict"]
    section = ""
    columns: list[str] = []
    for line in (report / "report.md").read_text().splitlines():
        if line.startswith("#"):
            section, columns = line.lstrip("# "), []
        elif section == "Verdicts" and line.startswith("- **"):
            head, _, tail = line.partition(":")
            out[f"Verdicts: {head[2:]}"] = _DECIMAL.sub("#", tail).strip()
        elif line.startswith("| ") and line.endswith(" |"):
            cells = [c.strip() for c in line[2:-2].split(" | ")]
            if cells[:2] in (["claim", "here"], ["episode", "scenario"], ["episode", "condition"]):
                columns = cells
            elif set(cells) == {"---"} or len(cells) != len(columns):
                continue
            elif columns[:2] == ["claim", "here"]:
                out[f"claim ({section.partition(' (')[0]}): {cells[0]}"] = _DECIMAL.sub(
                    "#", cells[1]
                )
            elif columns[:2] == ["episode", "scenario"]:
                out[f"episode {cells[0]}: error at the target"] = cells[-1]
            elif columns[:2] == ["episode", "condition"]:
                out[f"shown: {cells[1]} {cells[2]} {cells[4]}"] = cells[0]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--keep", type=Path, help="keep recordings and reports here")
    ap.add_argument(
        "--reuse", action="store_true",
        help="compare the runs a previous --keep DIR holds (its runs.json) without recording",
    )  # fmt: skip
    args = ap.parse_args()
    if args.reuse and not args.keep:
        print("error: --reuse needs --keep DIR (the directory a previous run kept)")
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        runs: dict[str, dict[str, Any]] = {}
        if args.reuse:
            runs = json.loads((root / "runs.json").read_text())
        for mode in MODES if not args.reuse else ():
            rec_wall, starts = _record(root / mode / "recordings", mode=mode)
            rep_wall, metrics = _report(root / mode / "recordings", root / mode / "report")
            runs[mode] = {"record_s": rec_wall, "report_s": rep_wall, "starts": starts,
                          "metrics": metrics}  # fmt: skip
        if args.keep and not args.reuse:
            (root / "runs.json").write_text(json.dumps(runs))
    print(f"load: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} CPUs")
    for mode, r in runs.items():
        s = r["starts"]
        print(
            f"{mode}: {len(s)} episodes, pre-roll {sum(s):.1f} s simulated in all "
            f"(min {min(s):.2f}, max {max(s):.2f} s); record {r['record_s']:.1f} s, "
            f"report {r['report_s']:.1f} s wall"
        )
    said = {mode: verdicts(root / mode / "report") for mode in runs}
    for other in ("settled", "fixed-0.1s"):
        rows, moves = compare(runs["fixed"]["metrics"], runs[other]["metrics"])
        print(f"\n### fixed 2 s vs {other}\n")
        print("| metrics.json section | numbers | with a 95 % interval | moved more than "
              "allowed (the issue's rule) | moved more than the practical rule allows "
              "| worst |Δ| / half width | worst |Δ| / |value| (no interval) |")  # fmt: skip
        print("|---|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            mine = [m for m in moves if m.name.startswith(r["section"] + "/")]
            beyond = sum(not m.practical for m in mine)
            print(f"| {r['section']} | {r['n']} | {r['with_ci']} | {len(mine)} | {beyond} | "
                  f"{r['worst_ci']:.3f} | {r['worst_rel'] * 100:.3f} % |")  # fmt: skip
        beyond = [m for m in moves if not m.practical]
        print(f"\nmoved more than allowed: {len(moves)} (the issue's rule); "
              f"{len(beyond)} beyond the practical rule")  # fmt: skip
        for m in moves:
            if not m.name.startswith(("episodes/", "comparisons/")):
                print(f"- {m.name}: {m.text}{'' if m.practical else ' **BEYOND**'}")
        for m in beyond:
            if m.name.startswith(("episodes/", "comparisons/")):
                print(f"- {m.name}: {m.text} **BEYOND**")
        a, b = said["fixed"], said[other]
        flips = [k for k in a if a[k] != b.get(k)] + [k for k in b if k not in a]
        print(f"\nverdicts that change: {len(flips)} of {len(a)} (win/loss "
              f"{sum(k.startswith('win/loss') for k in a)}, Verdicts sentences "
              f"{sum(k.startswith('Verdicts') for k in a)}, claims "
              f"{sum(k.startswith('claim') for k in a)}, error at the target "
              f"{sum(k.startswith('episode') for k in a)}, episodes shown "
              f"{sum(k.startswith('shown') for k in a)})")  # fmt: skip
        for k in flips:
            print(f"- {k}: {a.get(k)!r} -> {b.get(k)!r}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
