"""The record stage: params -> plan per scenario -> episodes -> one ROS 2 bag each.

Planning happens once per scenario (``plan_path`` re-seeds OMPL and builds
fresh objects, so a path depends on the scenario and its seed alone); every
controller of that scenario then tracks the same reference. Episodes run in a
process pool (``--jobs``); each writes its own bag atomically. Nothing here
puts a wall-clock reading into a recording.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import multiprocessing as mp
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from multiprocessing import connection as mp_connection
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any, cast

import numpy as np

from pipeline import __version__
from pipeline.constants import FINAL_WINDOW_S
from pipeline.errors import EXIT_INTERRUPTED, ParamsError, PipelineError, interrupt_exit
from pipeline.fsutil import ensure_dir, remove_stale
from pipeline.params import Episode, Params, ScenarioParams
from pipeline.planning import PlannedPath, TimedTrajectory
from pipeline.robots.spec import RobotSpec, load_spec
from pipeline.settings import (
    ControllerSettings,
    EpisodeSettings,
    PlannerSettings,
    PlantSettings,
    ProtocolSettings,
    Uncertainty,
    per_joint,
)


@dataclass(frozen=True)
class ScenarioPlan:
    """A scenario's planned path and its timing (shared by every controller), or the error."""

    scenario: str
    path: PlannedPath | None
    trajectory: TimedTrajectory | None = None
    error: str = ""


@dataclass(frozen=True)
class EpisodeOutcome:
    """What the summary table shows for one episode."""

    name: str
    status: str  # "ok", "diverged" or "failed"
    reason: str
    bag: str
    max_abs_error_rad: float
    final_abs_error_rad: float
    duration_s: float
    wall_s: float
    contact: str = ""  # the execution-safety summary when the arm touched anything


# The code a recording depends on (relative to pipeline/): dvc.yaml's record deps list
# the same paths (a test keeps them equal), and recordings carry the last commit that
# changed them, so a commit that only touches the report, docs or results leaves the
# recordings' bytes, and committed results, reproducible from a clone.
RECORD_CODE = (
    "__init__.py",
    "__main__.py",
    "cli.py",
    "constants.py",
    "errors.py",
    "fsutil.py",
    "params.py",
    "settings.py",
    "trajectory.py",
    "yamlio.py",
    "identify/__init__.py",  # cli.py's sub-app, and a scenario's `nominal:` model file
    "identify/cli.py",
    "identify/defaults.py",
    "identify/model_file.py",
    "robots",
    "model",
    "kinematics",
    "planning",
    "control",
    "sim",
    "log/__init__.py",
    "log/bag.py",
    "log/cdr.py",
    "log/gather.py",
    "log/mcap.py",
    "log/msgdef.py",
    "log/rosbag2.py",
    "log/schemas.py",
    "stages/__init__.py",
    "stages/campaign.py",
    "stages/campaign_run.py",
    "stages/ray_executor.py",
    "stages/record.py",
)


def git_commit() -> str:
    """Last commit that changed the record code, ``-dirty`` if it has local changes.

    "" outside a git checkout.
    """
    package = Path(__file__).resolve().parents[1]

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=package, capture_output=True, text=True, check=True
        ).stdout.strip()

    try:
        sha = git("log", "-1", "--format=%H", "--", *RECORD_CODE)
        dirty = git("status", "--porcelain", "--untracked-files=no", "--", *RECORD_CODE)
    except (OSError, subprocess.CalledProcessError):
        return ""
    return f"{sha}-dirty" if sha and dirty else sha


def spec_as_dict(spec: RobotSpec) -> dict[str, Any]:
    """The robot spec as plain data (radians), as recorded in every bag."""
    return {
        "name": spec.name,
        "convention": spec.convention,
        "angle_unit": "rad",
        "joints": [
            {
                "name": j.name,
                "dh": [j.dh.alpha, j.dh.a, j.dh.d, j.dh.theta_offset],
                "limits": asdict(j.limits),
                **(
                    {
                        "inertial": {
                            "mass": j.inertial.mass,
                            "com": list(j.inertial.com),
                            "inertia": [
                                j.inertial.inertia[0][0],
                                j.inertial.inertia[1][1],
                                j.inertial.inertia[2][2],
                                j.inertial.inertia[0][1],
                                j.inertial.inertia[0][2],
                                j.inertial.inertia[1][2],
                            ],
                        }
                    }
                    if j.inertial is not None
                    else {}
                ),
                "collision": {"radius": j.collision_radius},
                "armature": j.armature,
            }
            for j in spec.joints
        ],
    }


def _field(source: str, path: str, msg: str) -> ParamsError:
    return ParamsError(f"{source}: {path}: {msg}")


