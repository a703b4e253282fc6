"""Benchmark: post-hoc execution safety (``assess_execution``) per trajectory sample.

A 3000-sample UR5 trajectory (the paper's motion as a 3 s minimum-jerk
profile at 1 kHz) is assessed whole (checker build included) with no
obstacle, and with the planning tests' blocking box on the straight path
(which the arm then crosses, so the exact robot–box distances run on many
rows). Peer: a bare loop of ``mj_kinematics`` + ``mj_collision`` on the same
model, the least any per-sample MuJoCo check can cost. Best of ``repeats``.

Run: ``python benches/safety.py [--samples 3000] [--repeats 5]``; prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import mujoco
import numpy as np

from pipeline.model.dh import forward_kinematics
from pipeline.model.mjcf import Box
from pipeline.planning.collision import CollisionChecker
from pipeline.robots import load_spec
from pipeline.robots.spec import RobotSpec
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.safety import assess_execution


def blocking_box(spec: RobotSpec) -> Box:
    """The planning tests' 6 cm cube beside the midpoint of start and goal flange positions."""
    mid = 0.5 * (
        forward_kinematics(spec, PAPER_START_RAD)[:3, 3]
        + forward_kinematics(spec, PAPER_GOAL_RAD)[:3, 3]
    )
    c = mid + np.array([-0.08, 0.0, 0.0])
    return Box("blocker", (float(c[0]), float(c[1]), float(c[2])), (0.03,) * 3)


def floor_s(spec: RobotSpec, q: np.ndarray, padding_m: float) -> float:
    """Wall time [s] of mj_kinematics + mj_collision over every row (model prebuilt)."""
    checker = CollisionChecker(spec, padding_m=padding_m)
    model, data = checker.model, checker.data
    kin, col = mujoco.mj_kinematics, mujoco.mj_collision
    t0 = time.perf_counter()
    for row in q:
        data.qpos[:] = row
        kin(model, data)
        col(model, data)
    return time.perf_counter() - t0


def measure(*, samples: int = 3000, repeats: int = 5) -> dict[str, Any]:
    """Best-of-``repeats`` cost [us per sample] of the floor and of assess_execution."""
    spec = load_spec("ur5")
    reference = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=3.0)
    q = reference.sample_many(np.arange(samples) * 1e-3)[0]
    stamp_ns = np.arange(samples, dtype=np.int64) * 1_000_000
    cases = {"no_obstacle": (), "blocking_box": (blocking_box(spec),)}
    best = {"floor": float("inf"), **{k: float("inf") for k in cases}}
    summaries = {}
    for _ in range(repeats):
        best["floor"] = min(best["floor"], floor_s(spec, q, 0.05))
        for key, obstacles in cases.items():
            t0 = time.perf_counter()
            result = assess_execution(spec, q=q, stamp_ns=stamp_ns, obstacles=obstacles)
            best[key] = min(best[key], time.perf_counter() - t0)
            summaries[key] = result.summary()
    return {
        "robot": "ur5",
        "samples": samples,
        "padding_m": 0.05,
        "floor_us_per_sample": round(best["floor"] / samples * 1e6, 2),
        "assess_execution": {
            key: {
                "us_per_sample": round(best[key] / samples * 1e6, 2),
                "ratio_to_floor": round(best[key] / best["floor"], 2),
                "summary": summaries[key],
            }
            for key in cases
        },
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--samples", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    out = measure(samples=args.samples, repeats=args.repeats)
    sys.stdout.write(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
