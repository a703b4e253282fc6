"""The controller study's tables (docs/control.md, "The study"), from the report's
campaign table: per joint, each law's paired change of a metric against ``pid`` over the
seeds (the same drawn plant and noise), and each law's paired change from the delay.

    python studies/controllers_table.py reports-study/campaigns/controllers-delay.parquet \
        [--metric max_abs_error]

Effect: the mean over seeds of the per-seed relative change ``(x - x_ref) / x_ref`` in
%, with its two-sided 95 % Student-t interval (n = seeds, paired; ``mean_ci``).
"""

from __future__ import annotations

import argparse

import polars as pl

from pipeline.analysis.aggregate import mean_ci

LAWS = ("pid", "pid_ff", "ctc", "ctc_pid", "passivity", "adaptive")
DELAY = "swept.loop.delay_s"


def _ci(values: list[float], digits: int = 0) -> str:
    ci = mean_ci(values)
    if ci.mean is None or ci.half_width is None:
        return "n/a"
    return f"{ci.mean:+.{digits}f} ± {ci.half_width:.{digits + 1}f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("table")
    parser.add_argument("--metric", default="max_abs_error")
    args = parser.parse_args()
    frame = pl.read_parquet(args.table).filter(pl.col("status") == "ok")
    metric = args.metric
    joints = list(dict.fromkeys(frame["joint"].to_list()))
    value = {
        (r["controller"], float(r[DELAY]), r["joint"], r["seed"]): r[metric]
        for r in frame.iter_rows(named=True)
    }
    seeds = sorted({k[3] for k in value})
    delays = sorted({k[1] for k in value})
    short = [j.replace("_joint", "") for j in joints]
    for delay in delays:
        print(f"\n{metric}, delay {delay * 1e3:g} ms: mean [mrad]; change vs pid [%]")
        print("| law | " + " | ".join(short) + " |")
        print("|" + "------|" * (len(joints) + 1))
        for law in LAWS:
            cells = []
            for j in joints:
                xs = [value.get((law, delay, j, s)) for s in seeds]
                ref = [value.get(("pid", delay, j, s)) for s in seeds]
                pairs = [(x, r) for x, r in zip(xs, ref, strict=True) if x is not None and r]
                mean = mean_ci([x for x, _ in pairs]).mean or float("nan")
                change = (
                    "" if law == "pid" else " (" + _ci([(x - r) / r * 100 for x, r in pairs]) + ")"
                )
                cells.append(f"{mean * 1e3:.2f}{change}")
            print(f"| {law} | " + " | ".join(cells) + " |")
    if len(delays) > 1:
        lo, hi = delays[0], delays[-1]
        print(f"\n{metric}: change from {lo * 1e3:g} to {hi * 1e3:g} ms delay, paired by seed [%]")
        print("| law | " + " | ".join(short) + " |")
        print("|" + "------|" * (len(joints) + 1))
        for law in LAWS:
            cells = []
            for j in joints:
                pairs = [(value.get((law, hi, j, s)), value.get((law, lo, j, s))) for s in seeds]
                cells.append(
                    _ci([(x - r) / r * 100 for x, r in pairs if x is not None and r], digits=2)
                )
            print(f"| {law} | " + " | ".join(cells) + " |")
    print(f"\nn = {len(seeds)} seeds per law and delay")


if __name__ == "__main__":
    main()
