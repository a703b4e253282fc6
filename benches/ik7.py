"""7-DOF numeric IK benchmark (issue 17): success with FK verification and solve time.

    python benches/ik7.py              # the numbers in docs/BENCHMARKS.md
    python benches/ik7.py --quick      # 1,000 poses while developing

Protocol (targets from issue 17 and the kinematics notes):
- panda_dh (Franka's modified DH, 7 joints): N joint vectors uniform within the
  limits (rng seed 0) -> flange FK gives reachable targets; the numeric solver with
  its defaults (tolerance 1e-6 m / 1e-6 rad, seeded from the middle of the joint
  range, restarts allowed, null-space pull toward the middle of the ranges), one
  call per pose. Success = an answer within the limits whose FK is within the
  tolerance (>= 99.5 %); solve time p50 and p99 (p99 <= 5 ms). Wall clock
  (time.perf_counter_ns) and the thread's CPU time (time.thread_time_ns) around the
  solve only: on a shared machine the CPU time is what the solver itself costs.
- Peers in the same run: the same solver on ur5 (6 joints, the same protocol and
  count), the panda without the null-space pull (first 2,000 poses: what the pull
  costs, and how much nearer the rest posture it ends over the first 500), and
  Pinocchio's documented CLIK loop on the panda (damped pseudo-inverse, damping
  1e-12, step 0.1, <= 1000 iterations, no restarts, same tolerance; first 500
  poses).
The numeric solver restarts from the robot's seed table (FK samples, built once per
process on the first restart); each run builds it before the timed solves and
reports the build time apart (seed_table_build_s).
FK is the robot's Pinocchio model (kinematics.flange_pose); tests/kinematics
cross-check it against DH FK and against example-robot-data's panda URDF.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from typing import Any

import numpy as np
import pinocchio as pin
from ik import clik, cpu_model

from pipeline.kinematics import IKOptions, flange_pose, make_solver, pose_error
from pipeline.kinematics.seeds import seed_table
from pipeline.robots import RobotSpec, load_spec


def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return f"load average {os.getloadavg()}"


def machine() -> dict[str, Any]:
    return {
        "nproc": os.cpu_count(),
        "cpu": cpu_model(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "pinocchio": pin.__version__,
        "uptime_at_start": uptime(),
    }


def stats_ms(ns: np.ndarray) -> dict[str, float]:
    ms = ns * 1e-6
    return {
        "mean": float(ms.mean()),
        "p50": float(np.median(ms)),
        "p99": float(np.percentile(ms, 99)),
        "max": float(ms.max()),
    }


DISTANCE_POSES = 500


def targets_for(spec: RobotSpec, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    qs = np.random.default_rng(seed).uniform(spec.lower, spec.upper, (count, spec.dof))
    return qs, np.array([flange_pose(spec, q) for q in qs])


def bench_numeric(spec: RobotSpec, targets: np.ndarray, options: IKOptions) -> dict[str, Any]:
    solver = make_solver("numeric", spec, options=options)
    t0 = time.perf_counter_ns()
    seed_table(spec)  # built once per process, on the first restart: not a solve's cost
    table_s = (time.perf_counter_ns() - t0) * 1e-9
    n = len(targets)
    wall = np.empty(n)
    cpu = np.empty(n)
    iters = np.empty(n)
    restarts = np.empty(n)
    ok = 0
    unverified = 0
    rest_distance = np.full(n, np.nan)
    rest = 0.5 * (spec.lower + spec.upper)
    reasons: list[str] = []
    for i, target in enumerate(targets):
        c0, t0 = time.thread_time_ns(), time.perf_counter_ns()
        result = solver.solve(target)
        wall[i] = time.perf_counter_ns() - t0
        cpu[i] = time.thread_time_ns() - c0
        iters[i] = result.iterations
        restarts[i] = result.restarts
        if result.ok:
            q = result.solutions[0]
            pos, ang = pose_error(flange_pose(spec, q), target)
            inside = bool(np.all(q >= spec.lower) and np.all(q <= spec.upper))
            if pos <= options.tol_m and ang <= options.tol_rad and inside:
                ok += 1
                rest_distance[i] = float(np.linalg.norm(q - rest))
            else:
                unverified += 1
        elif len(reasons) < 6:
            reasons.append(f"pose {i}: {result.reason}")
    return {
        "robot": spec.name,
        "dof": spec.dof,
        "poses": n,
        "null_space_iterations": options.null_space_iterations,
        "success_rate": ok / n,
        "failed": n - ok,
        "answers_failing_fk_verification": unverified,
        "wall_ms": stats_ms(wall),
        "cpu_ms": stats_ms(cpu),
        "iterations": {"mean": float(iters.mean()), "p99": float(np.percentile(iters, 99))},
        "restarted_fraction": float((restarts > 0).mean()),
        "seed_table_build_s": table_s,
        # |q - rest| of the answers (rest: the middle of the ranges) over the first
        # DISTANCE_POSES poses, the ones the run without the pull solves too
        "distance_to_rest_rad_mean_first_poses": float(np.nanmean(rest_distance[:DISTANCE_POSES])),
        "failures": reasons,
    }


def bench_clik(spec: RobotSpec, targets: np.ndarray, tol: float) -> dict[str, Any]:
    """Pinocchio's documented CLIK example (:func:`ik.clik`): success = converged to an
    answer within the joint limits."""
    wall, answers = clik(spec, targets, tol)
    inside = np.all((answers >= spec.lower) & (answers <= spec.upper), axis=1)  # NaN: False
    return {"poses": len(targets), "success_rate_within_limits": float(inside.mean()),
            "wall_ms": stats_ms(wall)}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000 poses (development)")
    parser.add_argument("--robot", default="panda_dh", help="the redundant arm to measure")
    parser.add_argument("--peer", default="ur5", help="the 6-joint arm run alongside")
    args = parser.parse_args()
    n, n_plain, n_clik = (1000, 500, 100) if args.quick else (10_000, 2000, 500)
    assert n_plain >= DISTANCE_POSES
    info = machine()
    options = IKOptions()
    spec = load_spec(args.robot)
    _, targets = targets_for(spec, n, seed=0)
    peer = load_spec(args.peer)
    _, peer_targets = targets_for(peer, n, seed=0)

    main_run = bench_numeric(spec, targets, options)
    peer_run = bench_numeric(peer, peer_targets, options)
    no_pull = bench_numeric(spec, targets[:n_plain], IKOptions(null_space_iterations=0))
    clik = bench_clik(spec, targets[:n_clik], options.tol_m)
    out = {
        "benchmark": "ik7",
        "command": " ".join([os.path.basename(sys.executable), *sys.argv]),
        "machine": {**info, "uptime_at_end": uptime()},
        "tolerance_m": options.tol_m,
        "tolerance_rad": options.tol_rad,
        "numeric": main_run,
        "peer_numeric_6dof": peer_run,
        "numeric_without_pull": no_pull,
        "clik_baseline": clik,
        "targets": {
            "success_ge_99.5pct": main_run["success_rate"] >= 0.995,
            "wall_p99_le_5ms": main_run["wall_ms"]["p99"] <= 5.0,
            "cpu_p99_le_5ms": main_run["cpu_ms"]["p99"] <= 5.0,
        },
    }
    sys.stdout.write(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
