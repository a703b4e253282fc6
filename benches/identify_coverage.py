"""Do identification's standard errors hold? Coverage on drawn plants with known truth.

For each seed 0..N-1: the ``paper-realistic`` scenario's plant for that seed (drawn
links and armature, MuJoCo frictionloss and damping, sensor noise), a short fixed
excitation (one period of a 0.1 Hz, 5-harmonic Fourier series, 10 s, seeded
coefficients, CTC on the CAD model), written as our recording, read back, and fitted
as ``pipeline identify fit`` does (5 Hz zero-phase filter, decimation, WLS; filtered
Coulomb columns, held torque aligned, rows near a stuck joint left out). The truth
of the base parameters is the plant's standard parameters (its drawn inertials and
armature, Coulomb = frictionloss, viscous = damping, offset 0) through the fit's own
base projection. Coverage: the share of the base-parameter estimates within +-2
standard errors of the truth, per standard error (textbook iid, Newey-West HAC, block
bootstrap). Target: >= 90 % (95 % expected of a Gaussian).

Prints one JSON object.

Usage: python benches/identify_coverage.py [--plants 20] [--periods 1]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.control import make_controller  # noqa: E402
from pipeline.identify.excitation import scenario_plant  # noqa: E402
from pipeline.identify.fit import identify  # noqa: E402
from pipeline.identify.fourier import FourierReference  # noqa: E402
from pipeline.identify.regressor import standard_parameters  # noqa: E402
from pipeline.identify.samples import joint_samples  # noqa: E402
from pipeline.log.bag import write_episode_bag  # noqa: E402
from pipeline.log.reader import read_recording  # noqa: E402
from pipeline.params import load_params  # noqa: E402
from pipeline.robots.loaders import load_spec  # noqa: E402
from pipeline.sim.runner import run_episode  # noqa: E402
from pipeline.trajectory import TrajectorySamples  # noqa: E402

MID_POSTURE = np.array([0.0, -1.2, 1.2, -1.0, 0.5, 0.0])
TARGET = 0.90


def one_plant(
    seed: int,
    *,
    periods: int,
    tmp: Path,
    cutoff_hz: float = 5.0,
    transition_speed_rad_s: float = 0.0,
) -> dict[str, object]:
    params = load_params(REPO / "params.yaml")
    scenario = params.scenarios["paper-realistic"]
    spec = load_spec(scenario.robot)
    plant_spec, plant, settings = scenario_plant(spec, scenario, seed=seed)
    free = np.random.default_rng(1000 + seed).normal(scale=0.06, size=48)
    ref = FourierReference.from_free(
        MID_POSTURE, free, harmonics=5, base_frequency_hz=0.1, periods=periods
    )
    result = run_episode(
        spec, reference=ref, controller=make_controller("ctc", spec), plant=plant,
        plant_spec=plant_spec, seed=seed, hold_s=0.0, preroll_s=0.0,
        position_noise_std_rad=scenario.plant.position_noise_std_rad,
        velocity_noise_std_rad_s=scenario.plant.velocity_noise_std_rad_s,
    )  # fmt: skip
    path = tmp / f"plant{seed}"
    t = np.arange(0.0, ref.duration_s, 0.05)
    write_episode_bag(
        path, spec=spec, result=result, planned=TrajectorySamples(t, *ref.sample_many(t)),
        metadata={
            "episode": path.name, "scenario": "paper-realistic", "controller": "ctc",
            "robot": "ur5", "seed": str(seed), "settings": "{}",
        },
    )  # fmt: skip
    samples = joint_samples(read_recording(path), spec, cutoff_hz=cutoff_hz)
    fit = identify(spec, [samples], transition_speed_rad_s=transition_speed_rad_s)
    theta_true = standard_parameters(
        plant_spec,
        coulomb_nm=np.array(settings["frictionloss"]),
        viscous_nm_s_rad=np.array(settings["damping"]),
    )
    err = np.abs(fit.beta_wls - fit.base.of(theta_true))
    out: dict[str, object] = {"seed": seed, "parameters": int(err.size), "lags": fit.hac_lags}
    for label, se in (
        ("iid", fit.std_error_iid),
        ("hac", fit.std_error),
        ("bootstrap", fit.std_error_bootstrap),
    ):
        assert se is not None
        out[f"within_{label}"] = int(np.sum(err <= 2 * se))
    out["median_hac_over_iid"] = float(np.median(fit.std_error / fit.std_error_iid))  # type: ignore[operator]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--plants", type=int, default=20)
    ap.add_argument("--periods", type=int, default=1)
    ap.add_argument("--cutoff-hz", type=float, default=5.0)
    ap.add_argument("--transition-speed", type=float, default=0.0)
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.plants):
            rows.append(
                one_plant(
                    seed,
                    periods=args.periods,
                    tmp=Path(tmp),
                    cutoff_hz=args.cutoff_hz,
                    transition_speed_rad_s=args.transition_speed,
                )
            )
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    total = sum(int(r["parameters"]) for r in rows)  # type: ignore[call-overload]
    out: dict[str, object] = {
        "machine": platform.machine(),
        "python": platform.python_version(),
        "load_average_1min": os.getloadavg()[0],
        "plants": args.plants,
        "excitation_s": 10.0 * args.periods,
        "cutoff_hz": args.cutoff_hz,
        "transition_speed_rad_s": args.transition_speed,
        "estimates": total,
    }
    for label in ("iid", "hac", "bootstrap"):
        within = sum(int(r[f"within_{label}"]) for r in rows)  # type: ignore[call-overload]
        out[f"coverage_{label}"] = within / total
        per_plant = [int(r[f"within_{label}"]) / int(r["parameters"]) for r in rows]  # type: ignore[call-overload]
        out[f"coverage_{label}_worst_plant"] = min(per_plant)
    out["median_lags"] = float(np.median([int(r["lags"]) for r in rows]))  # type: ignore[call-overload]
    out["target"] = TARGET
    out["met"] = bool(out["coverage_hac"] >= TARGET)  # type: ignore[operator]
    out["wall_s"] = time.perf_counter() - t0
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
