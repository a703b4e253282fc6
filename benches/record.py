"""Record-stage speed: wall time per control step vs the physics floor, same run.

Prints one JSON object. The floor is a bare loop of ``mj_step`` plus one
Pinocchio RNEA call per step on the same UR5 model; the episode is the paper's
CTC episode with full logging (plan excluded, time-parameterization, control
loop and bag writing included). ``--jobs`` scaling runs ``pipeline record`` on
four episodes with 1 and 2 processes.

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
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.params import load_params  # noqa: E402
from pipeline.robots import load_spec  # noqa: E402
from pipeline.stages.record import plan_scenario, run_one  # noqa: E402


def physics_floor_s_per_step(n_steps: int) -> float:
    spec = load_spec("ur5")
    from pipeline.model.mjcf import build_mujoco_model
    from pipeline.model.urdf import build_pinocchio_model

    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    pmodel = build_pinocchio_model(spec)
    pdata = pmodel.createData()
    zero = np.zeros(spec.dof)
    t0 = time.perf_counter()
    for _ in range(n_steps):
        tau = pin.rnea(pmodel, pdata, data.qpos, data.qvel, zero)
        data.ctrl[:] = tau
        mujoco.mj_step(model, data)
    return (time.perf_counter() - t0) / n_steps


def episode_s_per_step(repeat: int) -> tuple[float, int]:
    params = load_params(REPO / "params.yaml")
    episode = next(e for e in params.episodes if e.controller.type == "ctc")
    plan = plan_scenario(episode.scenario_name, episode.scenario, params.source)
    best = float("inf")
    steps = 0
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            outcome = run_one(episode, plan, out_dir=Path(tmp), force=False, commit="")
            wall = time.perf_counter() - t0
        assert outcome.status == "ok", outcome.reason
        steps = round(outcome.duration_s / (episode.sim.physics_dt_s * episode.sim.control_period_steps)) + 1
        best = min(best, wall / steps)
    return best, steps


def jobs_scaling() -> dict[str, float]:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    base = dict(data["episodes"])
    for k, v in list(base.items()):
        for seed in (1,):
            data["episodes"][f"{k}-s{seed}"] = {**v, "seed": seed}
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        params = Path(tmp) / "params.yaml"
        params.write_text(yaml.safe_dump(data))
        for jobs in (1, 2):
            t0 = time.perf_counter()
            subprocess.run(
                [sys.executable, "-m", "pipeline", "record", "--params", str(params),
                 "--out", f"{tmp}/rec{jobs}", "--jobs", str(jobs)],
                check=True, capture_output=True, cwd=REPO,
            )  # fmt: skip
            out[f"jobs_{jobs}_wall_s"] = time.perf_counter() - t0
    out["episodes"] = float(len(data["episodes"]))
    out["speedup_2_jobs"] = out["jobs_1_wall_s"] / out["jobs_2_wall_s"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-jobs", action="store_true", help="skip the --jobs scaling run")
    args = ap.parse_args()
    floor = min(physics_floor_s_per_step(5000) for _ in range(args.repeat))
    per_step, steps = episode_s_per_step(args.repeat)
    result: dict[str, object] = {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "processor": platform.processor() or platform.machine()},  # fmt: skip
        "physics_floor_us_per_step": floor * 1e6,
        "ctc_episode_us_per_step": per_step * 1e6,
        "ctc_episode_steps": steps,
        "ratio_to_floor": per_step / floor,
        "target_ratio": 2.0,
        "real_time_factor": 1e-3 / per_step,
    }
    if not args.no_jobs:
        result["jobs"] = jobs_scaling()
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
