"""Identification speed: a 60 s, 1 kHz excitation bag (6 joints) -> MODEL.yaml, and the design.

Prints one JSON object. Records a 60 s excitation (6 periods of a 0.1 Hz, 5-harmonic
Fourier series, not optimized) on the realistic plant (the ``paper-realistic``
scenario's drawn links, friction, damping and noise for seed 0) outside the clock, then
times ``pipeline identify fit``'s work (read, filter, regressor, WLS, physical
projection, write) at the default 5 Hz cutoff and unfiltered (cutoff 0, every sample).
Target: <= 10 s each. ``--design``: also time the excitation design (``--evaluations``, 6000 by
default, about 25 s for the UR5 on a quiet machine; target <= 60 s; ``--budget-s`` is
its wall-clock safety cap).

Usage: python benches/identify.py [--design] [--evaluations 6000] [--budget-s 600]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.control import make_controller  # noqa: E402
from pipeline.identify.defaults import DEFAULT_BUDGET_S, DEFAULT_EVALUATIONS  # noqa: E402
from pipeline.identify.excitation import design_excitation, scenario_plant  # noqa: E402
from pipeline.identify.fourier import FourierReference  # noqa: E402
from pipeline.identify.stage import fit_command  # noqa: E402
from pipeline.log.bag import write_episode_bag  # noqa: E402
from pipeline.params import load_params  # noqa: E402
from pipeline.robots.loaders import load_spec  # noqa: E402
from pipeline.sim.runner import run_episode  # noqa: E402
from pipeline.trajectory import TrajectorySamples  # noqa: E402

MID_POSTURE = np.array([0.0, -1.2, 1.2, -1.0, 0.5, 0.0])


def record_bag(path: Path) -> float:
    params = load_params(REPO / "params.yaml")
    scenario = params.scenarios["paper-realistic"]
    spec = load_spec(scenario.robot)
    plant_spec, plant, _ = scenario_plant(spec, scenario, seed=0)
    free = np.random.default_rng(1).normal(scale=0.06, size=48)
    ref = FourierReference.from_free(
        MID_POSTURE, free, harmonics=5, base_frequency_hz=0.1, periods=6
    )
    result = run_episode(
        spec,
        reference=ref,
        controller=make_controller("ctc", spec),
        plant=plant,
        plant_spec=plant_spec,
        seed=0,
        hold_s=0.0,
        preroll_s=0.0,
        position_noise_std_rad=scenario.plant.position_noise_std_rad,
        velocity_noise_std_rad_s=scenario.plant.velocity_noise_std_rad_s,
    )
    t = np.arange(0.0, ref.duration_s, 0.05)
    write_episode_bag(
        path,
        spec=spec,
        result=result,
        planned=TrajectorySamples(t, *ref.sample_many(t)),
        metadata={
            "episode": "bench", "scenario": "paper-realistic", "controller": "ctc",
            "robot": "ur5", "seed": "0", "settings": "{}",
        },
    )  # fmt: skip
    return float(result.stamp_ns[-1] * 1e-9)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--design", action="store_true")
    ap.add_argument("--evaluations", type=int, default=DEFAULT_EVALUATIONS)
    ap.add_argument("--budget-s", type=float, default=DEFAULT_BUDGET_S)
    args = ap.parse_args()
    out: dict[str, object] = {"machine": platform.machine(), "python": platform.python_version()}
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "excitation"
        out["bag_duration_s"] = record_bag(bag)
        out["bag_bytes"] = sum(p.stat().st_size for p in bag.iterdir())
        for label, cutoff in (("fit_5hz", 5.0), ("fit_unfiltered", 0.0)):
            t0 = time.perf_counter()
            s = fit_command([bag], out=Path(tmp) / f"{label}.yaml", cutoff_hz=cutoff)
            out[f"{label}_wall_s"] = time.perf_counter() - t0
            out[f"{label}_equations"] = s["equations"]
            out[f"{label}_condition_number"] = s["condition_number"]
        out["fit_target_s"] = 10.0
    if args.design:
        spec = load_spec("ur5")
        t0 = time.perf_counter()
        d = design_excitation(
            spec, q0=MID_POSTURE, variant=0, evaluations=args.evaluations, budget_s=args.budget_s
        )
        out["design_wall_s"] = time.perf_counter() - t0
        out["design_evaluations"] = d.evaluations
        out["design_condition_number_scaled"] = d.condition_number_scaled
        out["design_condition_number"] = d.condition_number
        out["design_target_s"] = 60.0
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
