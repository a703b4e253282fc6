"""Benchmark: the episode loop's cost per control step against the physics floor.

The floor is a bare loop of one Pinocchio RNEA call plus the control period's
``mj_step`` calls per control step on the same plant, the least any Python loop
running a model-based controller can cost. Every ``run_episode`` call is timed whole
(model build, reference sampling, noise, result assembly included) and divided by its
control steps. The defaults are the recorded experiment's (RK4, 0.5 ms, 2 physics steps
per 1 kHz control step). Best of ``repeats`` runs, interleaved, so other load on the
machine hits both.

Run: ``python benches/sim_loop.py [--robot ur5] [--seconds 10] [--repeats 3]
[--physics-dt-s 0.0005] [--period 2]``; prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pinocchio as pin

from pipeline.control import make_controller
from pipeline.model.mjcf import build_mujoco_model
from pipeline.robots import load_spec
from pipeline.robots.spec import RobotSpec
from pipeline.robots.urdf import build_pinocchio_model
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode

sys.path.insert(0, str(Path(__file__).resolve().parent))
from floor import floor_summary, measure_floor, per_step_ratio, uptime


def physics_floor_s(
    spec: RobotSpec, *, steps: int, physics_dt_s: float = 0.001, control_period_steps: int = 1
) -> float:
    """Wall time [s] of ``steps`` x (pin.rnea + ``control_period_steps`` x mj_step) on the
    nominal plant, at rest start.

    The RNEA torque (gravity + Coriolis) is applied, so the arm stays up and no contact
    is ever computed: the same contact-free physics an episode runs. (Leaving ctrl at
    zero lets the arm fall onto the floor, and contact handling inflates the floor.)
    """
    model = build_mujoco_model(spec, timestep_s=physics_dt_s)
    data = mujoco.MjData(model)
    pmodel = build_pinocchio_model(spec)
    pdata = pmodel.createData()
    zeros = np.zeros(spec.dof)
    step, rnea, nstep = mujoco.mj_step, pin.rnea, control_period_steps
    t0 = time.perf_counter()
    ctrl = data.ctrl
    for _ in range(steps):
        ctrl[:] = rnea(pmodel, pdata, data.qpos, data.qvel, zeros)
        step(model, data, nstep)
    return time.perf_counter() - t0


def measure(
    robot: str = "ur5",
    *,
    seconds: float = 10.0,
    repeats: int = 3,
    motion_s: float = 2.0,
    physics_dt_s: float = 0.0005,
    period: int = 2,
) -> dict[str, Any]:
    """Floor and per-controller episode cost [us per control step] (best of ``repeats``)."""
    spec = load_spec(robot)
    if spec.dof == len(PAPER_START_RAD):
        start, goal = PAPER_START_RAD, PAPER_GOAL_RAD
    else:  # another arm: its first named state (an SRDF's ready pose) or mid-range, 0.3 rad on
        mid = 0.5 * (spec.lower + spec.upper)
        start = np.array(spec.named_states[0][1]) if spec.named_states else mid
        goal = np.clip(start + 0.3, spec.lower, spec.upper)
    reference = QuinticReference.between(start, goal, duration_s=motion_s)
    hold_s = seconds - motion_s
    cases: dict[str, dict[str, Any]] = {
        "ctc": {"controller": "ctc"},
        "pid": {"controller": "pid"},
        "pd_gravity": {"controller": "pd_gravity"},
        "ctc_noisy": {"controller": "ctc", "noise": True},
        "ctc_period_5": {"controller": "ctc", "period": 5},
    }
    periods = sorted({case.get("period", period) for case in cases.values()})
    floors = dict.fromkeys(periods, float("inf"))
    best = {k: float("inf") for k in cases}
    physics_steps = round(seconds / physics_dt_s)
    for _ in range(repeats):
        for p, floor in floors.items():
            took = physics_floor_s(
                spec, steps=physics_steps // p, physics_dt_s=physics_dt_s, control_period_steps=p
            )
            floors[p] = min(floor, took)
        for key, case in cases.items():
            controller = make_controller(case["controller"], spec)
            noise = 1e-4 if case.get("noise") else 0.0
            t0 = time.perf_counter()
            result = run_episode(
                spec,
                reference=reference,
                controller=controller,
                seed=0,
                hold_s=hold_s,
                physics_dt_s=physics_dt_s,
                control_period_steps=case.get("period", period),
                position_noise_std_rad=noise,
                velocity_noise_std_rad_s=noise,
            )
            best[key] = min(best[key], time.perf_counter() - t0)
            if not result.ok:
                raise RuntimeError(f"{key}: {result.reason}")
    out: dict[str, Any] = {
        "robot": robot,
        "physics_steps": physics_steps,
        "physics_dt_s": physics_dt_s,
        "floor_us_per_control_step": {
            f"period_{p}": round(floors[p] / (physics_steps // p) * 1e6, 3) for p in periods
        },
        "episodes": {},
    }
    for key, case in cases.items():
        p = case.get("period", period)
        out["episodes"][key] = {
            "control_period_steps": p,
            "us_per_control_step": round(best[key] / (physics_steps // p) * 1e6, 3),
            "ratio_to_floor": round(best[key] / floors[p], 3),
        }
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--robot", default="ur5")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--physics-dt-s", type=float, default=0.0005)
    parser.add_argument("--period", type=int, default=2, help="physics steps per control step")
    args = parser.parse_args(argv)
    floor, before = measure_floor(), uptime()
    out = measure(
        args.robot,
        seconds=args.seconds,
        repeats=args.repeats,
        physics_dt_s=args.physics_dt_s,
        period=args.period,
    )
    floor = floor.merged(measure_floor())  # the converged floor (benches/floor.py), same run
    out["converged_floor"] = floor_summary(floor) | {"uptime": [before, uptime()]}
    for case in out["episodes"].values():
        case["x_converged_floor"] = per_step_ratio(floor, case["us_per_control_step"])
    sys.stdout.write(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
