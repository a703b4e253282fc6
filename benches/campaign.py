"""Campaign scale: parallel efficiency of the executors and a large campaign end to end.

Prints one JSON object.

``efficiency``: one campaign (the paper's motion on the realistic plant, pid and ctc,
``--eff-seeds`` seeds each) recorded in this process by ``record()`` with 1 job, 2 jobs
and the Ray executor on a local 2-CPU instance (started before the clock, as a cluster
is; worker start-up inside the clock). Efficiency = t(1 job) / (2 x t(executor)); the
targets are >= 0.9 (jobs 2) and >= 0.8 (Ray). Also checks the runs wrote the same bytes.

``scale``: ``--episodes`` episodes (pid and ctc, realistic plant, full-rate logging)
recorded with ``--jobs 2``, then ``pipeline report`` on them: wall time of each, the
peak resident memory of each command's process tree (sampled every 0.2 s), the
recordings' and the report's sizes. Targets for 10,000 episodes: record + report
<= 10 min, peak <= 4 GB, report outputs <= 100 MB.

Usage: python benches/campaign.py [--eff-seeds 20] [--episodes 1000] [--no-ray] [--no-scale]
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import psutil
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benches"))

from floor import Floor, floor_fields, floor_summary, measure_floor  # noqa: E402

CONTROL_DT_S = 0.001  # params.yaml's sim: 0.5 ms x 2


def _params(folder: Path, *, seeds: int) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["campaigns"] = {
        "bench": {"scenario": "paper-realistic", "controllers": ["pid", "ctc"], "seeds": seeds}
    }
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _timed(cmd: list[str]) -> tuple[float, int]:
    """Wall time [s] and peak RSS of the process tree [B] of ``cmd``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    peak = [0]
    stop = threading.Event()

    def sample() -> None:
        root = psutil.Process(proc.pid)
        while not stop.is_set():
            try:
                procs = [root, *root.children(recursive=True)]
                rss = 0
                for p in procs:
                    with contextlib.suppress(psutil.Error):
                        rss += p.memory_info().rss
                peak[0] = max(peak[0], rss)
            except psutil.Error:
                pass
            stop.wait(0.2)

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    _, err = proc.communicate()
    wall = time.perf_counter() - t0
    stop.set()
    thread.join()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{err.decode()[-2000:]}")
    return wall, peak[0]


def _digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not any(part.startswith(".") for part in p.relative_to(folder).parts):
            h.update(str(p.relative_to(folder)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def _size(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def _record_campaign(params: Path, out: Path, **kwargs: Any) -> tuple[float, float, int]:
    """Wall time [s] of recording the bench campaign in this process (plans included),
    the sum of the episodes' own wall times [s] (busy time of the workers) and their
    control steps."""
    from pipeline.params import load_params
    from pipeline.stages.campaign_run import completion_marker, plan_run
    from pipeline.stages.record import record

    loaded = load_params(params)
    run = plan_run(loaded, "bench", out=out)
    t0 = time.perf_counter()
    outcomes = record(
        loaded, run.pending, out_dir=run.out_dir, force=True, commit=run.commit,
        on_event=completion_marker(run, lambda *a: None), **kwargs,
    )  # fmt: skip
    wall = time.perf_counter() - t0
    bad = [o for o in outcomes if o.status != "ok"]
    if bad:
        raise SystemExit(f"{bad[0].name}: {bad[0].status}: {bad[0].reason}")
    steps = sum(round(o.duration_s / CONTROL_DT_S) + 1 for o in outcomes)
    return wall, sum(o.wall_s for o in outcomes), steps


def efficiency(tmp: Path, *, seeds: int, ray: bool, floor: Floor) -> dict[str, Any]:
    """record() on 1 job, 2 jobs and Ray (instance started before the clock: a cluster
    users already run; its workers' start-up and imports are inside the clock)."""
    params = _params(tmp, seeds=seeds)
    out: dict[str, Any] = {"episodes": 2 * seeds}
    # utilization = busy / (workers x wall): the executor's own overhead (idle workers,
    # planning, start-up), which CPU contention from other processes does not inflate
    for name, jobs in (("jobs1", 1), ("jobs2", 2)):
        wall, busy, steps = _record_campaign(params, tmp / name, jobs=jobs)
        out[f"{name}_s"] = round(wall, 2)
        out[f"{name}_converged"] = floor_fields(floor, control_steps=steps, wall_s=wall,
                                                cores=jobs)  # fmt: skip
        out[f"{name}_utilization"] = round(busy / (jobs * wall), 3)
    out["jobs2_efficiency"] = round(out["jobs1_s"] / (2 * out["jobs2_s"]), 3)
    digests = {_digest(tmp / name) for name in ("jobs1", "jobs2")}
    if ray:
        import ray as ray_

        t0 = time.perf_counter()
        ray_.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        out["ray_init_s"] = round(time.perf_counter() - t0, 2)
        try:
            wall, busy, _ = _record_campaign(params, tmp / "ray", executor="ray")
            out["ray_s"] = round(wall, 2)
            out["ray_utilization"] = round(busy / (2 * wall), 3)
        finally:
            ray_.shutdown()
        out["ray_efficiency"] = round(out["jobs1_s"] / (2 * out["ray_s"]), 3)
        digests.add(_digest(tmp / "ray"))
    out["same_bytes"] = len(digests) == 1
    return out


def scale(tmp: Path, *, episodes: int, floor: Floor) -> dict[str, Any]:
    params = _params(tmp, seeds=episodes // 2)
    rec, rep = tmp / "rec", tmp / "rep"
    record_s, record_peak = _timed(
        [sys.executable, "-m", "pipeline", "record", "--params", str(params), "--out", str(rec),
         "--campaign", "bench", "-j", "2"]
    )  # fmt: skip
    report_s, report_peak = _timed(
        [sys.executable, "-m", "pipeline", "report", "--recordings", str(rec), "--out", str(rep)]
    )
    runs = json.loads((rep / "metrics.json").read_text())["episodes"].values()
    steps = sum(round(e["end_s"] / CONTROL_DT_S) + 1 for e in runs)
    return {
        "episodes": 2 * (episodes // 2),
        "converged": floor_fields(floor, control_steps=steps, wall_s=record_s + report_s, cores=2),
        "record_s": round(record_s, 1),
        "report_s": round(report_s, 1),
        "total_s": round(record_s + report_s, 1),
        "record_peak_rss_mb": round(record_peak / 1e6),
        "report_peak_rss_mb": round(report_peak / 1e6),
        "recordings_mb": round(_size(rec) / 1e6),
        "report_outputs_mb": round(_size(rep) / 1e6, 1),
        "per_episode_record_s": round(record_s / episodes, 4),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eff-seeds", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--no-ray", action="store_true")
    parser.add_argument("--no-efficiency", action="store_true")
    parser.add_argument("--no-scale", action="store_true")
    args = parser.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True).stdout.strip()  # fmt: skip
    result: dict[str, Any] = {
        "commit": commit,
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "python": platform.python_version(),
    }
    floor = measure_floor()  # benches/floor.py, stated beside each figure
    with tempfile.TemporaryDirectory() as tmp:
        if not args.no_efficiency:
            result["efficiency"] = efficiency(
                Path(tmp) / "eff", seeds=args.eff_seeds, ray=not args.no_ray, floor=floor
            )
        if not args.no_scale:
            result["scale"] = scale(Path(tmp) / "scale", episodes=args.episodes, floor=floor)
    result["converged_floor"] = floor_summary(floor.merged(measure_floor()))
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
