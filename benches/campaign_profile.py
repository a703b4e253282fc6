"""Where a campaign episode's wall time goes: record side and report side, against the floor.

Prints one JSON object. A realistic-plant campaign (``paper-realistic``: a drawn plant per
seed, friction, damping, sensor noise; ``--controllers`` x ``--seeds``) is recorded in
this process with one job, exactly as ``pipeline record --campaign`` runs it (``record()``,
planning included), while the pipeline's own functions are wrapped with timers. Each
timer keeps *exclusive* time (a wrapped call nested in another is charged to itself
only), so the stages add up to the run:

- ``plan``: ``plan_scenario`` (path + timing; once per distinct plan input, shared);
- ``plant build``: the plant draw (``draw_scenario_plant``) and ``build_mujoco_model``;
- ``controller``: the controller and its nominal model (``make_controller``, ``nominal_spec``);
- ``control loop``: ``_Loop.run`` (physics, controller, state copies, divergence check);
- ``episode setup``: the rest of ``run_episode`` (reference sampling, noise, result);
- ``contact check``: ``assess_execution``;
- ``settings``: ``episode_settings`` + ``bag_metadata`` (the bag's settings JSON);
- ``encode``: ``encode_episode`` (CDR of every topic, whole arrays);
- ``compress``: zstd (``ZstdCompressor.compress``);
- ``write``: MCAP framing (``write_mcap`` without zstd), the bag folder, fsync, rename;
- ``other``: what ``record()`` spends outside those (executor, outcomes, imports).

The report side runs ``run_report`` on the recordings with the same timers:
``read`` (``read_recording``: MCAP scan, decompress, CDR decode into frames), ``metrics``
(``_Measured.add``: protocol view, metrics, the kept error series) and ``report
outputs`` (tables, figures, .rrd, Markdown: partly fixed per report, so its per-episode
share shrinks with N).

The floor, measured in the same run: per control step of the episode, ``mj_step`` for
the control period's physics steps plus one Pinocchio RNEA, on the nominal plant with the
scenario's integrator and step (best of six, three before and three after the run). The
plant floor: the same loop on the first episode's drawn plant (Coulomb friction makes
MuJoCo's constraint solver run every step), the least the control loop itself can cost.

Usage: python benches/campaign_profile.py [--seeds 10] [--controllers pid,ctc] [--no-report]
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

RECORD_STAGES = (
    "plan",
    "plant build",
    "controller",
    "control loop",
    "episode setup",
    "contact check",
    "settings",
    "encode",
    "compress",
    "write",
    "other",
)
REPORT_STAGES = ("read", "metrics", "report outputs")


class Timers:
    """Exclusive wall time per stage: a nested timed call is charged to its own stage."""

    def __init__(self) -> None:
        self.total_s: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._stack: list[list[float]] = []  # [start, time of timed children]

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        frame = [time.perf_counter(), 0.0]
        self._stack.append(frame)
        try:
            yield
        finally:
            self._stack.pop()
            spent = time.perf_counter() - frame[0]
            self.total_s[name] += spent - frame[1]
            self.calls[name] += 1
            if self._stack:
                self._stack[-1][1] += spent

    def wrap(self, owner: Any, attr: str, name: str) -> None:
        """Replace ``owner.attr`` by a timed wrapper (for the rest of the process)."""
        fn = getattr(owner, attr)

        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Any:
            with self.stage(name):
                return fn(*args, **kwargs)

        setattr(owner, attr, timed)


class _TimedZstd:
    """``zstandard`` as ``pipeline.log.mcap`` uses it, its compressor timed."""

    def __init__(self, timers: Timers, module: Any) -> None:
        self._timers, self._module = timers, module

    def __getattr__(self, name: str) -> Any:
        return getattr(self._module, name)

    def ZstdCompressor(self, *args: Any, **kwargs: Any) -> Any:
        inner = self._module.ZstdCompressor(*args, **kwargs)
        timers = self._timers

        class Compressor:
            def compress(self, data: bytes) -> bytes:
                with timers.stage("compress"):
                    return inner.compress(data)  # type: ignore[no-any-return]

        return Compressor()


def instrument(timers: Timers) -> None:
    """Wrap the record and report stages' pieces (module attributes, looked up per call)."""
    import pipeline.control as control
    import pipeline.identify.model_file as model_file
    import pipeline.log.bag as bag
    import pipeline.log.mcap as mcap
    import pipeline.log.rosbag2 as rosbag2
    import pipeline.sim.runner as runner
    import pipeline.sim.safety as safety
    import pipeline.stages.episode as episode
    import pipeline.stages.plans as plans
    import pipeline.stages.report as report

    timers.wrap(plans, "plan_scenario", "plan")
    timers.wrap(episode, "draw_scenario_plant", "plant build")
    # the plant model: set on the compiled robot (pipeline.sim.plant), or compiled per draw
    for name in ("plant_model", "build_mujoco_model"):
        if hasattr(runner, name):
            timers.wrap(runner, name, "plant build")
    timers.wrap(control, "make_controller", "controller")
    timers.wrap(model_file, "nominal_spec", "controller")
    timers.wrap(runner._Loop, "run", "control loop")
    timers.wrap(runner, "run_episode", "episode setup")
    timers.wrap(safety, "assess_execution", "contact check")
    timers.wrap(episode, "episode_settings", "settings")
    timers.wrap(episode, "bag_metadata", "settings")
    timers.wrap(bag, "encode_episode", "encode")
    timers.wrap(bag, "write_mcap", "write")
    timers.wrap(rosbag2, "write_bag_dir", "write")
    mcap.zstandard = _TimedZstd(timers, mcap.zstandard)  # type: ignore[assignment]
    timers.wrap(report, "read_recording", "read")
    timers.wrap(report._Measured, "add", "metrics")


