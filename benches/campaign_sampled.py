"""A sampled campaign end to end: ``keep_bags: {every: k}`` recorded, reported, weighed.

Records the ``paper-realistic`` campaign (pid and ctc x ``--seeds`` seeds: a drawn plant
per seed, friction, sensor noise, RK4 0.5 ms, full-rate logging) with
``keep_bags: {every: --every}`` by ``pipeline record --campaign --jobs`` in a fresh
process (its wall time and the peak RSS of its process tree, sampled every 0.2 s; the
median and worst per controller are re-run into bags inside it), then ``pipeline report``
on it in a fresh process (the same figures), then weighs the campaign folder: bags,
metric partials, their shared parts and the completion marks, in bytes (apparent) and
on disk (allocated blocks). The disk use is extrapolated to 10,000 episodes: every k-th
episode's bag (at this run's mean bag size), the sample's re-runs, and a partial and mark
for every episode.

Targets: issue 20, a 1,000-episode campaign report in <= 60 s; issue 21, a 10,000-episode
sampled campaign <= 1 GB on disk.

With ``--worker N`` it instead times, in this process, what a worker does for one
episode it keeps as its partial, on one pid and one ctc episode, N times each,
interleaved: the former way (write the bag, read it back, measure it:
``write_episode_bag`` + ``measure_bag``) against the recording made in memory
(``episode_recording`` + ``measure_recording``), medians in ms.

Prints one JSON object. Usage:
    python benches/campaign_sampled.py [--seeds 500] [--every 20] [--jobs 2]
        [--work /tmp/campaign_sampled] [--keep] [--worker N]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import yaml
from campaign_report import _timed  # the wall time and peak RSS of a command's tree

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benches"))
from floor import floor_fields, floor_summary, measure_floor, steps_in_report  # noqa: E402

CONTROLLERS = ("pid", "ctc")
TARGET_REPORT_S = 60.0
TARGET_DISK_B = 1e9
SCALE_EPISODES = 10_000


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _params(work: Path, *, seeds: int, every: int) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["campaigns"] = {
        "bench": {
            "scenario": "paper-realistic",
            "controllers": list(CONTROLLERS),
            "seeds": seeds,
            "keep_bags": {"every": every},
        }
    }
    path = work / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _weigh(campaign: Path) -> dict[str, dict[str, int]]:
    """Files, apparent bytes and allocated bytes per part of the campaign folder."""
    parts: dict[str, dict[str, int]] = {}
    for root, _, files in os.walk(campaign):
        rel = Path(root).relative_to(campaign).parts
        if not rel:
            continue
        part = {".done": "marks", ".partials": "partials"}.get(rel[0], "bags")
        part = "shared" if rel[:2] == (".partials", "shared") else part
        entry = parts.setdefault(part, {"files": 0, "bytes": 0, "disk_bytes": 0, "folders": 0})
        entry["folders"] += 1
        for name in files:
            st = os.stat(Path(root) / name)
            entry["files"] += 1
            entry["bytes"] += st.st_size
            entry["disk_bytes"] += st.st_blocks * 512
    return parts


def _worker(work: Path, reps: int) -> dict[str, Any]:
    """Per-episode worker cost of a partial: from its bag vs made in memory [ms]."""
    import statistics
    import time

    sys.path.insert(0, str(REPO))
    from pipeline.log.bag import write_episode_bag
    from pipeline.log.streams import EpisodeStreams
    from pipeline.log.whole import episode_recording
    from pipeline.params import load_params
    from pipeline.stages import episode as episode_stage
    from pipeline.stages.campaign_run import plan_run
    from pipeline.stages.partials import measure_bag, measure_recording
    from pipeline.stages.record import record

    params = load_params(_params(work, seeds=1, every=2))
    run = plan_run(params, "bench", out=work / "worker")
    captured: dict[str, tuple[Path, dict[str, Any]]] = {}

    def capture(episode: Any, bag_dir: Path, recorded: dict[str, Any], *, force: bool) -> None:
        del force
        captured[episode.name] = (bag_dir, recorded)

    episode_stage._write_outputs = capture
    record(params, run.pending, out_dir=run.out_dir, force=True, commit=run.commit)
    times: dict[str, dict[str, list[float]]] = {}
    for name, (bag_dir, recorded) in captured.items():
        t = times.setdefault(name, {"bag_write_read_measure": [], "in_memory_measure": []})
        for _ in range(reps):
            t0 = time.perf_counter()
            write_episode_bag(bag_dir, **recorded, force=True)
            measure_bag(bag_dir, measure_code="")
            t1 = time.perf_counter()
            measure_recording(
                episode_recording(EpisodeStreams.of(**recorded), bag_dir), measure_code=""
            )
            t2 = time.perf_counter()
            t["bag_write_read_measure"].append(1e3 * (t1 - t0))
            t["in_memory_measure"].append(1e3 * (t2 - t1))
    out = {}
    for name, t in times.items():
        med = {k: round(statistics.median(v), 1) for k, v in t.items()}
        med["ratio"] = round(med["in_memory_measure"] / med["bag_write_read_measure"], 3)
        out[name] = med
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=500, help="per controller (pid, ctc)")
    ap.add_argument("--every", type=int, default=20)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--work", default="/tmp/campaign_sampled")
    ap.add_argument("--keep", action="store_true", help="keep the recordings and report")
    ap.add_argument("--worker", type=int, default=0, help="time one worker's partial, N times")
    args = ap.parse_args()
    work = Path(args.work)
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    if args.worker:
        load = _load()
        print(json.dumps({"load_before": load, "worker_ms": _worker(work, args.worker),
                          "load_after": _load()}, indent=2))  # fmt: skip
        shutil.rmtree(work, ignore_errors=True)
        return
    floor = measure_floor()  # benches/floor.py, stated beside the record and report times
    params = _params(work, seeds=args.seeds, every=args.every)
    episodes = args.seeds * len(CONTROLLERS)
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True
    ).stdout.strip()
    out: dict[str, Any] = {"commit": commit, "episodes": episodes, "every": args.every,
                           "jobs": args.jobs, "load_before": _load()}  # fmt: skip
    recordings = work / "recordings"
    record = [sys.executable, "-m", "pipeline", "record", "--params", str(params), "--out",
              str(recordings), "--campaign", "bench", "--jobs", str(args.jobs)]  # fmt: skip
    wall, peak = _timed(record)
    out["record"] = {"wall_s": round(wall, 1), "per_episode_ms": round(1e3 * wall / episodes, 1),
                     "peak_rss_mb": round(peak / 2**20), "load_after": _load()}  # fmt: skip
    report = [sys.executable, "-m", "pipeline", "report", "--recordings", str(recordings),
              "--out", str(work / "report"), "--baseline", "pid"]  # fmt: skip
    wall, peak = _timed(report)
    out["report"] = {"wall_s": round(wall, 1), "peak_rss_mb": round(peak / 2**20),
                     "target_s": TARGET_REPORT_S, "met": wall <= TARGET_REPORT_S,
                     "load_after": _load()}  # fmt: skip
    floor = floor.merged(measure_floor())
    _, steps = steps_in_report(work / "report" / "metrics.json")
    out["converged_floor"] = floor_summary(floor)
    for key in ("record", "report"):
        out[key] |= floor_fields(floor, control_steps=steps, wall_s=out[key]["wall_s"],
                                 cores=args.jobs)  # fmt: skip
    out["record_plus_report"] = floor_fields(
        floor, control_steps=steps, wall_s=out["record"]["wall_s"] + out["report"]["wall_s"],
        cores=args.jobs,
    )  # fmt: skip
    parts = _weigh(recordings / "bench")
    out["disk"] = parts
    bags = parts.get("bags", {"folders": 0, "bytes": 0, "disk_bytes": 0})
    kept = bags["folders"]
    partial = parts["partials"]
    marks = parts["marks"]
    per_bag = bags["disk_bytes"] / max(kept, 1)
    per_episode = (partial["disk_bytes"] + marks["disk_bytes"]) / episodes
    sample = kept - math.ceil(episodes / args.every)  # the median and worst, re-run
    scale_kept = math.ceil(SCALE_EPISODES / args.every) + sample
    total = scale_kept * per_bag + SCALE_EPISODES * per_episode + parts["shared"]["disk_bytes"]
    out["per_episode"] = {
        "bag_bytes": round(bags["bytes"] / max(kept, 1)),
        "partial_bytes": round(partial["bytes"] / episodes),
        "partial_disk_bytes": round(partial["disk_bytes"] / episodes),
        "mark_disk_bytes": round(marks["disk_bytes"] / episodes),
        "campaign_disk_bytes": round(sum(p["disk_bytes"] for p in parts.values()) / episodes),
    }
    out["extrapolated_10000"] = {
        "kept_bags": scale_kept,
        "disk_gb": round(total / 1e9, 3),
        "of_which_bags_gb": round(scale_kept * per_bag / 1e9, 3),
        "full_bags_gb": round(SCALE_EPISODES * per_bag / 1e9, 2),
        "target_gb": TARGET_DISK_B / 1e9,
        "met": total <= TARGET_DISK_B,
    }
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
