"""Plant convergence: how much each reported metric moves when the physics step halves.

The default experiment (``params.yaml``'s hand-listed episodes: the ``paper`` scenario
under pid and ctc, plus ``paper-realistic`` seed 0 under the same controllers) is
recorded at the control period of ``params.yaml`` with 1, 2, 4, ... physics substeps
per control period (the controller keeps its rate, zero-order hold), and the report's
metrics are computed from each bag exactly as ``pipeline report`` does. For each
halving, the largest relative change of every metric over episodes and joints is
printed, with where it happened. A change is relative to the finer step's value, or to
the metric's noise floor (``FLOORS``) when the value is below it (a perfect-model CTC's
error at the target is ~1e-13 rad: its relative change is rounding, not physics).

Run: ``python benches/convergence.py [--substeps 1 2 4 8] [--params params.yaml]``;
prints one JSON object (also the cost: physics steps and simulated seconds per wall
second, per setting). ``tests/sim/test_convergence.py`` asserts the default setting's
halving stays within ``TOLERANCE``.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import polars as pl

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.analysis.catalog import BY_NAME, FINAL_DRIFT_REL, METRIC_COLUMNS  # noqa: E402
from pipeline.analysis.episodes import episode_table, limits_table  # noqa: E402
from pipeline.analysis.metrics import joint_metrics  # noqa: E402
from pipeline.analysis.protocol import protocol_view  # noqa: E402
from pipeline.analysis.verdict import ENCODER_RESOLUTION_RAD  # noqa: E402
from pipeline.log.reader import read_recording  # noqa: E402
from pipeline.params import Episode, Params, load_params  # noqa: E402
from pipeline.stages.episode import run_one  # noqa: E402
from pipeline.stages.plans import plan_scenario  # noqa: E402

TOLERANCE = 0.05
"""Largest relative change of any reported metric per halving of the physics step."""

REALISTIC = "paper-realistic"
FLOORS = {"rad": ENCODER_RESOLUTION_RAD, "rad/s": 1e-2, "s": 2e-3, "N m": 1e-3, "1": 1e-3}
"""Per unit, the size below which a metric's change is measured absolutely: in rad the
20-bit encoder's step (6.0e-6 rad), the smallest difference the report resolves (its
verdicts call a smaller one *equivalent*; 1e-6 rad until the per-row draws were aligned
to the motion, when a hunting pid's final drift of 2.6e-6 rad moved by 1.6e-7 rad, 6 %
of itself), 1e-2 rad/s about 1 % of a moving
joint's peak speed, 2 ms two control periods (a settling time is a sample index), 1e-3
of a fraction one sample in a thousand. The time of the peak velocity is compared only
for joints whose peak velocity is above its floor (a joint that does not move peaks
anywhere). A change of ``final_drift`` is relative to at least ``FINAL_DRIFT_REL`` x the
error at the target, the threshold the "not settled" flag compares the drift with."""


def default_experiment(params: Params) -> tuple[Episode, ...]:
    """The hand-listed episodes, plus ``paper-realistic`` seed 0 under their controllers."""
    episodes = list(params.episodes)
    if REALISTIC in params.scenarios:
        for e in params.episodes:
            episodes.append(
                dataclasses.replace(
                    e,
                    name=f"{REALISTIC}.{e.controller_name}.s0",
                    scenario_name=REALISTIC,
                    scenario=params.scenarios[REALISTIC],
                    seed=0,
                )
            )
    return tuple(episodes)


def metrics_at(
    params: Params, episodes: Sequence[Episode], *, physics_dt_s: float, substeps: int
) -> tuple[pl.DataFrame, dict[str, Any]]:
    """Record ``episodes`` at this physics step and substeps: their metrics, and the cost
    and the plant as each bag's settings record it (``plants``: episode -> integrator,
    physics_dt_s, control_period_s, friction_model)."""
    sim = params.sim.model_copy(
        update={"physics_dt_s": physics_dt_s, "control_period_steps": substeps}
    )
    plans = {e.scenario_name: plan_scenario(e.scenario_name, e.scenario, params.source)
             for e in episodes}  # fmt: skip
    frames = []
    plants: dict[str, dict[str, Any]] = {}
    wall_s = sim_s = 0.0
    bag_bytes = 0
    with tempfile.TemporaryDirectory() as tmp:
        for e in episodes:
            t0 = time.perf_counter()
            outcome = run_one(
                dataclasses.replace(e, sim=sim),
                plans[e.scenario_name],
                out_dir=Path(tmp),
                force=True,
                commit="",
            )
            wall_s += time.perf_counter() - t0
            if outcome.status != "ok":
                raise SystemExit(f"{e.name}: {outcome.status}: {outcome.reason}")
            sim_s += outcome.duration_s
            bag_bytes += sum(f.stat().st_size for f in (Path(tmp) / e.name).rglob("*"))
            view, _ = protocol_view(read_recording(Path(tmp) / e.name))
            rec = view.recording
            if view.settings is not None:
                p = view.settings.plant
                plants[e.name] = {
                    "integrator": p.integrator,
                    "physics_dt_s": p.physics_dt_s,
                    "control_period_s": p.control_period_s,
                    "friction_model": p.friction_model,
                    "control_rows": rec.controller_states.height // max(len(rec.joint_names), 1),
                }
            row = episode_table([rec], {rec.episode: view})
            frames.append(
                joint_metrics(rec.samples, rec.controller_states, row, limits_table([rec]))
            )
    steps = sim_s / physics_dt_s
    cost: dict[str, Any] = {
        "plants": plants,
        "wall_s": wall_s,
        "bag_bytes": bag_bytes,
        "physics_steps_per_s": steps / wall_s,
        "sim_s_per_wall_s": sim_s / wall_s,
    }
    return pl.concat(frames, how="vertical_relaxed"), cost


def changes(coarse: pl.DataFrame, fine: pl.DataFrame) -> dict[str, dict[str, Any]]:
    """Per metric, the largest |coarse - fine| / max(|fine|, floor) and where it is."""
    both = coarse.join(fine, on=["episode", "joint"], suffix="_fine")
    out: dict[str, dict[str, Any]] = {}
    for name in METRIC_COLUMNS:
        floor = FLOORS.get(BY_NAME[name].unit, 0.0)
        a, b = pl.col(name), pl.col(f"{name}_fine")
        scale = pl.max_horizontal(b.abs(), pl.lit(floor))
        if name == "final_drift":
            # a drift counts against the threshold the "not settled" flag compares it with
            scale = pl.max_horizontal(scale, pl.col("final_error_fine").abs() * FINAL_DRIFT_REL)
        rel = (a - b).abs() / scale
        if name == "peak_velocity_time":
            moving = pl.col("peak_velocity_fine").abs() >= FLOORS["rad/s"]
            both_here = both.filter(moving)
        else:
            both_here = both
        table = both_here.select(
            "episode", "joint", a.alias("coarse"), b.alias("fine"), rel.alias("rel")
        ).drop_nulls("rel")
        if table.height == 0:
            continue
        worst = table.sort("rel", descending=True).row(0, named=True)
        out[name] = worst
    return out


def convergence(
    params: Params, *, substeps: Sequence[int], control_period_s: float | None = None
) -> dict[str, Any]:
    """Metrics' changes per halving of the physics step at a fixed control period."""
    period_s = control_period_s or params.sim.physics_dt_s * params.sim.control_period_steps
    episodes = default_experiment(params)
    results = {
        n: metrics_at(params, episodes, physics_dt_s=period_s / n, substeps=n) for n in substeps
    }
    halvings: list[dict[str, Any]] = []
    for coarse, fine in itertools.pairwise(substeps):
        if fine != 2 * coarse:
            continue
        per_metric = changes(results[coarse][0], results[fine][0])
        worst = max(per_metric.values(), key=lambda w: w["rel"])
        halvings.append(
            {
                "substeps": [coarse, fine],
                "physics_dt_s": [period_s / coarse, period_s / fine],
                "max_rel_change": worst["rel"],
                "within_tolerance": worst["rel"] <= TOLERANCE,
                "per_metric": per_metric,
            }
        )
    return {
        "control_period_s": period_s,
        "episodes": [e.name for e in episodes],
        "tolerance": TOLERANCE,
        "floors": FLOORS,
        "cost": {
            str(n): {k: v for k, v in results[n][1].items() if k != "plants"} for n in substeps
        },
        "plants": {str(n): results[n][1]["plants"] for n in substeps},
        "halvings": halvings,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--params", default=str(REPO / "params.yaml"))
    ap.add_argument("--substeps", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--control-period-s", type=float, default=None)
    args = ap.parse_args()
    params = load_params(args.params)
    result = convergence(params, substeps=args.substeps, control_period_s=args.control_period_s)
    print(json.dumps(result, indent=2, default=str))


if __name__ == "__main__":
    main()