def _joint_vector(
    values: Sequence[float], spec: RobotSpec, *, source: str, path: str
) -> np.ndarray:
    if len(values) != spec.dof:
        raise _field(source, path, f"expected {spec.dof} values for {spec.name}, got {len(values)}")
    q = np.asarray(values, dtype=float)
    for i, (v, j) in enumerate(zip(q, spec.joints, strict=True)):
        if not j.limits.lower <= v <= j.limits.upper:
            raise _field(
                source,
                f"{path}[{i}]",
                f"{v} rad is outside {j.name}'s limits "
                f"[{j.limits.lower:.4g}, {j.limits.upper:.4g}]",
            )
    return q


def resolve_goal(
    spec: RobotSpec, scenario: ScenarioParams, *, name: str, source: str
) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal joint vectors; a Cartesian goal is solved by IK, nearest the start."""
    start = _joint_vector(scenario.start, spec, source=source, path=f"scenarios.{name}.start")
    if scenario.goal.joints is not None:
        goal = _joint_vector(
            scenario.goal.joints, spec, source=source, path=f"scenarios.{name}.goal.joints"
        )
        return start, goal
    from pipeline.kinematics import solve_pose_nearest

    pose = scenario.goal.pose
    assert pose is not None
    try:
        goal = solve_pose_nearest(
            spec,
            position=pose.position,
            quaternion_wxyz=pose.quaternion_wxyz,
            rpy=pose.rpy,
            solver=pose.solver,
            near=start,
        )
    except PipelineError as err:
        raise _field(source, f"scenarios.{name}.goal.pose", str(err)) from err
    return start, goal


def plan_scenario(name: str, scenario: ScenarioParams, source: str) -> ScenarioPlan:
    """Plan and time one scenario; a failure is returned, not raised (it fails its episodes)."""
    from pipeline.planning import plan_path, time_parameterize

    try:
        spec = load_spec(scenario.robot)
        start, goal = resolve_goal(spec, scenario, name=name, source=source)
        path = plan_path(
            spec,
            start=start,
            goal=goal,
            obstacles=_boxes(scenario),
            time_limit_s=scenario.planner.time_limit_s,
            simplify=scenario.planner.simplify,
            seed=scenario.planner.seed,
        )
        trajectory = time_parameterize(
            spec,
            path,
            velocity_scaling=scenario.timing.velocity_scaling,
            acceleration_scaling=scenario.timing.acceleration_scaling,
        )
    except PipelineError as err:
        return ScenarioPlan(name, None, error=str(err))
    return ScenarioPlan(name, path, trajectory)


def _boxes(scenario: ScenarioParams) -> list[Any]:
    from pipeline.model.scene import Box

    return [Box(b.name, b.center, b.half_size) for b in scenario.obstacles]


def _plant_is_exact(spec: RobotSpec, plant_spec: RobotSpec, scenario: ScenarioParams) -> bool:
    """The nominal model is the plant: nothing drawn, no friction, damping, payload, noise."""
    p = scenario.plant
    zero = (
        _per_joint(p.damping),
        _per_joint(p.frictionloss),
        (p.payload_kg,),
        (p.position_noise_std_rad, p.velocity_noise_std_rad_s),
    )
    return plant_spec == spec and all(x == 0 for group in zero for x in group)


def _per_joint(value: float | list[float]) -> tuple[float, ...]:
    return tuple(value) if isinstance(value, list) else (float(value),)


def failed_outcome(name: str, reason: str, wall_s: float = 0.0) -> EpisodeOutcome:
    """The outcome of an episode that produced no recording."""
    return EpisodeOutcome(name, "failed", reason, "", float("nan"), float("nan"), 0.0, wall_s)


def plan_all(
    params: Params, episodes: Sequence[Episode], *, emit: Callable[[str, str, float], None]
) -> tuple[dict[str, ScenarioPlan], dict[str, str]]:
    """Plan once per distinct plan input (robot, start, goal, obstacles, planner, timing).

    Returns:
        The plans by plan key, and each episode's plan key by episode name.
    """
    from pipeline.stages.campaign import plan_key

    plan_of: dict[str, str] = {}
    named: dict[str, str] = {}  # plan key -> a scenario name for messages
    by_scenario: dict[int, str] = {}  # campaign episodes share scenario objects
    for e in episodes:
        key = by_scenario.get(id(e.scenario))
        if key is None:
            key = by_scenario[id(e.scenario)] = plan_key(e.scenario)
        plan_of[e.name] = key
        named.setdefault(key, e.scenario_name)
    plans: dict[str, ScenarioPlan] = {}
    scenarios = {plan_of[e.name]: e.scenario for e in episodes}
    for key in sorted(named, key=lambda k: (named[k], k)):
        plans[key] = plan_scenario(named[key], scenarios[key], params.source)
        emit("plan", named[key], 1.0)
    return plans, plan_of


def run_one(
    episode: Episode,
    plan: ScenarioPlan,
    *,
    out_dir: Path,
    force: bool,
    commit: str,
    progress: Callable[[float], None] | None = None,
    before_write: Callable[[], None] | None = None,
) -> EpisodeOutcome:
    """Run one episode and write its bag. Errors become a failed outcome, not a raise.

    ``before_write`` runs after the simulation, right before the bag is written and
    published (a pool worker exits there if its parent is gone).
    """
    wall0 = time.perf_counter()
    bag_dir = out_dir / episode.name
    try:
        if plan.path is None or plan.trajectory is None:
            raise PipelineError(plan.error)
        outcome = _run_and_write(
            episode,
            plan.path,
            plan.trajectory,
            bag_dir=bag_dir,
            force=force,
            commit=commit,
            progress=progress,
            before_write=before_write,
        )
    except (PipelineError, OSError, MemoryError) as err:
        if isinstance(err, OSError):
            reason = f"{bag_dir}: cannot write the recording ({err.strerror or err})"
        elif isinstance(err, MemoryError):
            reason = "out of memory: shorten the episode (hold_s) or log less"
        else:
            reason = str(err)
        return failed_outcome(episode.name, reason, time.perf_counter() - wall0)
    return EpisodeOutcome(**{**asdict(outcome), "wall_s": time.perf_counter() - wall0})


def _run_and_write(
    episode: Episode,
    path: PlannedPath,
    trajectory: TimedTrajectory,
    *,
    bag_dir: Path,
    force: bool,
    commit: str,
    progress: Callable[[float], None] | None,
    before_write: Callable[[], None] | None = None,
) -> EpisodeOutcome:
    from pipeline.control import make_controller
    from pipeline.identify.model_file import nominal_spec
    from pipeline.log.bag import write_episode_bag
    from pipeline.model.mjcf import PlantOptions
    from pipeline.model.uncertainty import draw_plant, link_inertials, with_plant
    from pipeline.sim.runner import run_episode
    from pipeline.sim.safety import SKIP_WITHIN_M, assess_execution

    scenario = episode.scenario
    spec = load_spec(scenario.robot)
    sim = episode.sim
    control_dt_s = sim.physics_dt_s * sim.control_period_steps
    nominal = nominal_spec(spec, scenario.nominal, where=f"scenarios.{episode.scenario_name}")
    controller = make_controller(
        episode.controller.type,
        nominal,
        episode.controller.gains,
        source=f"controllers.{episode.controller_name}",
    )
    p = scenario.plant
    uncertainty = Uncertainty(**p.uncertainty.model_dump())
    plant_spec = draw_plant(spec, uncertainty, seed=episode.seed)
    extra_armature = _per_joint(p.armature)
    plant_spec = with_plant(
        plant_spec,
        link_inertials(plant_spec),
        [
            a + x
            for a, x in zip(plant_spec.armature, per_joint(extra_armature, spec.dof), strict=True)
        ],
    )
    plant = PlantOptions(
        damping=_per_joint(p.damping),
        frictionloss=_per_joint(p.frictionloss),
        payload_kg=p.payload_kg,
    )
    result = run_episode(
        spec,
        reference=trajectory,
        controller=controller,
        plant=plant,
        plant_spec=plant_spec,
        obstacles=_boxes(scenario),
        physics_dt_s=sim.physics_dt_s,
        control_period_steps=sim.control_period_steps,
        hold_s=scenario.hold_s,
        preroll_s=scenario.preroll_s,
        position_noise_std_rad=p.position_noise_std_rad,
        velocity_noise_std_rad_s=p.velocity_noise_std_rad_s,
        seed=episode.seed,
        progress=progress,
    )
    k0 = int(result.extra["motion_start_row"])
    motion_start_s = float(result.extra["motion_start_s"])
    # contacts and clearance along the plant's true motion: every control step that is
    # not provably within SKIP_WITHIN_M of a checked one
    safety = assess_execution(
        spec,
        q=result.q_true,
        stamp_ns=result.stamp_ns,
        obstacles=_boxes(scenario),
        skip_within_m=SKIP_WITHIN_M,
    )
    plant_settings = PlantSettings(
        exact=_plant_is_exact(nominal, plant_spec, scenario),
        links=link_inertials(plant_spec),
        armature=tuple(float(a) for a in plant_spec.armature),
        nominal_armature=tuple(float(a) for a in nominal.armature),
        damping=per_joint(_per_joint(p.damping), spec.dof),
        frictionloss=per_joint(_per_joint(p.frictionloss), spec.dof),
        payload_kg=p.payload_kg,
        position_noise_std_rad=p.position_noise_std_rad,
        velocity_noise_std_rad_s=p.velocity_noise_std_rad_s,
        uncertainty=uncertainty,
        physics_dt_s=sim.physics_dt_s,
        control_period_s=control_dt_s,
    )
    at_start = min(k0, len(result.stamp_ns) - 1)
    # planning_time_s is wall clock: printed, never recorded (recordings are byte-reproducible)
    settings = EpisodeSettings(
        episode=episode.name,
        robot=spec_as_dict(spec),
        scenario={"name": episode.scenario_name, **scenario.model_dump()},
        controller=ControllerSettings(
            name=episode.controller_name,
            type=episode.controller.type,
            gains=controller.settings(),
        ),
        plant=plant_settings,
        planner=PlannerSettings(
            planner=path.planner,
            seed=path.seed,
            time_limit_s=path.time_limit_s,
            simplify=path.simplified,
            direct=path.direct,
            n_waypoints=len(path.waypoints),
            n_states_before_simplify=path.n_states_before_simplify,
            path_length_rad=path.path_length_rad,
            padding_m=path.padding_m,
            check_step_rad=path.check_step_rad,
            interpolation=trajectory.interpolation,
            trajectory_duration_s=float(trajectory.duration_s),
            velocity_scaling=scenario.timing.velocity_scaling,
            acceleration_scaling=scenario.timing.acceleration_scaling,
            start=tuple(float(x) for x in path.start),
            goal=tuple(float(x) for x in path.goal),
        ),
        protocol=ProtocolSettings(
            motion_start_s=motion_start_s,
            hold_s=scenario.hold_s,
            start_abs_error_rad=tuple(
                float(x) for x in np.abs(result.q_ref[at_start] - result.q_true[at_start])
            )
            if result.stamp_ns.size
            else (),
            start_effort_nm=tuple(float(x) for x in result.tau_nm[at_start])
            if result.stamp_ns.size
            else (),
            reproduces_paper=scenario.reproduces_paper,
        ),
        safety=safety,
        seed=episode.seed,
        status=result.status,
        reason=result.reason,
        mujoco_warnings=result.mujoco_warnings,
        package_version=__version__,
        git_commit=commit,
        campaign=episode.campaign,
    )
    metadata = {
        "episode": episode.name,
        "scenario": episode.scenario_name,
        "controller": episode.controller_name,
        "robot": spec.name,
        "seed": str(episode.seed),
        **({"campaign": episode.campaign.name} if episode.campaign else {}),
        "status": result.status,
        "settings": json.dumps(settings.to_dict(), sort_keys=True, separators=(",", ":")),
    }
    if before_write is not None:
        before_write()
    write_episode_bag(
        bag_dir,
        spec=spec,
        result=result,
        planned=trajectory.samples(0.01),
        motion_start_ns=round(motion_start_s * 1e9),
        metadata=metadata,
        joint_state_decimation=sim.joint_state_decimation,
        tf_rate_hz=sim.tf_rate_hz,
        ros_distro=sim.ros_distro,
        force=force,
    )
    # true tracking error from the motion start (the report's definition)
    err = np.abs(result.q_ref[k0:] - result.q_true[k0:])
    # same window as the report's "error at the target"
    n_hold = max(1, round(min(FINAL_WINDOW_S, scenario.hold_s / 2) / control_dt_s))
    return EpisodeOutcome(
        name=episode.name,
        status=result.status,
        reason=result.reason,
        bag=str(bag_dir),
        max_abs_error_rad=float(err.max()) if err.size else float("nan"),
        final_abs_error_rad=float(err[-n_hold:].mean(axis=0).max()) if err.size else float("nan"),
        duration_s=float(result.stamp_ns[-1] * 1e-9) if result.stamp_ns.size else 0.0,
        wall_s=0.0,
        contact=safety.summary() if safety.touched else "",
    )


# --- resource estimate ----------------------------------------------------------------

# What one control step costs, per joint, measured on the paper scenario (UR5, 1 kHz, full
# logging incl. the true state): peak RSS of `pipeline record` grows by ~3.6 kB per control
# step (6 joints) with the episode's length (benches/record_memory.py, docs/BENCHMARKS.md).
# The episode is held in memory whole (EpisodeResult arrays, then every CDR message, then
# the MCAP chunks), so this is what a longer episode adds. 800 B is the measured ~605 B
# plus a margin, so the estimate stays an upper bound when logging grows a little
# (tests/stages/test_record_budget.py fails when it no longer is).
BYTES_PER_JOINT_STEP = 800
# Wall time per physics step and joint: 5-14 us measured for a whole process, idle to busy
# machine (simulation, control, safety checks and writing), rounded up.
SECONDS_PER_JOINT_STEP = 2e-5
MAX_EPISODE_WALL_S = 2 * 3600.0  # longer is a typo in hold_s or physics_dt_s, not a study
MEMORY_SHARE = 0.8  # of MemAvailable, split between the episodes that run at once


@dataclass(frozen=True)
class EpisodeEstimate:
    """What an episode will cost, from its settings alone.

    Attributes:
        duration_s: simulated time (pre-roll + motion + hold) [s].
        control_steps: logged rows.
        physics_steps: MuJoCo steps.
        memory_bytes: peak memory the episode adds [B].
        wall_s: wall-clock time [s].
    """

    duration_s: float
    control_steps: int
    physics_steps: int
    memory_bytes: int
    wall_s: float


def estimate_episode(episode: Episode, *, dof: int, motion_s: float) -> EpisodeEstimate:
    """Estimate one episode's memory and time (``motion_s``: the reference's duration)."""
    sim = episode.sim
    duration_s = episode.scenario.preroll_s + motion_s + episode.scenario.hold_s
    control_s = sim.physics_dt_s * sim.control_period_steps
    control_steps = int(duration_s / control_s) + 1
    physics_steps = control_steps * sim.control_period_steps
    return EpisodeEstimate(
        duration_s=duration_s,
        control_steps=control_steps,
        physics_steps=physics_steps,
        memory_bytes=control_steps * dof * BYTES_PER_JOINT_STEP,
        wall_s=physics_steps * dof * SECONDS_PER_JOINT_STEP,
    )


def available_memory_bytes() -> int:
    """``MemAvailable`` of /proc/meminfo (Linux); 8 GiB where it cannot be read."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 8 * 1024**3