def physics_floor_s(
    episode: Any, steps: int, *, drawn: bool = False, euler_1ms: bool = False
) -> float:
    """Wall time [s] of ``steps`` control steps of bare physics: the control period's
    ``mj_step`` calls plus one RNEA, nominal plant, the scenario's integrator and step.

    ``drawn``: on the episode's own plant instead (drawn links, Coulomb friction,
    damping, payload: the constraint solver runs every step), the floor of that plant.
    ``euler_1ms``: the nominal plant on one Euler step of 1 ms per control step (the plant
    before issue 19, whose floor the issue's targets were set against)."""
    import mujoco
    import numpy as np
    import pinocchio as pin

    from pipeline.model.mjcf import build_mujoco_model
    from pipeline.model.urdf import build_pinocchio_model
    from pipeline.robots.loaders import load_spec
    from pipeline.stages.assemble import draw_scenario_plant
    from pipeline.stages.plans import obstacle_boxes

    spec = load_spec(episode.scenario.robot)
    sim = episode.sim
    if euler_1ms:
        sim = sim.model_copy(
            update={"physics_dt_s": 0.001, "control_period_steps": 1, "integrator": "Euler"}
        )
    if drawn:
        plant_spec, plant, _ = draw_scenario_plant(spec, episode.scenario, seed=episode.seed)
        model = build_mujoco_model(
            plant_spec, timestep_s=sim.physics_dt_s, plant=plant,
            obstacles=obstacle_boxes(episode.scenario), integrator=sim.integrator,
        )  # fmt: skip
    else:
        model = build_mujoco_model(spec, timestep_s=sim.physics_dt_s, integrator=sim.integrator)
    data = mujoco.MjData(model)
    pmodel = build_pinocchio_model(spec)
    pdata = pmodel.createData()
    zeros = np.zeros(spec.dof)
    step, rnea, nstep, ctrl = mujoco.mj_step, pin.rnea, sim.control_period_steps, data.ctrl
    t0 = time.perf_counter()
    for _ in range(steps):
        ctrl[:] = rnea(pmodel, pdata, data.qpos, data.qvel, zeros)
        step(model, data, nstep)
    return time.perf_counter() - t0


def episode_wall_s(episode: Any, plan: Any) -> tuple[float, int]:
    """Wall time [s] of one whole episode with its bag (``run_one``, as ``pipeline record``
    runs it), and its control steps: the peer of :func:`physics_floor_s`.

    Raises:
        RuntimeError: the episode did not end ok.
    """
    from pipeline.stages.episode import run_one

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        outcome = run_one(episode, plan, out_dir=Path(tmp), force=False, commit="")
        wall_s = time.perf_counter() - t0
    if outcome.status != "ok":
        raise RuntimeError(f"{episode.name}: {outcome.status}: {outcome.reason}")
    control_dt_s = episode.sim.physics_dt_s * episode.sim.control_period_steps
    return wall_s, round(outcome.duration_s / control_dt_s) + 1


