"""The converged floor, stated once (issue 31 item 3): what every throughput bench divides by.

Per control step: the control period's physics steps of the default converged plant
(``sim`` in ``params.yaml``: RK4, 0.5 ms, two steps per 1 ms control period) on the
realistic scenario's plant *with its joint friction* (``paper-realistic`` drawn for seed
0: Coulomb friction, damping, drawn links; contacts off), plus one Pinocchio RNEA on the
nominal robot. Nothing else: no controller, no logging, no checks. A bench measures it
in its own run (:func:`measure_floor`, best of a few repeats, before and after its own
work under the same load) and prints :func:`floor_fields` beside each throughput figure:
the floor per control step and the figure as a multiple of it.

:func:`measure_floor_jobs` measures it with ``-j`` loops at once (one process each): the
peer of a ``-j 2`` figure, since two busy cores of a shared machine are not two quiet ones.

Usage as a script: ``python benches/floor.py`` prints both (one and two at once) as one
JSON object.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

FLOOR_SCENARIO = "paper-realistic"
FLOOR_SEED = 0
FLOOR_STEPS = 2000  # control steps per repeat (2 s of simulated time)


@dataclass(frozen=True)
class Floor:
    """The converged floor as measured: best and all repeats, per control step [us];
    wall and CPU (the CPU figure is the one that holds on a loaded machine)."""

    us_per_control_step: float
    repeats_us: tuple[float, ...]
    cpu_us_per_control_step: float
    what: str

    def seconds(self, control_steps: int, *, cores: int = 1) -> float:
        """The floor [s] of ``control_steps`` spread over ``cores`` busy cores."""
        return control_steps * self.us_per_control_step * 1e-6 / cores

    def merged(self, other: Floor) -> Floor:
        """The best of two measurements (e.g. before and after a bench's own work)."""
        runs = self.repeats_us + other.repeats_us
        cpu = min(self.cpu_us_per_control_step, other.cpu_us_per_control_step)
        return Floor(min(runs), runs, cpu, self.what)


def _floor_loop(scenario: str, seed: int, params_path: Path) -> Any:
    """A closure running ``steps`` control steps of the floor; returns its wall [s]."""
    import mujoco
    import numpy as np
    import pinocchio as pin

    from pipeline.experiment.assemble import draw_scenario_plant
    from pipeline.model.mjcf import build_mujoco_model
    from pipeline.params import load_params
    from pipeline.robots.loaders import load_spec
    from pipeline.robots.urdf import build_pinocchio_model

    params = load_params(params_path)
    sc = params.scenarios[scenario]
    sim = params.sim
    spec = load_spec(sc.robot)
    plant_spec, plant, _ = draw_scenario_plant(spec, sc, seed=seed)
    model = build_mujoco_model(
        plant_spec, timestep_s=sim.physics_dt_s, plant=plant, integrator=sim.integrator
    )
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    data = mujoco.MjData(model)
    data.qpos[:] = np.asarray(sc.start, dtype=float)
    pmodel = build_pinocchio_model(spec)
    pdata = pmodel.createData()
    zeros = np.zeros(spec.dof)
    step, rnea, nstep, ctrl = mujoco.mj_step, pin.rnea, sim.control_period_steps, data.ctrl
    what = (
        f"{nstep} x {sim.integrator} {1e3 * sim.physics_dt_s:g} ms mj_step on {scenario} "
        f"seed {seed}'s drawn plant (friction, damping; contacts off) + 1 RNEA (nominal "
        f"{sc.robot}) per control step"
    )

    def run(steps: int) -> tuple[float, float]:
        mujoco.mj_resetData(model, data)
        data.qpos[:] = np.asarray(sc.start, dtype=float)
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(steps):
            ctrl[:] = rnea(pmodel, pdata, data.qpos, data.qvel, zeros)
            step(model, data, nstep)
        return time.perf_counter() - t0, time.process_time() - c0

    return run, what


def measure_floor(
    *,
    repeats: int = 3,
    steps: int = FLOOR_STEPS,
    scenario: str = FLOOR_SCENARIO,
    seed: int = FLOOR_SEED,
    params_path: Path = REPO / "params.yaml",
) -> Floor:
    """The converged floor per control step, best of ``repeats`` runs of ``steps``."""
    run, what = _floor_loop(scenario, seed, params_path)
    run(50)  # warm caches
    timed = [run(steps) for _ in range(repeats)]
    runs = tuple(round(1e6 * wall / steps, 2) for wall, _ in timed)
    cpu = round(1e6 * min(c for _, c in timed) / steps, 2)
    return Floor(min(runs), runs, cpu, what)


def _floor_job(args: tuple[int, int, str, int, Path, Any, Any]) -> None:
    """One of :func:`measure_floor_jobs`' processes: build, wait for the others, measure."""
    index, steps, scenario, seed, params_path, barrier, results = args
    run, what = _floor_loop(scenario, seed, params_path)
    run(50)
    barrier.wait()
    results.put((index, what, [run(steps) for _ in range(3)]))


def measure_floor_jobs(
    jobs: int,
    *,
    steps: int = FLOOR_STEPS,
    scenario: str = FLOOR_SCENARIO,
    seed: int = FLOOR_SEED,
    params_path: Path = REPO / "params.yaml",
) -> Floor:
    """The floor with ``jobs`` floor loops running at once, one process each (started
    together after their setup): the floor per control step that ``-j jobs`` workers get
    from this machine, where two busy cores are not two quiet ones (shared caches, memory
    bandwidth, a host's other tenants). Per process the best of three runs; the figure is
    their mean (wall and CPU)."""
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    barrier, results = ctx.Barrier(jobs), ctx.Queue()
    procs = [
        ctx.Process(
            target=_floor_job, args=((i, steps, scenario, seed, params_path, barrier, results),)
        )
        for i in range(jobs)
    ]
    for proc in procs:
        proc.start()
    timed = [results.get(timeout=600) for _ in procs]
    for proc in procs:
        proc.join()
    walls = [1e6 * min(w for w, _ in runs) / steps for _, _, runs in timed]
    cpus = [1e6 * min(c for _, c in runs) / steps for _, _, runs in timed]
    return Floor(
        round(sum(walls) / jobs, 2),
        tuple(round(w, 2) for w in walls),
        round(sum(cpus) / jobs, 2),
        f"{jobs} processes at once, each: {timed[0][1]}",
    )


def floor_fields(
    floor: Floor,
    *,
    control_steps: int,
    wall_s: float,
    cpu_s: float | None = None,
    cores: int = 1,
    name: str = "",
) -> dict[str, Any]:
    """What a bench prints beside a throughput figure: the floor and the figure's ratio.

    ``wall_s`` is the figure (seconds for ``control_steps`` control steps on ``cores``
    busy cores); its floor is ``floor.seconds(control_steps, cores=cores)``. ``cpu_s``
    (the CPU seconds of the same work, all processes) is set against the CPU floor of
    all the steps on one core: on a loaded machine the CPU ratio is the one to read."""
    floor_s = floor.seconds(control_steps, cores=cores)
    prefix = f"{name}_" if name else ""
    out: dict[str, Any] = {
        f"{prefix}control_steps": control_steps,
        f"{prefix}floor_s": round(floor_s, 3),
        f"{prefix}x_floor": round(wall_s / floor_s, 2) if floor_s > 0 else None,
    }
    if cpu_s is not None:
        cpu_floor_s = control_steps * floor.cpu_us_per_control_step * 1e-6
        out[f"{prefix}cpu_floor_s"] = round(cpu_floor_s, 3)
        out[f"{prefix}cpu_x_floor"] = round(cpu_s / cpu_floor_s, 2) if cpu_floor_s else None
    return out


def steps_in_report(metrics_json: Path, *, control_dt_s: float = 0.001) -> tuple[int, int]:
    """(episodes, control steps simulated) of a report's ``metrics.json`` (its per-episode
    ``end_s``, pre-roll included): the steps a campaign's floor counts."""
    episodes = json.loads(metrics_json.read_text())["episodes"]
    steps = sum(round(e["end_s"] / control_dt_s) + 1 for e in episodes.values())
    return len(episodes), steps


def per_step_ratio(floor: Floor, us_per_control_step: float) -> float:
    """A per-control-step cost [us] as a multiple of the converged floor."""
    return round(us_per_control_step / floor.us_per_control_step, 2)


def floor_summary(floor: Floor) -> dict[str, Any]:
    """The floor itself, for a bench's JSON (once per run)."""
    return {
        "floor_us_per_control_step": floor.us_per_control_step,
        "floor_repeats_us": list(floor.repeats_us),
        "floor_cpu_us_per_control_step": floor.cpu_us_per_control_step,
        "floor": floor.what,
    }


def uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def main() -> None:
    floor = measure_floor(repeats=5)
    jobs = measure_floor_jobs(2)
    print(
        json.dumps(
            floor_summary(floor)
            | {f"jobs_2_{k}": v for k, v in floor_summary(jobs).items()}
            | {"uptime": uptime()},
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
