"""Benchmark: RRTConnect around a box that blocks the straight joint-space segment.

The scenario of the planning tests: UR5, the paper's start and goal, a 6 cm cube
beside the midpoint of the flange positions so that the straight segment hits
it. Each seed is one ``plan_path`` call, timed whole (checker build, start/goal
checks, solve, OMPL simplification + shortcut rounds, the independent re-check
of the result); ``planning_time_s`` (solve + simplification) is reported too.
Wall-clock and process CPU time are both given: the machine is shared, and CPU
time moves less with other load. Also counted: configurations checked
(``mj_kinematics`` + ``mj_collision`` calls) per plan.

Run: ``python benches/planning.py [--seeds 20] [--repeats 2]``; prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from safety import blocking_box

from pipeline.planning import plan_path
from pipeline.robots import load_spec
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD

TARGET_MEDIAN_MS = 50.0


def _count_checks() -> list[int]:
    """Count mj_collision calls from here on (wraps the module attribute)."""
    counter = [0]
    original = mujoco.mj_collision

    def counted(model: Any, data: Any) -> None:
        counter[0] += 1
        original(model, data)

    mujoco.mj_collision = counted
    return counter


def measure(*, seeds: int = 20, repeats: int = 2) -> dict[str, Any]:
    spec = load_spec("ur5")
    box = blocking_box(spec)
    plan_path(spec, start=PAPER_START_RAD, goal=PAPER_GOAL_RAD, obstacles=[box], seed=0)  # warm
    wall: dict[int, float] = {}
    cpu: dict[int, float] = {}
    inner: dict[int, float] = {}
    for _ in range(repeats):
        for seed in range(seeds):
            t0, c0 = time.perf_counter(), time.process_time()
            path = plan_path(
                spec, start=PAPER_START_RAD, goal=PAPER_GOAL_RAD, obstacles=[box], seed=seed
            )
            w, c = time.perf_counter() - t0, time.process_time() - c0
            wall[seed] = min(wall.get(seed, float("inf")), w)
            cpu[seed] = min(cpu.get(seed, float("inf")), c)
            inner[seed] = min(inner.get(seed, float("inf")), path.planning_time_s)
    counter = _count_checks()
    checks, lengths, direct = [], [], 0
    for seed in range(seeds):
        c0 = counter[0]
        path = plan_path(
            spec, start=PAPER_START_RAD, goal=PAPER_GOAL_RAD, obstacles=[box], seed=seed
        )
        checks.append(counter[0] - c0)
        lengths.append(path.path_length_rad)
        direct += path.direct

    def ms(values: dict[int, float]) -> dict[str, float]:
        v = sorted(values.values())
        return {
            "median": 1e3 * statistics.median(v),
            "p90": 1e3 * float(np.percentile(v, 90)),
            "max": 1e3 * v[-1],
        }

    return {
        "seeds": seeds,
        "repeats_best_of": repeats,
        "plan_path_wall_ms": ms(wall),
        "plan_path_cpu_ms": ms(cpu),
        "planning_time_s_ms": ms(inner),
        "configurations_checked_median": statistics.median(checks),
        "path_length_rad": {
            "median": statistics.median(lengths),
            "max": max(lengths),
            "straight": float(np.linalg.norm(np.subtract(PAPER_GOAL_RAD, PAPER_START_RAD))),
        },
        "direct_plans": direct,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    result = measure(seeds=args.seeds, repeats=args.repeats)
    median = result["plan_path_wall_ms"]["median"]
    out = {
        "benchmark": "planning",
        "command": "python benches/planning.py",
        "machine": {
            "nproc": os.cpu_count(),
            "python": platform.python_version(),
            "mujoco": mujoco.__version__,
            "loadavg_1min_at_start": load0,
            "loadavg_1min_at_end": os.getloadavg()[0],
        },
        **result,
        "target_median_ms": TARGET_MEDIAN_MS,
        "met": median <= TARGET_MEDIAN_MS,
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