def _size(n_bytes: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes / 1e3:.3g} kB"


def _duration(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.3g} h"
    if seconds >= 60:
        return f"{seconds / 60:.3g} min"
    return f"{seconds:.3g} s"


def check_budget(
    params: Params,
    episodes: Sequence[Episode],
    *,
    motion_s: Mapping[str, float],
    jobs: int,
    memory_bytes: int | None = None,
) -> None:
    """Refuse, before any episode runs, one that cannot fit in memory or time.

    Args:
        motion_s: reference duration per scenario [s] (0 before planning: a lower bound).
        jobs: episodes run at once; each gets an equal share of the memory.
        memory_bytes: memory to share (default: :func:`available_memory_bytes`).

    Raises:
        ParamsError: one line with the estimate and the fields to change.
    """
    parallel = max(1, min(jobs, len(episodes)))
    share = MEMORY_SHARE * (memory_bytes or available_memory_bytes()) / parallel
    for episode in episodes:
        spec = load_spec(episode.scenario.robot)
        est = estimate_episode(
            episode, dof=spec.dof, motion_s=motion_s.get(episode.scenario_name, 0.0)
        )
        where = f"scenarios.{episode.scenario_name}.hold_s or sim.control_period_steps"
        what = (
            f"episode '{episode.name}' is {est.duration_s:.6g} s at "
            f"{est.control_steps:,} control steps x {spec.dof} joints"
        )
        if est.memory_bytes > share:
            per = f" (each of {parallel} parallel episodes)" if parallel > 1 else ""
            raise ParamsError(
                f"{params.source}: {what}: it would hold about {_size(est.memory_bytes)} in "
                f"memory, more than the {_size(share)} this machine can give it{per}; "
                f"lower {where}" + (" or --jobs" if parallel > 1 else "")
            )
        if est.wall_s > MAX_EPISODE_WALL_S:
            raise ParamsError(
                f"{params.source}: {what} ({est.physics_steps:,} physics steps): it would "
                f"run for about {_duration(est.wall_s)}, more than "
                f"{_duration(MAX_EPISODE_WALL_S)}; lower {where}, or raise sim.physics_dt_s"
            )


