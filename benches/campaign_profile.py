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
- ``encode``: ``encode_streams`` (CDR of every topic, whole arrays);
- ``compress``: zstd (``ZstdCompressor.compress``);
- ``write``: MCAP framing (``write_mcap`` without zstd), the bag folder, fsync, rename;
- ``recording in memory``: with ``--keep-every``, ``episode_recording`` (what the bag
  would read back as, made from the episode's arrays: a dropped episode writes no bag);
- ``partial``: with ``--keep-every``, ``keep_partial`` (the report's measuring of that
  recording, its ``metrics`` included, and the Arrow IPC partial written);
- ``sample selection``: with ``--keep-every``, choosing the median and worst episodes
  from the partials and planning their re-runs (``sample_without_bags``, ``plan_run``);
- ``other``: what ``record()`` spends outside those (executor, outcomes, imports).

The report side runs ``run_report`` on the recordings with the same timers:
``read`` (``read_recording``: MCAP scan, decompress, CDR decode into frames),
``metrics`` (``Measured.add``: protocol view, metrics, the kept error series),
``partial read`` (``read_partial``: a dropped episode's partial) and ``report outputs``
(tables, figures, .rrd, Markdown: partly fixed per report, so its per-episode share
shrinks with N).

The floor, measured in the same run: per control step of the episode, ``mj_step`` for
the control period's physics steps plus one Pinocchio RNEA, on the nominal plant with the
scenario's integrator and step (best of six, three before and three after the run). The
plant floor: the same loop on the first episode's drawn plant (Coulomb friction makes
MuJoCo's constraint solver run every step), the least the control loop itself can cost.

``--keep-every K`` profiles the sampled campaign (``keep_bags: {every: K}``) as
``pipeline record --campaign`` runs it: the campaign, then the re-runs by key of the
median and worst episodes whose bags were not kept (``sample re-runs``, inside the
record figures), then the report on the bags and partials. Per episode end to end
(record + write + the report's share), wall and CPU, against the floors.

Usage: python benches/campaign_profile.py [--seeds 10] [--controllers pid,ctc]
[--keep-every K] [--no-report]
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
sys.path.insert(0, str(REPO / "benches"))

from floor import floor_fields, floor_summary, measure_floor  # noqa: E402

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
    "recording in memory",
    "partial",
    "sample selection",
    "other",
)
REPORT_STAGES = ("read", "metrics", "partial read", "report outputs")
JOBS2_EFFICIENCY = 0.927  # `--jobs 2`, quiet machine (BENCHMARKS.md, Session 3, parallel)


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
    import pipeline.analysis.measure as measure
    import pipeline.control as control
    import pipeline.identify.model_file as model_file
    import pipeline.log.bag as bag
    import pipeline.log.mcap as mcap
    import pipeline.log.rosbag2 as rosbag2
    import pipeline.log.whole as whole
    import pipeline.sim.runner as runner
    import pipeline.sim.safety as safety
    import pipeline.stages.campaign_run as campaign_run
    import pipeline.stages.episode as episode
    import pipeline.stages.partials as partials
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
    timers.wrap(bag, "encode_streams", "encode")
    timers.wrap(bag, "write_mcap", "write")
    timers.wrap(rosbag2, "write_bag_dir", "write")
    timers.wrap(whole, "episode_recording", "recording in memory")
    timers.wrap(campaign_run, "keep_partial", "partial")
    mcap.zstandard = _TimedZstd(timers, mcap.zstandard)  # type: ignore[attr-defined,assignment]
    timers.wrap(report, "read_recording", "read")
    timers.wrap(measure, "read_recording", "read")
    timers.wrap(partials, "read_recording", "read")
    timers.wrap(measure.Measured, "add", "metrics")
    timers.wrap(report, "read_partial", "partial read")


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

    from pipeline.experiment.assemble import draw_scenario_plant
    from pipeline.model.mjcf import build_mujoco_model
    from pipeline.robots.loaders import load_spec
    from pipeline.robots.urdf import build_pinocchio_model
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


def _params(folder: Path, *, seeds: int, controllers: list[str], keep_every: int | None) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    campaign: dict[str, Any] = {
        "scenario": "paper-realistic", "controllers": controllers, "seeds": seeds
    }  # fmt: skip
    if keep_every is not None:
        campaign["keep_bags"] = {"every": keep_every}
    data["campaigns"] = {"profile": campaign}
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


def _record_run(record: Any, params: Any, run: Any) -> list[Any]:
    """Record ``run``'s pending episodes in this process, as the campaign command does."""
    from pipeline.stages.campaign_run import completion_marker

    done = completion_marker(run, lambda *a: None)
    outcomes: list[Any] = record(
        params, run.pending, out_dir=run.out_dir, force=True, commit=run.commit, on_event=done
    )
    bad = [o for o in outcomes if o.status != "ok"]
    if bad:
        raise SystemExit(f"{bad[0].name}: {bad[0].status}: {bad[0].reason}")
    return outcomes


def _end_to_end(
    *, wall_s: float, cpu_s: float, episodes: int, floor_s: float, plant_floor_s: float
) -> dict[str, Any]:
    """Per episode end to end (record, write, the report's share), wall and CPU, against
    the floors; and 10,000 episodes extrapolated on 2 cores at ``JOBS2_EFFICIENCY``."""
    per_s = wall_s / episodes
    return {
        "end_to_end_ms_per_episode": round(1e3 * per_s, 1),
        "end_to_end_cpu_ms_per_episode": round(1e3 * cpu_s / episodes, 1),
        "end_to_end_x_floor": round(per_s / floor_s, 2),
        "end_to_end_cpu_x_floor": round(cpu_s / episodes / floor_s, 2),
        "end_to_end_x_plant_floor": round(per_s / plant_floor_s, 2),
        "extrapolated_10k_2cores_s": round(1e4 * per_s / (2 * JOBS2_EFFICIENCY)),
        "floor_10k_2cores_s": round(1e4 * floor_s / 2),
        "plant_floor_10k_2cores_s": round(1e4 * plant_floor_s / 2),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--controllers", default="pid,ctc")
    ap.add_argument("--keep-every", type=int, default=None, metavar="K",
                    help="profile the sampled campaign: keep_bags: {every: K}")  # fmt: skip
    ap.add_argument("--no-report", action="store_true")
    args = ap.parse_args()
    from pipeline.params import load_params
    from pipeline.stages.campaign_run import plan_run, sample_without_bags
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
        params = load_params(
            _params(
                Path(tmp), seeds=args.seeds, controllers=controllers, keep_every=args.keep_every
            )
        )
        run = plan_run(params, "profile", out=Path(tmp) / "rec")
        episodes = len(run.pending)
        # the floor before and after the run (best of both): other load moves it
        converged = measure_floor()  # benches/floor.py: what every throughput bench states
        floors = [physics_floor_s(run.pending[0], 4011) for _ in range(3)]
        t0, c0 = time.perf_counter(), time.process_time()
        outcomes = _record_run(record, params, run)
        reruns, rerun_s = 0, 0.0
        if run.sampled:  # as `pipeline record --campaign` does after a keep_bags campaign
            with timers.stage("sample selection"):
                keys = sample_without_bags(run)
                rerun = plan_run(params, "profile", out=Path(tmp) / "rec", only=keys)
            reruns, t1 = len(keys), time.perf_counter()
            if keys:
                _record_run(record, params, rerun)
            rerun_s = time.perf_counter() - t1
        record_s = time.perf_counter() - t0
        record_cpu_s = time.process_time() - c0
        # a worker's partial is measured by the report's code: charge it to "partial"
        for stage in REPORT_STAGES:
            timers.total_s["partial"] += timers.total_s.pop(stage, 0.0)
        timed = sum(timers.total_s[s] for s in RECORD_STAGES)
        timers.total_s["other"] = record_s - timed
        control_dt_s = run.pending[0].sim.physics_dt_s * run.pending[0].sim.control_period_steps
        steps = round(outcomes[0].duration_s / control_dt_s) + 1
        # the settled pre-roll makes episodes differ in length: every episode's own steps
        total_steps = sum(round(o.duration_s / control_dt_s) + 1 for o in outcomes)
        converged = converged.merged(measure_floor())
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
            "keep_every": args.keep_every,
            "bags_kept": sum(1 for _ in run.out_dir.rglob("*.mcap")),
            "sample_reruns": reruns,
            "sample_reruns_s": round(rerun_s, 2),
            "record_s": round(record_s, 2),
            "record_cpu_s": round(record_cpu_s, 2),
            "record": _table(timers, RECORD_STAGES, episodes, floor_s),
            "campaign_mb_per_episode": round(
                sum(p.stat().st_size for p in run.out_dir.rglob("*") if p.is_file())
                / episodes
                / 1e6,
                3,
            ),
        }
        report_s = report_cpu_s = 0.0
        if not args.no_report:
            t0, c0 = time.perf_counter(), time.process_time()
            run_report(recordings_dir=run.out_dir, out_dir=Path(tmp) / "report")
            report_s = time.perf_counter() - t0
            report_cpu_s = time.process_time() - c0
            timers.total_s["report outputs"] = report_s - sum(
                timers.total_s[s] for s in REPORT_STAGES[:2]
            )
            result["report_s"] = round(report_s, 2)
            result["report_cpu_s"] = round(report_cpu_s, 2)
            result["report"] = _table(timers, REPORT_STAGES, episodes, floor_s)
        result["converged_floor"] = floor_summary(converged)
        result["converged_record"] = floor_fields(
            converged, control_steps=total_steps, wall_s=record_s, cpu_s=record_cpu_s
        )
        result["converged_end_to_end"] = floor_fields(
            converged, control_steps=total_steps, wall_s=record_s + report_s,
            cpu_s=record_cpu_s + report_cpu_s,
        )  # fmt: skip
        result |= _end_to_end(
            wall_s=record_s + report_s, cpu_s=record_cpu_s + report_cpu_s,
            episodes=episodes, floor_s=floor_s, plant_floor_s=plant_floor_s,
        )  # fmt: skip
    result["uptime_after"] = subprocess.run(
        ["uptime"], capture_output=True, text=True
    ).stdout.strip()
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