def _params(folder: Path, *, seeds: int, controllers: list[str]) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["campaigns"] = {
        "profile": {"scenario": "paper-realistic", "controllers": controllers, "seeds": seeds}
    }
    path = folder / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _table(
    timers: Timers, stages: tuple[str, ...], episodes: int, floor_s: float
) -> dict[str, Any]:
    total = sum(timers.total_s[s] for s in stages)
    return {
        s: {
            "ms_per_episode": round(1e3 * timers.total_s[s] / episodes, 2),
            "share": round(timers.total_s[s] / total, 3) if total else 0.0,
            "x_floor": round(timers.total_s[s] / episodes / floor_s, 2),
        }
        for s in stages
    } | {
        "total": {
            "ms_per_episode": round(1e3 * total / episodes, 2),
            "x_floor": round(total / episodes / floor_s, 2),
        }
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--controllers", default="pid,ctc")
    ap.add_argument("--no-report", action="store_true")
    args = ap.parse_args()
    from pipeline.params import load_params
    from pipeline.stages.campaign_run import completion_marker, plan_run
    from pipeline.stages.record import record
    from pipeline.stages.report import run_report

    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True).stdout.strip()  # fmt: skip
    timers = Timers()
    instrument(timers)
    controllers = args.controllers.split(",")
    result: dict[str, Any] = {
        "commit": commit,
        "uptime_before": uptime,
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
    }
    with tempfile.TemporaryDirectory() as tmp:
        params = load_params(_params(Path(tmp), seeds=args.seeds, controllers=controllers))
        run = plan_run(params, "profile", out=Path(tmp) / "rec")
        episodes = len(run.pending)
        # the floor before and after the run (best of both): other load moves it
        floors = [physics_floor_s(run.pending[0], 4011) for _ in range(3)]
        t0 = time.perf_counter()
        done = completion_marker(run, lambda *a: None)
        outcomes = record(
            params, run.pending, out_dir=run.out_dir, force=True, commit=run.commit, on_event=done
        )
        record_s = time.perf_counter() - t0
        bad = [o for o in outcomes if o.status != "ok"]
        if bad:
            raise SystemExit(f"{bad[0].name}: {bad[0].status}: {bad[0].reason}")
        timed = sum(timers.total_s[s] for s in RECORD_STAGES)
        timers.total_s["other"] = record_s - timed
        control_dt_s = run.pending[0].sim.physics_dt_s * run.pending[0].sim.control_period_steps
        steps = round(outcomes[0].duration_s / control_dt_s) + 1
        floors = [f * steps / 4011 for f in floors]
        floors += [physics_floor_s(run.pending[0], steps) for _ in range(3)]
        floor_s = min(floors)
        plant_floor_s = min(physics_floor_s(run.pending[0], steps, drawn=True) for _ in range(3))
        euler_s = min(physics_floor_s(run.pending[0], steps, euler_1ms=True) for _ in range(3))
        result |= {
            "episodes": episodes,
            "control_steps_per_episode": steps,
            "physics_steps_per_control_step": run.pending[0].sim.control_period_steps,
            "integrator": run.pending[0].sim.integrator,
            "floor_ms_per_episode": round(1e3 * floor_s, 2),
            "floor_us_per_control_step": round(1e6 * floor_s / steps, 2),
            "floor_spread_ms": [round(1e3 * f, 1) for f in floors],
            "plant_floor_ms_per_episode": round(1e3 * plant_floor_s, 2),
            "euler_1ms_floor_ms_per_episode": round(1e3 * euler_s, 2),
            "control_loop_x_plant_floor": round(
                timers.total_s["control loop"] / episodes / plant_floor_s, 2
            ),
            "record_s": round(record_s, 2),
            "record": _table(timers, RECORD_STAGES, episodes, floor_s),
            "bag_mb": round(
                sum(p.stat().st_size for p in run.out_dir.rglob("*.mcap")) / episodes / 1e6, 3
            ),
        }
        if not args.no_report:
            t0 = time.perf_counter()
            run_report(recordings_dir=run.out_dir, out_dir=Path(tmp) / "report")
            report_s = time.perf_counter() - t0
            timers.total_s["report outputs"] = report_s - sum(
                timers.total_s[s] for s in REPORT_STAGES[:2]
            )
            result["report_s"] = round(report_s, 2)
            result["report"] = _table(timers, REPORT_STAGES, episodes, floor_s)
        end_to_end = record_s + result.get("report_s", 0.0)
        result["end_to_end_ms_per_episode"] = round(1e3 * end_to_end / episodes, 1)
        result["end_to_end_x_floor"] = round(end_to_end / episodes / floor_s, 2)
    result["uptime_after"] = subprocess.run(
        ["uptime"], capture_output=True, text=True
    ).stdout.strip()
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