# --- orchestration (parent process) ---------------------------------------------------


class Interrupted(PipelineError):
    """Ctrl-C (SIGINT) or SIGTERM during a record run: what finished and what did not.

    Attributes:
        finished: outcomes of the episodes that ended (ok, diverged or failed).
        unfinished: names of the episodes that were cancelled (running or queued).
        exit_code: 130 for Ctrl-C, 143 for SIGTERM (what shells report).
    """

    exit_code = EXIT_INTERRUPTED

    def __init__(
        self,
        finished: Sequence[EpisodeOutcome],
        unfinished: Sequence[str],
        *,
        cause: BaseException | None = None,
    ) -> None:
        self.finished = tuple(finished)
        self.unfinished = tuple(unfinished)
        word, self.exit_code = interrupt_exit(cause or KeyboardInterrupt())
        done = ", ".join(f"{o.name} ({o.status})" for o in self.finished) or "none"
        super().__init__(
            f"{word}: finished {len(self.finished)} episode(s): {done}; not recorded: "
            f"{', '.join(self.unfinished) or 'none'}"
        )


def _mp_context() -> mp.context.BaseContext:
    # fork where available: workers inherit the imported libraries (a spawned worker spends
    # ~2 s importing MuJoCo, Pinocchio and OMPL). No library here runs threads before the
    # fork, and the plan is computed before it, so nothing random is inherited mid-use.
    return mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")


