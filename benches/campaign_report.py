"""Campaign report speed: ``pipeline report`` on a campaign of really recorded episodes.

Records one campaign with the project's own recorder (``pipeline record --campaign``,
``--jobs 2``): the paper's motion on the realistic plant (a drawn plant per seed,
friction, noise), pid, ctc and ctc_pid, full-rate logging; then times ``pipeline report``
on it in a fresh process (wall time, peak RSS of the process tree, sampled every 0.2 s).
Nothing is synthesised: every episode is a real recording with its own plant draw.

With ``--profile`` the report runs once more under cProfile and the 20 functions with
the largest cumulative time are printed (stderr) and returned in the JSON.

Target (issue 20): a campaign report of 1,000 episodes in <= 60 s on this machine. When
``--episodes`` is below 1,000 the JSON also gives a linear extrapolation to 1,000
(labelled ``extrapolated``): fixed cost (figures, .rrd) + per-episode cost, where the
per-episode cost is taken from the two largest sizes when ``--sizes`` gives two or more.
The campaign is recorded once, at the largest size; a smaller size reports the first N of
its episodes, seed by seed (hard links to the same files: real recordings, each its own
episode).

Prints one JSON object. Usage:
    python benches/campaign_report.py [--episodes 201] [--sizes 99,201] [--jobs 2]
        [--repeat 3] [--work /tmp/campaign_report] [--profile] [--profile-out F] [--keep]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import platform
import pstats
import resource
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import psutil
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benches"))
from floor import floor_fields, floor_summary, measure_floor, steps_in_report  # noqa: E402

CONTROLLERS = ("pid", "ctc", "ctc_pid")
TARGET_EPISODES = 1000
TARGET_S = 60.0
CPU_S: list[float] = []  # CPU time of each timed command [s]


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _params(folder: Path, *, seeds: int) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["campaigns"] = {
        "bench": {"scenario": "paper-realistic", "controllers": list(CONTROLLERS), "seeds": seeds}
    }
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _timed(cmd: list[str]) -> tuple[float, int]:
    """Wall time [s] and peak RSS of the process tree [B] of ``cmd`` (fails loudly); its CPU
    time (user + system, the workers it waited for included) goes to :data:`CPU_S`."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    peak = [0]
    stop = threading.Event()

    def sample() -> None:
        root = psutil.Process(proc.pid)
        while not stop.wait(0.2):
            try:
                procs = [root, *root.children(recursive=True)]
                peak[0] = max(peak[0], sum(p.memory_info().rss for p in procs))
            except psutil.Error:
                pass

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    _, err = proc.communicate()
    wall = time.perf_counter() - t0
    stop.set()
    thread.join()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    CPU_S.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{err.decode()[-2000:]}")
    return wall, peak[0]


def _record(work: Path, *, seeds: int, jobs: int) -> tuple[Path, float]:
    """The campaign's recordings (recorded once per seed count, then reused)."""
    recordings = work / f"recordings-{seeds}"
    params = _params(work / f"params-{seeds}", seeds=seeds)
    cmd = [sys.executable, "-m", "pipeline", "record", "--params", str(params),
           "--out", str(recordings), "--campaign", "bench", "--jobs", str(jobs)]  # fmt: skip
    wall, _ = _timed(cmd)  # a re-run skips the episodes already recorded
    return recordings, wall


def _episodes(recordings: Path) -> list[Path]:
    """The campaign's episode folders (not its ``.done`` fingerprints), seed by seed
    (``ctc.s0, ctc_pid.s0, pid.s0, ctc.s1, ...``): the first N hold every controller."""

    def seed_first(p: Path) -> tuple[int, str]:
        _, _, seed = p.name.rpartition(".s")
        return (int(seed) if seed.isdigit() else 0, p.name)

    found = (p for p in (recordings / "bench").iterdir() if not p.name.startswith("."))
    return sorted(found, key=seed_first)


def _subset(work: Path, episodes: list[Path]) -> Path:
    """A recordings folder holding ``episodes`` (hard links to their files)."""
    root = work / f"subset-{len(episodes)}"
    shutil.rmtree(root, ignore_errors=True)
    for ep in episodes:
        shutil.copytree(ep, root / "bench" / ep.name, copy_function=os.link)
    return root


def _report_cmd(recordings: Path, out: Path, jobs: int | None) -> list[str]:
    return [sys.executable, "-m", "pipeline", "report", "--recordings", str(recordings),
            "--out", str(out), "--baseline", "pid",
            *(["--jobs", str(jobs)] if jobs else [])]  # fmt: skip


