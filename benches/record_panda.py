"""Record-stage speed on a URDF robot: a Panda episode with full logging against its
physics floor, measured in the same run (issue 17).

Prints one JSON object. The episodes are params.yaml's Panda experiment
(``extra_campaigns.panda-box``: a drawn realistic plant, friction, damping, sensor noise),
seed 0 of each controller, each run whole by ``run_one`` exactly as ``pipeline record``
runs it (plant and controller setup, control loop, contact check, bag encode, compress
and write); planning and time-parameterization are excluded (once per scenario, shared by
its controllers). The floor, per control step: the control period's ``mj_step`` calls
plus one Pinocchio RNEA on the Panda, nominal plant, the scenario's integrator and step
(``campaign_profile.physics_floor_s``); the drawn-plant floor is the same loop on the
episode's own plant (Coulomb friction runs MuJoCo's constraint solver every step). Floors
and episodes are interleaved, best of ``--repeat``, so other load hits both.

Also checked: the robot is built once per process (the loader's, the MJCF compile's and
Pinocchio's caches: their hits and misses after every episode ran).

Usage: python benches/record_panda.py [--repeat 3] [--controllers pid,ctc,ctc_pid]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benches"))

from campaign_profile import episode_wall_s, physics_floor_s  # noqa: E402
from floor import floor_summary, measure_floor, per_step_ratio  # noqa: E402

from pipeline.model import mjcf  # noqa: E402
from pipeline.params import load_params  # noqa: E402
from pipeline.robots import loaders, urdf  # noqa: E402
from pipeline.stages.campaign_expand import expand  # noqa: E402
from pipeline.stages.plans import plan_scenario  # noqa: E402

CAMPAIGN = "panda-box"
TARGET_RATIO = 2.5  # issue 17: a Panda episode with full logging <= 2.5x its floor


def _shell(*cmd: str) -> str:
    return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO).stdout.strip()


def _caches() -> dict[str, dict[str, int]]:
    caches = {
        "load_spec (built-in robot)": loaders._load_builtin,
        "MJCF compile": mjcf.compiled_model,
        "Pinocchio model": urdf.pinocchio_model,
        "URDF text": urdf.build_urdf,
    }
    return {k: {"hits": f.cache_info().hits, "misses": f.cache_info().misses}
            for k, f in caches.items()}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--controllers", default="pid,ctc,ctc_pid")
    args = ap.parse_args()
    result: dict[str, Any] = {
        "commit": _shell("git", "rev-parse", "--short", "HEAD"),
        "uptime_before": _shell("uptime"),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
    }
    t0 = time.perf_counter()
    loaders.load_spec("panda")
    first_load_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    loaders.load_spec("panda")
    result["load_spec_ms"] = {"first": round(1e3 * first_load_s, 2),
                              "again": round(1e3 * (time.perf_counter() - t0), 4)}  # fmt: skip
    converged = measure_floor(scenario=CAMPAIGN)  # benches/floor.py on the Panda's plant
    params = load_params(REPO / "params.yaml")
    wanted = args.controllers.split(",")
    episodes = [e for e in expand(params, CAMPAIGN) if e.seed == 0 and e.controller_name in wanted]
    plan = plan_scenario(episodes[0].scenario_name, episodes[0].scenario, params.source)
    cold_s, _ = episode_wall_s(episodes[0], plan)  # the first: compiles and caches
    best: dict[str, dict[str, float]] = {
        e.controller_name: {"episode": float("inf"), "floor": float("inf"),
                            "plant_floor": float("inf")}
        for e in episodes
    }  # fmt: skip
    steps: dict[str, int] = {}
    for _ in range(args.repeat):
        for e in episodes:
            b = best[e.controller_name]
            wall_s, n = episode_wall_s(e, plan)
            steps[e.controller_name] = n
            b["episode"] = min(b["episode"], wall_s)
            b["floor"] = min(b["floor"], physics_floor_s(e, n))
            b["plant_floor"] = min(b["plant_floor"], physics_floor_s(e, n, drawn=True))
    converged = converged.merged(measure_floor(scenario=CAMPAIGN))
    rows = {}
    for name, b in best.items():
        n = steps[name]
        rows[name] = {
            "control_steps": n,
            "episode_s": round(b["episode"], 3),
            "us_per_control_step": round(1e6 * b["episode"] / n, 1),
            "floor_us_per_control_step": round(1e6 * b["floor"] / n, 1),
            "plant_floor_us_per_control_step": round(1e6 * b["plant_floor"] / n, 1),
            "ratio_to_floor": round(b["episode"] / b["floor"], 2),
            "ratio_to_plant_floor": round(b["episode"] / b["plant_floor"], 2),
            "x_converged_floor": per_step_ratio(converged, 1e6 * b["episode"] / n),
        }
    worst = max(r["ratio_to_floor"] for r in rows.values())
    result |= {
        "first_episode_s (cold: builds and caches)": round(cold_s, 3),
        "episodes": rows,
        "converged_floor": floor_summary(converged),
        "worst_ratio_to_floor": worst,
        "target_ratio_to_floor": TARGET_RATIO,
        "met": worst <= TARGET_RATIO,
        "caches after all episodes": _caches(),
        "uptime_after": _shell("uptime"),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