def _episode_progress(
    emit: Callable[[str, str, float], None], name: str
) -> Callable[[float], None]:
    return lambda fraction: emit("episode", name, fraction)


_PR_SET_PDEATHSIG = 1


def _die_with_parent(parent_pid: int) -> None:
    """Make this (worker) process end when ``parent_pid`` does, however it ends.

    Linux: the kernel sends SIGKILL at the parent's death (``PR_SET_PDEATHSIG``). Elsewhere
    a daemon thread polls ``getppid``. Either way a worker never outlives its parent.
    """
    armed = False
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)
    if not armed:

        def watch() -> None:
            while os.getppid() == parent_pid:
                time.sleep(0.2)
            os._exit(1)

        threading.Thread(target=watch, name="parent-watch", daemon=True).start()


class _Cancelled(BaseException):
    """Raised inside a worker's episode once the parent cancelled the run (not an error)."""


def _worker_main(
    conn: Connection, cancel: Any, parent_pid: int, out_dir: str, force: bool, commit: str
) -> None:
    """A pool worker: run the episodes the parent sends until it sends None."""
    _die_with_parent(parent_pid)
    # Ctrl-C reaches the whole process group, and so does SIGTERM from `timeout`, systemd
    # or a CI runner; the parent decides what it cancels (and kills the workers).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)

    def before_write() -> None:
        if os.getppid() != parent_pid:
            os._exit(1)  # never publish a recording for a run that is gone
        if cancel.is_set():
            raise _Cancelled

    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        episode, plan = task

        def progress(fraction: float, name: str = episode.name) -> None:
            if cancel.is_set():
                raise _Cancelled
            conn.send(("progress", name, fraction))

        try:
            outcome = run_one(
                episode, plan, out_dir=Path(out_dir), force=force, commit=commit,
                progress=progress, before_write=before_write,
            )  # fmt: skip
        except _Cancelled:
            conn.send(("cancelled", episode.name, None))
            continue
        conn.send(("done", episode.name, outcome))


