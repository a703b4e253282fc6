"""Record-stage speed: the control loop and the whole episode per control step vs the physics floor.

Prints one JSON object. The floor, measured in the same run (``campaign_profile.
physics_floor_s``): per control step of the episode, the control period's ``mj_step``
calls with the scenario's integrator and step (two RK4 steps of 0.5 ms since issue 19)
plus one Pinocchio RNEA, on the nominal UR5 plant; the plant floor is the same loop on
the realistic episode's drawn plant (Coulomb friction: MuJoCo's constraint solver runs
every step). Until this round the floor here was one 1 ms step per control step, half
the physics the episode runs.

Episodes (planning and time-parameterization excluded: once per scenario, shared):
the paper's CTC episode (ideal plant) and the ``paper-realistic`` pid, ctc and ctc_pid
episodes (seed 1: a drawn plant, friction, damping, sensor noise), all with full
logging (their own control steps since issue 31's settled pre-roll and hold: every figure
per step divides by the episode's own; until this was fixed they all divided by the last
episode's). Per episode:

- ``loop``: ``sim.runner._Loop.run``, the hot loop (physics, the law, the logged state
  rows, sensor noise, the divergence check);
- ``physics``: the episode's own torques replayed on a copy of its plant from the same
  start (``mj_step`` alone along the same trajectory; checked to end in the same state):
  ``loop - physics`` is what the Python around the physics costs. The replay runs with
  the plant's contacts off, as the floor does (where the loop's contact gate ran them on,
  no contact was possible: the same states); ``benches/contact_gate.py`` compares the
  loop with and without the gate;
- ``motion_floor``: the replay plus one RNEA (nominal model) per control step at the
  episode's own states: the floor's work along this episode's motion instead of at rest;
  ``realistic_pid_ctc_*``: the realistic pid and ctc episodes together, per step of both
  (the campaign benches' laws);
- ``whole``: ``run_one`` (controller and plant setup, loop, contact check, bag write).

Each figure is the best of ``--repeat``, interleaved (the floors, then each episode), so
other load on the machine hits all of them; wall time and this thread's CPU time
(``time.thread_time``: less moved by other processes on a shared machine) are both given.
``--jobs`` scaling runs ``pipeline record`` on four episodes with 1 and 2 processes.

Usage: python benches/record.py [--repeat 5] [--no-jobs] [--no-marginal]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benches"))

from campaign_profile import episode_wall_s, physics_floor_s  # noqa: E402
from floor import floor_summary, measure_floor, per_step_ratio  # noqa: E402

import pipeline.sim.runner as runner  # noqa: E402
from pipeline.params import Episode, load_params  # noqa: E402
from pipeline.stages.plans import ScenarioPlan, plan_scenario  # noqa: E402

REALISTIC_SEED = 1
TARGET_RATIO = 2.0


class LoopProbe:
    """Wraps ``_Loop.run``: times it (wall and CPU) and replays its physics alone."""

    def __init__(self) -> None:
        self.wall_s = self.cpu_s = self.physics_wall_s = self.physics_cpu_s = 0.0
        self.rnea_wall_s = self.rnea_cpu_s = 0.0
        self._pin: dict[str, Any] = {}
        self._run = runner._Loop.run
        probe = self

        def run(loop: Any, *args: Any, **kwargs: Any) -> tuple[int, str]:
            return probe.timed(loop, *args, **kwargs)

        runner._Loop.run = run  # type: ignore[method-assign]

    def timed(
        self, loop: Any, *args: Any, first: int = 0, stop: int | None = None, final: bool = True
    ) -> tuple[int, str]:
        """One run of rows (an episode runs several since issue 31: the pre-roll's
        windows, the motion, the hold's); the figures add up over an episode."""
        import mujoco

        if first == 0:  # an episode's first run
            self.wall_s = self.cpu_s = self.physics_wall_s = self.physics_cpu_s = 0.0
            self.rnea_wall_s = self.rnea_cpu_s = 0.0
        # the whole state (the constraint solver's warm start too: with the realistic plant's
        # friction a replay from qpos and qvel alone leaves the trajectory)
        start = mujoco.MjData(loop.model)
        mujoco.mj_copyData(start, loop.model, loop.data)
        c0, w0 = time.thread_time(), time.perf_counter()
        rows, reason = self._run(loop, *args, first=first, stop=stop, final=final)
        self.wall_s += time.perf_counter() - w0
        self.cpu_s += time.thread_time() - c0
        if loop.actuator is None and not reason:
            steps = rows - first - (1 if final else 0)
            self._replay(loop, start, tau_cmd=args[9], first=first, steps=steps)
            self._rnea(loop, q=args[0], qd=args[1], first=first, steps=steps)
        return rows, reason

    def _rnea(self, loop: Any, *, q: Any, qd: Any, first: int, steps: int) -> None:
        """One RNEA (nominal model) per control step at the episode's own states: with
        the physics replay, the converged floor's work along this motion."""
        import numpy as np
        import pinocchio as pin

        from pipeline.robots.urdf import build_pinocchio_model

        name = loop.spec.name
        if name not in self._pin:
            pmodel = build_pinocchio_model(loop.spec)
            self._pin[name] = (pmodel, pmodel.createData())
        pmodel, pdata = self._pin[name]
        zeros, rnea = np.zeros(loop.spec.dof), pin.rnea
        c0, w0 = time.thread_time(), time.perf_counter()
        for k in range(first, first + steps):
            rnea(pmodel, pdata, q[k], qd[k], zeros)
        self.rnea_wall_s += time.perf_counter() - w0
        self.rnea_cpu_s += time.thread_time() - c0

    def _replay(self, loop: Any, data: Any, *, tau_cmd: Any, first: int, steps: int) -> None:
        """The same torques on the same plant from the same start: ``mj_step`` alone."""
        import mujoco

        model, step, ctrl, nstep = loop.model, mujoco.mj_step, data.ctrl, loop.nstep
        # contacts off, as the floor: where the loop ran them on (its contact gate), no
        # contact was possible, so the states are the same (checked below)
        flags = int(model.opt.disableflags)
        model.opt.disableflags = flags | int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        c0, w0 = time.thread_time(), time.perf_counter()
        for k in range(first, first + steps):
            ctrl[:] = tau_cmd[k]
            step(model, data, nstep)
        self.physics_wall_s += time.perf_counter() - w0
        self.physics_cpu_s += time.thread_time() - c0
        model.opt.disableflags = flags
        if not (data.qpos == loop.data.qpos).all():
            raise RuntimeError("the physics replay left the episode's trajectory")


def _episodes() -> list[tuple[str, Episode, ScenarioPlan]]:
    """(label, episode, plan): the paper's CTC episode, the realistic pid, ctc, ctc_pid."""
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["episodes"] = {"paper-ctc": {"scenario": "paper", "controller": "ctc", "seed": 0}} | {
        f"realistic-{c}": {"scenario": "paper-realistic", "controller": c, "seed": REALISTIC_SEED}
        for c in ("pid", "ctc", "ctc_pid")
    }
    data["campaigns"] = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "params.yaml"
        path.write_text(yaml.safe_dump(data))
        params = load_params(path)
    plans: dict[str, ScenarioPlan] = {}
    out = []
    for e in params.episodes:
        if e.scenario_name not in plans:
            plans[e.scenario_name] = plan_scenario(e.scenario_name, e.scenario, params.source)
        out.append((e.name, e, plans[e.scenario_name]))
    return out


def _floors(episode: Episode, steps: int) -> dict[str, float]:
    """Wall and CPU time of the nominal floor [s] for ``steps`` control steps."""
    c0 = time.thread_time()
    wall = physics_floor_s(episode, steps)
    return {"wall": wall, "cpu": time.thread_time() - c0}


def measure(repeat: int, *, marginal: bool) -> dict[str, Any]:
    """Best-of-``repeat`` figures per episode and the floors, interleaved."""
    probe = LoopProbe()
    cases = _episodes()
    realistic = next(e for name, e, _ in cases if name.startswith("realistic"))
    inf = float("inf")
    best: dict[str, dict[str, float]] = {}
    floor = {"wall": inf, "cpu": inf}
    plant_floor = inf
    steps = 0
    case_steps: dict[str, int] = {}  # each episode's own control steps (the settled
    # pre-roll and hold make them differ: a figure per step divides by its own)
    for _ in range(repeat):
        for name, episode, plan in cases:
            whole_s, case_steps[name] = episode_wall_s(episode, plan)
            got = {
                "whole": whole_s,
                "loop": probe.wall_s,
                "loop_cpu": probe.cpu_s,
                "physics": probe.physics_wall_s,
                "physics_cpu": probe.physics_cpu_s,
                "motion_floor": probe.physics_wall_s + probe.rnea_wall_s,
                "motion_floor_cpu": probe.physics_cpu_s + probe.rnea_cpu_s,
            }
            mine = best.setdefault(name, dict.fromkeys(got, inf))
            for key, value in got.items():
                mine[key] = min(mine[key], value)
        steps = case_steps[next(name for name, e, _ in cases if e is realistic)]
        for key, value in _floors(realistic, steps).items():
            floor[key] = min(floor[key], value)
        plant_floor = min(plant_floor, physics_floor_s(realistic, steps, drawn=True))
    per_step = 1e6 / steps  # the floors' steps (the first realistic episode's)
    out: dict[str, Any] = {
        "control_steps": steps,
        "physics_steps_per_control_step": realistic.sim.control_period_steps,
        "physics_dt_s": realistic.sim.physics_dt_s,
        "integrator": realistic.sim.integrator,
        "floor_us_per_control_step": round(floor["wall"] * per_step, 2),
        "floor_cpu_us_per_control_step": round(floor["cpu"] * per_step, 2),
        "plant_floor_us_per_control_step": round(plant_floor * per_step, 2),
        "plant_floor_x_floor": round(plant_floor / floor["wall"], 3),
        "target_ratio_to_floor": TARGET_RATIO,
    }
    floor_us = floor["wall"] * per_step
    floor_cpu_us = floor["cpu"] * per_step
    for name, b in best.items():
        own = 1e6 / case_steps[name]
        out[name] = {
            "control_steps": case_steps[name],
            "loop_us_per_step": round(b["loop"] * own, 2),
            "loop_x_floor": round(b["loop"] * own / floor_us, 3),
            "loop_cpu_x_floor_cpu": round(b["loop_cpu"] * own / floor_cpu_us, 3),
            "physics_us_per_step": round(b["physics"] * own, 2),
            "physics_x_floor": round(b["physics"] * own / floor_us, 3),
            "physics_cpu_x_floor_cpu": round(b["physics_cpu"] * own / floor_cpu_us, 3),
            "python_us_per_step": round((b["loop"] - b["physics"]) * own, 2),
            "python_cpu_us_per_step": round((b["loop_cpu"] - b["physics_cpu"]) * own, 2),
            "whole_us_per_step": round(b["whole"] * own, 2),
            "whole_x_floor": round(b["whole"] * own / floor_us, 3),
            # the floor's work (mj_step + 1 RNEA) along this episode's own motion
            "motion_floor_us_per_step": round(b["motion_floor"] * own, 2),
            "motion_floor_x_floor": round(b["motion_floor"] * own / floor_us, 3),
            "loop_x_motion_floor": round(b["loop"] / b["motion_floor"], 3),
            "whole_x_motion_floor": round(b["whole"] / b["motion_floor"], 3),
        }
    # the realistic pid + ctc pair (the campaign benches' laws), each weighted by its steps
    pair = [f"realistic-{c}" for c in ("pid", "ctc")]
    pair_steps = sum(case_steps[n] for n in pair)
    for key in ("motion_floor", "loop", "whole"):
        out[f"realistic_pid_ctc_{key}_us_per_step"] = round(
            1e6 * sum(best[n][key] for n in pair) / pair_steps, 2
        )
    out["realistic_pid_ctc_motion_floor_x_floor"] = round(
        out["realistic_pid_ctc_motion_floor_us_per_step"] / floor_us, 3
    )
    for key in ("loop_x_floor", "loop_cpu_x_floor_cpu"):  # the campaign profile's laws
        pair = [out[f"realistic-{c}"][key] for c in ("pid", "ctc")]
        out[f"realistic_pid_ctc_{key}"] = round(sum(pair) / 2, 3)
    if marginal:
        out["paper_ctc_marginal"] = _marginal(cases[0][1], repeat, floor["wall"] / steps)
    return out


def _marginal(episode: Episode, repeat: int, floor_s_per_step: float) -> dict[str, Any]:
    """Per extra control step of a 31 s hold over the paper's 1 s (no fixed setup)."""
    long = replace(episode, scenario=episode.scenario.model_copy(update={"hold_s": 31.0}))
    params = load_params(REPO / "params.yaml")
    plan = plan_scenario(episode.scenario_name, episode.scenario, params.source)
    short_s = long_s = float("inf")
    short_steps = long_steps = 0
    for _ in range(repeat):
        s, short_steps = episode_wall_s(episode, plan)
        x, long_steps = episode_wall_s(long, plan)
        short_s, long_s = min(short_s, s), min(long_s, x)
    marginal = (long_s - short_s) / (long_steps - short_steps)
    return {
        "note": "(31 s-hold episode - paper episode) / extra steps: excludes fixed setup",
        "us_per_step": round(marginal * 1e6, 2),
        "ratio_to_floor": round(marginal / floor_s_per_step, 3),
    }


def jobs_scaling(hold_s: float) -> dict[str, float]:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = hold_s
    for key, value in list(data["episodes"].items()):
        data["episodes"][f"{key}-b"] = {**value, "seed": value.get("seed", 0) + 1}
    out: dict[str, float] = {"episodes": float(len(data["episodes"])), "hold_s": hold_s}
    with tempfile.TemporaryDirectory() as tmp:
        params = Path(tmp) / "params.yaml"
        params.write_text(yaml.safe_dump(data))
        for jobs in (1, 2):
            cmd = [sys.executable, "-m", "pipeline", "record", "--params", str(params)]
            cmd += ["--out", f"{tmp}/rec{jobs}", "--jobs", str(jobs)]
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, cwd=REPO)
            out[f"jobs_{jobs}_wall_s"] = time.perf_counter() - t0
    out["speedup_2_jobs"] = out["jobs_1_wall_s"] / out["jobs_2_wall_s"]
    return out


def _shell(*cmd: str) -> str:
    return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO).stdout.strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-jobs", action="store_true", help="skip the --jobs scaling run")
    ap.add_argument("--no-marginal", action="store_true", help="skip the 31 s-hold episode")
    args = ap.parse_args()
    result: dict[str, Any] = {
        "commit": _shell("git", "rev-parse", "--short", "HEAD"),
        "uptime_before": _shell("uptime"),
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "machine": platform.machine(),
        },
    }
    converged = measure_floor()
    result |= measure(args.repeat, marginal=not args.no_marginal)
    converged = converged.merged(measure_floor())  # benches/floor.py, same run
    result["converged_floor"] = floor_summary(converged)
    for case in result.values():
        if isinstance(case, dict) and "whole_us_per_step" in case:
            case["loop_x_converged_floor"] = per_step_ratio(converged, case["loop_us_per_step"])
            case["whole_x_converged_floor"] = per_step_ratio(converged, case["whole_us_per_step"])
    if not args.no_jobs:
        result["jobs"] = jobs_scaling(hold_s=240.0)
    result["uptime_after"] = _shell("uptime")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
