"""Record-stage speed: wall time per control step vs the physics floor, same run.

Prints one JSON object. The floor is a bare loop of ``mj_step`` plus one
Pinocchio RNEA call per step on the same UR5 model; the episode is the paper's
CTC episode with full logging: controller and plant setup, control loop and bag
writing included; planning and time-parameterization excluded (done once per
scenario, shared by its controllers). ``--jobs`` scaling runs ``pipeline record``
on four episodes with 1 and 2 processes.

Usage: python benches/record.py [--repeat 3] [--no-jobs]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benches"))

from sim_loop import physics_floor_s  # noqa: E402

from pipeline.params import load_params  # noqa: E402
from pipeline.robots import load_spec  # noqa: E402
from pipeline.stages.episode import run_one  # noqa: E402
from pipeline.stages.plans import plan_scenario  # noqa: E402


def physics_floor_s_per_step(n_steps: int) -> float:
    return physics_floor_s(load_spec("ur5"), steps=n_steps) / n_steps


def _episode_wall_s(hold_s: float, repeat: int) -> tuple[float, int]:
    """Best wall time of the paper's CTC episode (plan and timing excluded) and its steps."""
    params = load_params(REPO / "params.yaml")
    episode = next(e for e in params.episodes if e.controller.type == "ctc")
    scenario = episode.scenario.model_copy(update={"hold_s": hold_s})
    episode = replace(episode, scenario=scenario)
    plan = plan_scenario(episode.scenario_name, scenario, params.source)
    best = float("inf")
    steps = 0
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            outcome = run_one(episode, plan, out_dir=Path(tmp), force=False, commit="")
            best = min(best, time.perf_counter() - t0)
        assert outcome.status == "ok", outcome.reason
        control_dt_s = episode.sim.physics_dt_s * episode.sim.control_period_steps
        steps = round(outcome.duration_s / control_dt_s) + 1
    return best, steps


def jobs_scaling(hold_s: float) -> dict[str, float]:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = hold_s
    for key, value in list(data["episodes"].items()):
        data["episodes"][f"{key}-b"] = {**value, "seed": value.get("seed", 0) + 1}
    out: dict[str, float] = {"episodes": float(len(data["episodes"])), "hold_s": hold_s}
    with tempfile.TemporaryDirectory() as tmp:
        params = Path(tmp) / "params.yaml"
        params.write_text(yaml.safe_dump(data))
        for jobs in (1, 2):
            cmd = [sys.executable, "-m", "pipeline", "record", "--params", str(params)]
            cmd += ["--out", f"{tmp}/rec{jobs}", "--jobs", str(jobs)]
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, cwd=REPO)
            out[f"jobs_{jobs}_wall_s"] = time.perf_counter() - t0
    out["speedup_2_jobs"] = out["jobs_1_wall_s"] / out["jobs_2_wall_s"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-jobs", action="store_true", help="skip the --jobs scaling run")
    args = ap.parse_args()
    floor = min(physics_floor_s_per_step(5000) for _ in range(args.repeat))
    paper_s, paper_steps = _episode_wall_s(1.0, args.repeat)
    long_s, long_steps = _episode_wall_s(31.0, args.repeat)
    marginal = (long_s - paper_s) / (long_steps - paper_steps)
    machine = {
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    result: dict[str, object] = {
        "machine": machine,
        "physics_floor_us_per_step": floor * 1e6,
        "paper_ctc_episode": {
            "steps": paper_steps,
            "wall_s": paper_s,
            "us_per_step": paper_s / paper_steps * 1e6,
            "ratio_to_floor": paper_s / paper_steps / floor,
        },
        "marginal_per_step": {
            "note": "(31 s-hold episode - paper episode) / extra steps: excludes fixed setup",
            "us_per_step": marginal * 1e6,
            "ratio_to_floor": marginal / floor,
        },
        "target_ratio_to_floor": 2.0,
        "real_time_factor_paper_episode": 1e-3 * paper_steps / paper_s,
    }
    if not args.no_jobs:
        result["jobs"] = jobs_scaling(hold_s=240.0)
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