def _run_pool(
    episodes: Sequence[Episode],
    plans: dict[str, ScenarioPlan],
    *,
    out_dir: Path,
    force: bool,
    commit: str,
    jobs: int,
    emit: Callable[[str, str, float], None],
    started_s: float,
) -> dict[str, EpisodeOutcome]:
    """Run episodes on ``jobs`` worker processes, one pipe each (no manager process).

    A worker that dies (out-of-memory killer, a crash in a library) fails its episode
    and is replaced. Ctrl-C cancels the run: workers abandon their episodes at the next
    progress report (or just before writing), those already writing get
    :data:`CANCEL_GRACE_S` to finish, then every worker is killed and
    :class:`Interrupted` raised.
    """
    ctx = _mp_context()
    cancel = ctx.Event()
    queued = list(episodes)
    outcomes: dict[str, EpisodeOutcome] = {}
    workers: dict[Connection, tuple[Any, str | None]] = {}  # conn -> (process, episode)

    def start_worker() -> None:
        here, there = ctx.Pipe()
        proc = ctx.Process(  # type: ignore[attr-defined]
            target=_worker_main,
            args=(there, cancel, os.getpid(), str(out_dir), force, commit),
            name="pipeline-record-worker",
            daemon=True,
        )
        proc.start()
        there.close()
        workers[here] = (proc, None)

    def feed(conn: Connection) -> None:
        proc, _ = workers[conn]
        if queued:
            episode = queued.pop(0)
            conn.send((episode, plans[episode.name]))
            workers[conn] = (proc, episode.name)
        else:
            with contextlib.suppress(OSError):
                conn.send(None)
            workers[conn] = (proc, None)

    try:
        for _ in range(min(jobs, len(queued))):
            start_worker()
        for conn in list(workers):
            feed(conn)
        while len(outcomes) < len(episodes):
            ready = mp_connection.wait(list(workers), timeout=0.5)
            for item in ready:
                conn = cast(Connection, item)
                proc, current = workers[conn]
                try:
                    kind, name, value = conn.recv()
                except (EOFError, OSError):
                    proc.join(timeout=5)
                    if current is not None and current not in outcomes:
                        outcomes[current] = _worker_died(current, proc.exitcode)
                        emit("done", current, 1.0)
                    del workers[conn]
                    conn.close()
                    if queued:
                        start_worker()
                        feed(list(workers)[-1])
                    continue
                if kind == "progress":
                    emit("episode", name, value)
                else:
                    outcomes[name] = value
                    emit("done", name, 1.0)
                    feed(conn)
            if not workers and len(outcomes) < len(episodes):  # pragma: no cover - defensive
                for e in queued:
                    outcomes[e.name] = _worker_died(e.name, None)
                queued.clear()
    except KeyboardInterrupt as err:
        cancel.set()
        _collect_until_idle(workers, outcomes, timeout_s=CANCEL_GRACE_S)
        _kill_all(workers)
        _sweep(out_dir)
        raise _interrupted(episodes, outcomes, out_dir, started_s=started_s, cause=err) from None
    finally:
        _kill_all(workers)
        _sweep(out_dir, mine=False)  # what a worker that died mid-write left
    return outcomes


