"""Benchmark: post-hoc execution safety (``assess_execution``) per trajectory sample.

A 3000-sample UR5 trajectory (the paper's motion as a 3 s minimum-jerk
profile at 1 kHz) is assessed whole (checker build included) with no
obstacle, and with the planning tests' blocking box on the straight path
(which the arm then crosses, so the exact robot–box distances run on many
rows). Peer: a bare loop of ``mj_kinematics`` + ``mj_collision`` on the same
model, the least any per-sample MuJoCo check can cost. Best of ``repeats``.

Also the record stage's setting, ``skip_within_m = SKIP_WITHIN_M`` (rows provably
within 0.5 mm of a checked one are skipped), on the same rows and on an episode-like
run (the start held 2 s before the motion and the goal 1 s after it).

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
from pipeline.sim.safety import SKIP_WITHIN_M, assess_execution


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
    box = (blocking_box(spec),)
    # the record stage's setting: rows provably within SKIP_WITHIN_M of a checked one are
    # skipped; "episode" holds the start for 2 s and the goal for 1 s around the motion
    # (pre-roll and hold, as an episode does): samples + 3000 rows
    held = np.concatenate([np.repeat(q[:1], 2000, axis=0), q, np.repeat(q[-1:], 1000, axis=0)])
    cases: dict[str, tuple[Any, tuple[Box, ...], float]] = {
        "no_obstacle": (q, (), 0.0),
        "blocking_box": (q, box, 0.0),
        "no_obstacle_skip_0.5mm": (q, (), SKIP_WITHIN_M),
        "blocking_box_skip_0.5mm": (q, box, SKIP_WITHIN_M),
        "episode_like_no_obstacle_skip_0.5mm": (held, (), SKIP_WITHIN_M),
    }
    best = {"floor": float("inf"), **{k: float("inf") for k in cases}}
    summaries = {}
    checked = {}
    for _ in range(repeats):
        best["floor"] = min(best["floor"], floor_s(spec, q, 0.05))
        for key, (rows, obstacles, skip) in cases.items():
            t0 = time.perf_counter()
            stamps = np.arange(len(rows), dtype=np.int64) * 1_000_000
            result = assess_execution(
                spec, q=rows, stamp_ns=stamps, obstacles=obstacles, skip_within_m=skip
            )
            best[key] = min(best[key], time.perf_counter() - t0)
            summaries[key] = result.summary()
            checked[key] = result.samples_checked
    return {
        "robot": "ur5",
        "samples": samples,
        "padding_m": 0.05,
        "floor_us_per_sample": round(best["floor"] / samples * 1e6, 2),
        "assess_execution": {
            key: {
                "rows": len(cases[key][0]),
                "us_per_sample": round(best[key] / len(cases[key][0]) * 1e6, 2),
                "ratio_to_floor": round(
                    best[key] / len(cases[key][0]) / (best["floor"] / samples), 2
                ),
                "samples_checked": checked[key],
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
