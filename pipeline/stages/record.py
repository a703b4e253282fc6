"""The record stage: params -> plan per scenario -> episodes -> one ROS 2 bag each.

Planning happens once per scenario (``plan_path`` re-seeds OMPL and builds
fresh objects, so a path depends on the scenario and its seed alone); every
controller of that scenario then tracks the same reference. Episodes run in a
process pool (``--jobs``); each writes its own bag atomically. Nothing here
puts a wall-clock reading into a recording.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import subprocess
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline import __version__
from pipeline.constants import FINAL_WINDOW_S
from pipeline.errors import ParamsError, PipelineError
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
    "cli.py",
    "constants.py",
    "errors.py",
    "params.py",
    "settings.py",
    "trajectory.py",
    "yamlio.py",
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


def run_one(
    episode: Episode,
    plan: ScenarioPlan,
    *,
    out_dir: Path,
    force: bool,
    commit: str,
    progress: Callable[[float], None] | None = None,
) -> EpisodeOutcome:
    """Run one episode and write its bag. Errors become a failed outcome, not a raise."""
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
        )
    except (PipelineError, OSError, MemoryError) as err:
        if isinstance(err, OSError):
            reason = f"{bag_dir}: cannot write the recording ({err.strerror or err})"
        elif isinstance(err, MemoryError):
            reason = "out of memory: shorten the episode (hold_s) or log less"
        else:
            reason = str(err)
        return EpisodeOutcome(
            episode.name, "failed", reason, "", float("nan"), float("nan"), 0.0,
            time.perf_counter() - wall0,
        )  # fmt: skip
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
) -> EpisodeOutcome:
    from pipeline.control import make_controller
    from pipeline.log.bag import write_episode_bag
    from pipeline.model.mjcf import PlantOptions
    from pipeline.model.uncertainty import draw_plant, link_inertials, with_plant
    from pipeline.sim.runner import run_episode
    from pipeline.sim.safety import assess_execution

    scenario = episode.scenario
    spec = load_spec(scenario.robot)
    sim = episode.sim
    control_dt_s = sim.physics_dt_s * sim.control_period_steps
    controller = make_controller(
        episode.controller.type,
        spec,
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
    # contacts and clearance along the plant's true motion, every control step
    safety = assess_execution(
        spec, q=result.q_true, stamp_ns=result.stamp_ns, obstacles=_boxes(scenario)
    )
    plant_settings = PlantSettings(
        exact=_plant_is_exact(spec, plant_spec, scenario),
        links=link_inertials(plant_spec),
        armature=tuple(float(a) for a in plant_spec.armature),
        nominal_armature=tuple(float(a) for a in spec.armature),
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
    )
    metadata = {
        "episode": episode.name,
        "scenario": episode.scenario_name,
        "controller": episode.controller_name,
        "robot": spec.name,
        "seed": str(episode.seed),
        "status": result.status,
        "settings": json.dumps(settings.to_dict(), sort_keys=True, separators=(",", ":")),
    }
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


# --- orchestration (parent process) ---------------------------------------------------


def _mp_context() -> mp.context.BaseContext:
    # fork where available: workers inherit the imported libraries (a spawned worker spends
    # ~2 s importing MuJoCo, Pinocchio and OMPL). No library here runs threads before the
    # fork, and the plan is computed before it, so nothing random is inherited mid-use.
    return mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")


def _progress_proxy(queue: Any, name: str) -> Callable[[float], None]:
    def report(fraction: float) -> None:
        queue.put((name, fraction))

    return report


def _episode_progress(
    emit: Callable[[str, str, float], None], name: str
) -> Callable[[float], None]:
    return lambda fraction: emit("episode", name, fraction)


def _episode_worker(
    episode: Episode, plan: ScenarioPlan, out_dir: str, force: bool, commit: str, queue: Any
) -> EpisodeOutcome:
    return run_one(
        episode,
        plan,
        out_dir=Path(out_dir),
        force=force,
        commit=commit,
        progress=_progress_proxy(queue, episode.name),
    )


def check_outputs_free(episodes: Sequence[Episode], out_dir: Path, *, force: bool) -> None:
    """Refuse up front (before any work) a bad --out or to overwrite a recording."""
    if out_dir.exists() and not out_dir.is_dir():
        raise PipelineError(f"{out_dir}: --out is a file, expected a directory")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise PipelineError(
            f"{out_dir}: cannot create the output directory ({err.strerror})"
        ) from err
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


def _run_pool(
    episodes: Sequence[Episode],
    plans: dict[str, ScenarioPlan],
    *,
    out_dir: Path,
    force: bool,
    commit: str,
    jobs: int,
    emit: Callable[[str, str, float], None],
) -> dict[str, EpisodeOutcome]:
    ctx = _mp_context()
    manager = ctx.Manager()
    queue = manager.Queue()
    outcomes: dict[str, EpisodeOutcome] = {}
    try:
        with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            running: dict[str, Future[EpisodeOutcome]] = {
                e.name: pool.submit(
                    _episode_worker, e, plans[e.scenario_name], str(out_dir), force, commit, queue
                )
                for e in episodes
            }
            while len(outcomes) < len(running):
                while not queue.empty():
                    name, fraction = queue.get_nowait()
                    emit("episode", name, fraction)
                for name, fut in running.items():
                    if name not in outcomes and fut.done():
                        outcomes[name] = fut.result()
                        emit("done", name, 1.0)
                time.sleep(0.05)
    finally:
        manager.shutdown()
    return outcomes


def prepare(
    params: Params, *, out_dir: Path, only: list[str] | None = None, force: bool = False
) -> tuple[Episode, ...]:
    """The selected episodes, validated, with --out usable: every input error, before work."""
    episodes = params.select(only)
    validate_episodes(params, episodes)
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
) -> list[EpisodeOutcome]:
    """Run prepared episodes; returns one outcome per episode (failures included).

    ``on_event(kind, name, value)`` reports progress: kind is "plan" (value 0/1),
    "episode" (fraction done) or "done".
    """
    emit = on_event or (lambda kind, name, value: None)
    commit = git_commit()
    plans: dict[str, ScenarioPlan] = {}
    for name in sorted({e.scenario_name for e in episodes}):
        plans[name] = plan_scenario(name, params.scenarios[name], params.source)
        emit("plan", name, 1.0)
    outcomes: dict[str, EpisodeOutcome] = {}
    if jobs <= 1 or len(episodes) == 1:
        for e in episodes:
            outcomes[e.name] = run_one(
                e,
                plans[e.scenario_name],
                out_dir=out_dir,
                force=force,
                commit=commit,
                progress=_episode_progress(emit, e.name),
            )
            emit("done", e.name, 1.0)
    else:
        outcomes = _run_pool(episodes, plans, out_dir=out_dir, force=force, commit=commit,
                             jobs=jobs, emit=emit)  # fmt: skip
    return [outcomes[e.name] for e in episodes]