CANCEL_GRACE_S = 3.0  # a worker writing its bag when Ctrl-C (SIGTERM) comes may finish it


def _collect_until_idle(
    workers: dict[Connection, tuple[Any, str | None]],
    outcomes: dict[str, EpisodeOutcome],
    *,
    timeout_s: float,
) -> None:
    """After a cancel: take the outcomes busy workers still send, until none is busy."""
    busy = [conn for conn, (_, current) in workers.items() if current is not None]
    deadline = time.monotonic() + timeout_s
    while busy and time.monotonic() < deadline:
        for item in mp_connection.wait(busy, timeout=max(0.0, deadline - time.monotonic())):
            conn = cast(Connection, item)
            try:
                kind, name, value = conn.recv()
            except (EOFError, OSError):
                busy.remove(conn)
                continue
            if kind == "done":
                outcomes[name] = value
            if kind in ("done", "cancelled"):
                busy.remove(conn)


def _interrupted(
    episodes: Sequence[Episode],
    outcomes: Mapping[str, EpisodeOutcome],
    out_dir: Path,
    *,
    started_s: float,
    cause: BaseException,
) -> Interrupted:
    """What finished: the outcomes received, plus any recording this run published whose
    summary the interrupt cut off (its folder is newer than the run)."""
    finished = [outcomes[e.name] for e in episodes if e.name in outcomes]
    unfinished = []
    for e in episodes:
        if e.name in outcomes:
            continue
        try:
            # file times may lag time.time() by a clock tick
            published = (out_dir / e.name).stat().st_mtime >= started_s - 0.05
        except OSError:
            published = False
        if published:
            finished.append(
                EpisodeOutcome(e.name, "recorded", "summary lost to the interrupt", "",
                               float("nan"), float("nan"), 0.0, 0.0)
            )  # fmt: skip
        else:
            unfinished.append(e.name)
    return Interrupted(finished, unfinished, cause=cause)


def _worker_died(name: str, exitcode: int | None) -> EpisodeOutcome:
    how = f"killed by signal {-exitcode}" if exitcode is not None and exitcode < 0 else (
        f"exit code {exitcode}")  # fmt: skip
    hint = " (out of memory?)" if exitcode == -signal.SIGKILL else ""
    return EpisodeOutcome(
        name, "failed", f"its worker process died ({how}){hint}", "", float("nan"),
        float("nan"), 0.0, 0.0,
    )  # fmt: skip


def _kill_all(workers: dict[Connection, tuple[Any, str | None]]) -> None:
    for conn, (proc, _) in list(workers.items()):
        if proc.is_alive():
            proc.kill()
        proc.join(timeout=5)
        conn.close()
    workers.clear()


# Work folders of the bag writer (pipeline/log/bag.py: ``.<name>.partial-<pid>`` while
# writing, ``.<name>.old-<pid>`` while replacing with --force).
_STALE_BAG = re.compile(r"\..+\.(?:partial|old)-(?P<pid>\d+)")


def _sweep(out_dir: Path, *, mine: bool = True) -> None:
    """Remove work folders of writers that are gone (and this process's own, if ``mine``)."""
    remove_stale(out_dir, _STALE_BAG, also_pids=frozenset({os.getpid()} if mine else ()))


def check_outputs_free(episodes: Sequence[Episode], out_dir: Path, *, force: bool) -> None:
    """Refuse up front (before any work) a bad --out or to overwrite a recording.

    Also removes what killed runs left in ``out_dir`` (hidden work folders whose process
    is gone).
    """
    ensure_dir(out_dir)
    _sweep(out_dir, mine=False)
    if force:
        return
    taken = [e.name for e in episodes if (out_dir / e.name).exists()]
    if taken:
        more = f" (and {len(taken) - 1} more)" if len(taken) > 1 else ""
        raise PipelineError(
            f"{out_dir / taken[0]}: recording exists{more}; pass --force to overwrite, "
            "or --out to write elsewhere"
        )


