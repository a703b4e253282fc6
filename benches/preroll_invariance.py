"""The settled pre-roll does not move the metrics: the default experiment both ways.

Records every episode of the default experiment (params.yaml's hand-listed episodes and
its ``campaigns``: what ``make demo`` records) twice, in this process (``-j 1``, no DVC):

- ``fixed``: the pre-roll runs to its cap (``preroll_s``, 2 s), as before issue 31;
- ``settled``: the pre-roll ends at the first settled window (``pipeline.sim.settling``).

Everything else is the same (the hold's rule, the noise draws: the rows are allotted for
the cap either way). Then ``pipeline report`` on each, and every number of the two
``metrics.json`` files is compared:

- a number with a 95 % interval (the campaign aggregates: mean ± half width over seeds,
  their reductions): it passes when |settled - fixed| < the fixed run's half width;
- a number without (per-episode metrics, the hand-listed pair's reductions): when
  |settled - fixed| < 1 % of |fixed|, or both are below the noise floor (1e-9: a
  perfect-model CTC's error, ``pipeline.analysis.metrics.ERROR_FLOOR_RAD``).

Prints a Markdown table (one row per metrics.json section) and every number that moved
more than allowed. Usage: nice python benches/preroll_invariance.py [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import pipeline.sim.runner as runner  # noqa: E402
from pipeline.cli import app  # noqa: E402
from pipeline.params import load_params  # noqa: E402

NOISE_FLOOR = 1e-9
REL_TOL = 0.01
_SETTLED_PREROLL = runner._preroll


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


def compare(old: dict[str, Any], new: dict[str, Any]) -> tuple[list[dict[str, Any]], list[str]]:
    """Per section: numbers compared, with an interval, worst ratio; and the failures."""
    skip = {"parameters", "skipped"}
    sections: dict[str, dict[str, Any]] = {}
    failures: list[str] = []
    new_leaves = dict(_numbers(new))
    for path, a in _numbers(old):
        if path[0] in skip or path[-1] in ("n", "samples", "controller_samples"):
            continue
        s = sections.setdefault(
            path[0], {"section": path[0], "n": 0, "with_ci": 0, "worst_ci": 0.0, "worst_rel": 0.0}
        )
        b = new_leaves.get(path)
        name = "/".join(path)
        if b is None:
            failures.append(f"{name}: missing in the settled run")
            continue
        s["n"] += 1
        if isinstance(a, dict):
            (va, half), (vb, _) = _interval(a), _interval(b)
            if va is None or vb is None:
                if (va is None) != (vb is None):
                    failures.append(f"{name}: {va} -> {vb}")
                continue
            if half:
                s["with_ci"] += 1
                ratio = abs(vb - va) / half
                s["worst_ci"] = max(s["worst_ci"], ratio)
                if ratio >= 1:
                    failures.append(f"{name}: {va:.6g} -> {vb:.6g} (interval ± {half:.3g})")
                continue
            a, b = va, vb
        if not (isinstance(b, int | float) and math.isfinite(a) and math.isfinite(b)):
            continue
        if abs(a) < NOISE_FLOOR and abs(b) < NOISE_FLOOR:
            continue
        rel = abs(b - a) / max(abs(a), NOISE_FLOOR)
        s["worst_rel"] = max(s["worst_rel"], rel)
        if rel >= REL_TOL:
            failures.append(f"{name}: {a:.6g} -> {b:.6g} ({rel * 100:.2f} %)")
    return list(sections.values()), failures


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--keep", type=Path, help="keep recordings and reports here")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        runs: dict[str, dict[str, Any]] = {}
        for mode in MODES:
            rec_wall, starts = _record(root / mode / "recordings", mode=mode)
            rep_wall, metrics = _report(root / mode / "recordings", root / mode / "report")
            runs[mode] = {"record_s": rec_wall, "report_s": rep_wall, "starts": starts,
                          "metrics": metrics}  # fmt: skip
    print(f"load: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} CPUs")
    for mode, r in runs.items():
        s = r["starts"]
        print(
            f"{mode}: {len(s)} episodes, pre-roll {sum(s):.1f} s simulated in all "
            f"(min {min(s):.2f}, max {max(s):.2f} s); record {r['record_s']:.1f} s, "
            f"report {r['report_s']:.1f} s wall"
        )
    for other in ("settled", "fixed-0.1s"):
        rows, failures = compare(runs["fixed"]["metrics"], runs[other]["metrics"])
        print(f"\n### fixed 2 s vs {other}\n")
        print("| metrics.json section | numbers | with a 95 % interval | moved more than "
              "allowed | worst |Δ| / half width | worst |Δ| / |value| (no interval) |")  # fmt: skip
        print("|---|---:|---:|---:|---:|---:|")
        for r in rows:
            moved = sum(1 for f in failures if f.startswith(r["section"] + "/"))
            print(f"| {r['section']} | {r['n']} | {r['with_ci']} | {moved} | "
                  f"{r['worst_ci']:.3f} | {r['worst_rel'] * 100:.3f} % |")  # fmt: skip
        print(f"\nmoved more than allowed: {len(failures)}")
        for f in failures:
            if not f.startswith("episodes/"):
                print(f"- {f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