def _profile(recordings: Path, out: Path, save: str, top: int = 20) -> list[dict[str, Any]]:
    """cProfile of an in-process report: the ``top`` functions by cumulative time."""
    from pipeline.stages.report import run_report

    prof = cProfile.Profile()
    prof.enable()
    run_report(recordings_dir=recordings, out_dir=out, baseline="pid")
    prof.disable()
    if save:
        prof.dump_stats(save)
    buf = io.StringIO()
    stats = pstats.Stats(prof, stream=buf).sort_stats("cumulative")
    stats.print_stats(top)
    print(buf.getvalue(), file=sys.stderr)
    rows = []
    for (file, line, name), (_, ncalls, tottime, cumtime, _) in sorted(
        stats.stats.items(),  # type: ignore[attr-defined]
        key=lambda kv: -kv[1][3],
    )[:top]:
        where = file.replace(str(REPO) + "/", "")
        rows.append(
            {"function": f"{where}:{line}({name})", "calls": ncalls,
             "tottime_s": round(tottime, 3), "cumtime_s": round(cumtime, 3)}
        )  # fmt: skip
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=201, help="largest size (3 controllers)")
    ap.add_argument("--sizes", default="", help="comma-separated sizes (default: --episodes)")
    ap.add_argument("--jobs", type=int, default=2, help="record workers")
    ap.add_argument(
        "--report-jobs", default="", help="comma-separated `report -j` values (default: its own)"
    )
    ap.add_argument("--work", default="/tmp/campaign_report_bench")
    ap.add_argument("--repeat", type=int, default=1, help="report runs per size (best kept)")
    ap.add_argument("--profile", action="store_true", help="cProfile the largest size")
    ap.add_argument("--profile-out", default="", help="also write the cProfile stats here")
    ap.add_argument("--keep", action="store_true", help="keep the recordings and reports")
    ap.add_argument(
        "--recordings", default="", help="report on this recorded campaign (recorded before)"
    )
    args = ap.parse_args()
    sizes = sorted({int(s) for s in args.sizes.split(",") if s} | {args.episodes})
    report_jobs: list[int | None] = [int(j) for j in args.report_jobs.split(",") if j] or [None]
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    sys.path.insert(0, str(REPO))
    floor = measure_floor()  # benches/floor.py, stated beside each report time

    out: dict[str, Any] = {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "target": f"{TARGET_EPISODES} episodes in <= {TARGET_S:g} s",
        "runs": [],
    }
    # recorded once at the largest size; a smaller size is the first N of its episodes
    # (hard links of the same files: real recordings, each its own episode)
    seeds = -(-max(sizes) // len(CONTROLLERS))
    if args.recordings:  # a record run outside git would re-record: its commit differs
        full, record_s = Path(args.recordings), 0.0
    else:
        full, record_s = _record(work, seeds=seeds, jobs=args.jobs)
    out["record_s"] = round(record_s, 1)
    out["record_jobs"] = args.jobs
    episodes = _episodes(full)
    for size in sizes:
        recordings = full if size >= len(episodes) else _subset(work, episodes[:size])
        n = len(_episodes(recordings))
        bag_bytes = sum(p.stat().st_size for p in recordings.rglob("*") if p.is_file())
        load_before = _load()
        for jobs in report_jobs:
            report_dir = work / f"report-{n}-j{jobs or 'default'}"
            walls, cpus, peak = [], [], 0
            for _ in range(args.repeat):
                shutil.rmtree(report_dir, ignore_errors=True)
                w, p = _timed(_report_cmd(recordings, report_dir, jobs))
                walls.append(w)
                cpus.append(CPU_S[-1])
                peak = max(peak, p)
            wall = min(walls)
            outputs = sum(p.stat().st_size for p in report_dir.rglob("*") if p.is_file())
            _, steps = steps_in_report(report_dir / "metrics.json")
            out["runs"].append(
                {
                    "converged": floor_fields(
                        floor, control_steps=steps, wall_s=wall, cpu_s=min(cpus)
                    ),
                    "episodes": n,
                    "report_jobs": jobs or "default",
                    "recordings_mb": round(bag_bytes / 1e6, 1),
                    "report_s": round(wall, 2),
                    "report_s_every_run": [round(w, 2) for w in walls],
                    "report_cpu_s_every_run": [round(c, 1) for c in cpus],
                    "report_ms_per_episode": round(1000 * wall / n, 1),
                    "report_peak_rss_mb": round(peak / 1e6),
                    "report_outputs_mb": round(outputs / 1e6, 1),
                    "load_before": load_before,
                    "load_after": _load(),
                }
            )
            print(json.dumps(out["runs"][-1]), file=sys.stderr)
            load_before = _load()
    # the verdict (or the extrapolation) of the last --report-jobs value
    runs = [r for r in out["runs"] if r["report_jobs"] == out["runs"][-1]["report_jobs"]]
    big = runs[-1]
    for r in out["runs"]:
        if r["episodes"] >= TARGET_EPISODES:
            r["verdict"] = "met" if r["report_s"] <= TARGET_S else "missed"
    if big["episodes"] < TARGET_EPISODES:
        if len(runs) > 1:
            small = runs[-2]
            per = (big["report_s"] - small["report_s"]) / (big["episodes"] - small["episodes"])
            fixed = big["report_s"] - per * big["episodes"]
        else:
            per, fixed = big["report_s"] / big["episodes"], 0.0
        est = fixed + per * TARGET_EPISODES
        out["extrapolated"] = {
            "episodes": TARGET_EPISODES,
            "report_s": round(est, 1),
            "marginal_ms_per_episode": round(1000 * per, 1),
            "fixed_s": round(fixed, 1),
            "verdict (extrapolated)": "met" if est <= TARGET_S else "missed",
        }
    if args.profile:
        recordings = full if big["episodes"] >= len(episodes) else _subset(work, episodes)
        shutil.rmtree(work / "report-profile", ignore_errors=True)
        out["profile_top20_cumulative"] = _profile(
            recordings, work / "report-profile", args.profile_out
        )
    out["converged_floor"] = floor_summary(floor.merged(measure_floor()))
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