def validate_episodes(params: Params, episodes: Sequence[Episode]) -> None:
    """Fail fast, before any work, on what params alone can get wrong.

    Unknown robot, a robot without dynamics, start/goal of the wrong length or
    outside the joint limits, unknown controller type or bad gains. Collisions
    and reachability are the planner's to judge, per episode.
    """
    from pipeline.control import make_controller

    for episode in episodes:
        scenario = episode.scenario
        try:
            spec = load_spec(scenario.robot)
        except PipelineError as err:
            raise ParamsError(
                f"{params.source}: scenarios.{episode.scenario_name}.robot: {err}"
            ) from err
        spec.require_dynamics(f"recording scenario '{episode.scenario_name}' (simulation)")
        where = f"scenarios.{episode.scenario_name}"
        # joint vectors and Cartesian goals (IK: reachable, solver known) once, up front
        resolve_goal(spec, scenario, name=episode.scenario_name, source=params.source)
        for key in ("damping", "frictionloss", "armature"):
            value = getattr(scenario.plant, key)
            if isinstance(value, list) and len(value) not in (1, spec.dof):
                raise _field(
                    params.source,
                    f"{where}.plant.{key}",
                    f"expected 1 or {spec.dof} values, got {len(value)}",
                )
        make_controller(
            episode.controller.type,
            spec,
            episode.controller.gains,
            source=f"{params.source}: controllers.{episode.controller_name}",
        )


def prepare(
    params: Params,
    *,
    out_dir: Path,
    only: list[str] | None = None,
    force: bool = False,
    jobs: int = 1,
) -> tuple[Episode, ...]:
    """The selected episodes, validated, with --out usable: every input error, before work.

    The resource estimate here knows only ``hold_s`` (the motion is not planned yet): a
    lower bound. :func:`record` checks again with the planned durations.
    """
    episodes = params.select(only)
    validate_episodes(params, episodes)
    check_budget(params, episodes, motion_s={}, jobs=jobs)
    check_outputs_free(episodes, out_dir, force=force)
    return episodes


def record(
    params: Params,
    episodes: Sequence[Episode],
    *,
    out_dir: Path,
    jobs: int = 1,
    force: bool = False,
    on_event: Callable[[str, str, float], None] | None = None,
    executor: str = "local",
    address: str | None = None,
    commit: str | None = None,
) -> list[EpisodeOutcome]:
    """Run prepared episodes; returns one outcome per episode (failures included).

    ``on_event(kind, name, value)`` reports progress: kind is "plan" (value 0/1),
    "episode" (fraction done) or "done". ``executor``: "local" (this process, or a pool
    of ``jobs`` processes) or "ray" (tasks on the Ray instance at ``address``, see
    :mod:`pipeline.stages.ray_executor`). ``commit``: the recording code's version to
    record (default: :func:`git_commit`). The bytes do not depend on the executor.

    Raises:
        ParamsError: an episode would not fit in memory or time (before any runs).
        Interrupted: Ctrl-C or SIGTERM; nothing half-written is left under a final name.
    """
    emit = on_event or (lambda kind, name, value: None)
    started_s = time.time()
    commit = commit if commit is not None else git_commit()
    outcomes: dict[str, EpisodeOutcome] = {}
    try:
        plans, plan_of = plan_all(params, episodes, emit=emit)
        plan_by_episode = {e.name: plans[plan_of[e.name]] for e in episodes}
        motion_s: dict[str, float] = {}  # the longest reference of each scenario
        for e in episodes:
            trajectory = plan_by_episode[e.name].trajectory
            if trajectory is not None:
                duration_s = float(trajectory.duration_s)
                motion_s[e.scenario_name] = max(motion_s.get(e.scenario_name, 0.0), duration_s)
        # the estimate depends on the scenario and sim alone: one episode per scenario
        distinct = list({id(e.scenario): e for e in episodes}.values())
        check_budget(params, distinct, motion_s=motion_s, jobs=jobs)
        if executor == "ray":
            from pipeline.stages.ray_executor import run_on_ray

            outcomes = run_on_ray(episodes, plans, plan_of, out_dir=out_dir, force=force,
                                  commit=commit, address=address, emit=emit)  # fmt: skip
        elif jobs <= 1 or len(episodes) == 1:
            for e in episodes:
                outcomes[e.name] = run_one(
                    e,
                    plan_by_episode[e.name],
                    out_dir=out_dir,
                    force=force,
                    commit=commit,
                    progress=_episode_progress(emit, e.name),
                )
                emit("done", e.name, 1.0)
        else:
            outcomes = _run_pool(episodes, plan_by_episode, out_dir=out_dir, force=force,
                                 commit=commit, jobs=jobs, emit=emit,
                                 started_s=started_s)  # fmt: skip
    except KeyboardInterrupt as err:
        _sweep(out_dir)
        raise _interrupted(episodes, outcomes, out_dir, started_s=started_s, cause=err) from None
    return [outcomes[e.name] for e in episodes]
