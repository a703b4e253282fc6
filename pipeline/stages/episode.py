"""The episode runner: one episode on the MuJoCo plant, written as one ROS 2 bag.

:func:`run_one` is what every executor runs (in this process, in a pool worker, as a
Ray task); it writes its bag atomically and turns an error into a failed outcome.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.constants import FINAL_EDGE_S, FINAL_WINDOW_S
from pipeline.errors import ModelError, PipelineError
from pipeline.experiment.assemble import (
    bag_metadata,
    draw_scenario_plant,
    episode_settings,
    loop_settings,
    plant_run_options,
    scenario_spec,
)
from pipeline.fsutil import remove_stale
from pipeline.memory import out_of_memory
from pipeline.params import Episode
from pipeline.planning import PlannedPath, TimedTrajectory
from pipeline.stages.plans import ScenarioPlan, obstacle_boxes


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


DESIGN_SAMPLE_S = 0.01
"""Spacing [s] of the planned motion's samples the default gains are designed on."""


def failed_outcome(name: str, reason: str, wall_s: float = 0.0) -> EpisodeOutcome:
    """The outcome of an episode that produced no recording."""
    return EpisodeOutcome(name, "failed", reason, "", float("nan"), float("nan"), 0.0, wall_s)


def internal_error(err: BaseException) -> str:
    """The one-line reason of an episode stopped by an error that is no
    :class:`~pipeline.errors.PipelineError` (a bug), with where it was raised."""
    frames = traceback.extract_tb(err.__traceback__)
    where = f" at {Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else ""
    return f"internal error{where}: {type(err).__name__}: {err} (a bug: please report it)"


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
    """Run one episode and write its bag. Errors become a failed outcome, not a raise (an
    unexpected one too, so at ``-j 1`` the run's other episodes still run and keep theirs).

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
    except Exception as err:  # an engine's allocation failure (MuJoCo's FatalError), else a
        # bug: this episode fails alone, the run's others go on
        oom = out_of_memory(err)
        if oom is None:
            reason = internal_error(err)
        else:
            reason = f"{oom}: shorten the episode (hold_s), log less or use fewer --jobs"
        return failed_outcome(episode.name, reason, time.perf_counter() - wall0)
    return EpisodeOutcome(**{**asdict(outcome), "wall_s": time.perf_counter() - wall0})


def controller_nominal(episode: Episode) -> tuple[str | None, str]:
    """The nominal model path the episode's controller runs on (its own ``nominal:``, else
    its scenario's; None: the robot description's CAD values) and where it is set."""
    if episode.controller.nominal is not None:
        return episode.controller.nominal, f"controllers.{episode.controller_name}"
    return episode.scenario.nominal, f"scenarios.{episode.scenario_name}"


def plant_where(episode: Episode) -> str:
    """Where the plant the episode runs on is set in params: its controller's own
    ``plant:`` (``controllers.NAME.plant``), else its scenario's."""
    if episode.controller.plant is not None:
        return f"controllers.{episode.controller_name}.plant"
    return f"scenarios.{episode.scenario_name}.plant"


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
    from pipeline.control.contain import contained_controller
    from pipeline.control.controller import with_planned_path
    from pipeline.identify.model_file import nominal_path, nominal_spec, with_nominal_friction

    spec = scenario_spec(episode.scenario)
    given, where = controller_nominal(episode)  # the controller's own, else its scenario's
    model_path = nominal_path(given, seed=episode.seed)
    nominal = nominal_spec(spec, model_path, where=where)
    with contained_controller(
        episode.controller.type,
        lambda: make_controller(
            episode.controller.type,
            nominal,
            # default gains designed on the nominal inertia along the planned motion
            with_planned_path(
                with_nominal_friction(episode.controller.gains, model_path),
                trajectory.samples(DESIGN_SAMPLE_S).positions,
            ),
            source=f"controllers.{episode.controller_name}",
        ),
    ) as controller:  # a plug-in runs within its budgets, on read-only inputs
        result, gains, drawn = _simulate(episode, spec, controller, trajectory, progress)
    return _assess_and_write(
        episode, path, trajectory, spec=spec, nominal=nominal, result=result, gains=gains,
        drawn=drawn, bag_dir=bag_dir, force=force, commit=commit, before_write=before_write,
    )  # fmt: skip


def _simulate(
    episode: Episode,
    spec: Any,
    controller: Any,
    trajectory: TimedTrajectory,
    progress: Callable[[float], None] | None,
) -> tuple[Any, dict[str, Any], tuple[Any, Any]]:
    """Run the episode on the plant: (result, gains in effect, (plant spec, uncertainty))."""
    from pipeline.sim.runner import run_episode

    scenario, sim = episode.scenario, episode.sim
    p = scenario.plant
    where = plant_where(episode)
    try:
        plant_spec, plant, uncertainty = draw_scenario_plant(
            spec, scenario, seed=episode.seed, where=f"{where}.profile"
        )
        options = plant_run_options(spec, scenario, seed=episode.seed)
    except ModelError as err:
        message = str(err)
        if message.startswith("plant."):  # a draw's field: say whose plant
            raise ModelError(f"{where}{message.removeprefix('plant')}") from err
        raise
    result = run_episode(
        spec,
        reference=trajectory,
        controller=controller,
        plant=plant,
        plant_spec=plant_spec,
        obstacles=obstacle_boxes(scenario),
        physics_dt_s=sim.physics_dt_s,
        control_period_steps=sim.control_period_steps,
        integrator=sim.integrator,
        hold_s=scenario.hold_s,
        preroll_s=scenario.preroll_s,
        hold_max_s=scenario.hold_max_s,
        position_noise_std_rad=p.position_noise_std_rad,
        velocity_noise_std_rad_s=p.velocity_noise_std_rad_s,
        loop=loop_settings(scenario),
        seed=episode.seed,
        progress=progress,
        **options,
    )
    return result, controller.gains_in_effect(), (plant_spec, uncertainty)


def _assess_and_write(
    episode: Episode,
    path: PlannedPath,
    trajectory: TimedTrajectory,
    *,
    spec: Any,
    nominal: Any,
    result: Any,
    gains: dict[str, Any],
    drawn: tuple[Any, Any],
    bag_dir: Path,
    force: bool,
    commit: str,
    before_write: Callable[[], None] | None,
) -> EpisodeOutcome:
    from pipeline.control import controller_origin
    from pipeline.sim.safety import SKIP_WITHIN_M, assess_execution

    scenario = episode.scenario
    sim = episode.sim
    plant_spec, uncertainty = drawn
    k0 = result.motion_start_row
    motion_start_s = result.motion_start_s
    # contacts and clearance along the plant's true motion: every control step that is
    # not provably within SKIP_WITHIN_M of a checked one
    safety = assess_execution(
        spec,
        q=result.q_true,
        stamp_ns=result.stamp_ns,
        obstacles=obstacle_boxes(scenario),
        skip_within_m=SKIP_WITHIN_M,
    )
    settings = episode_settings(
        episode,
        spec=spec,
        nominal=nominal,
        plant_spec=plant_spec,
        uncertainty=uncertainty,
        gains=gains,
        origin=controller_origin(episode.controller.type),
        path=path,
        trajectory=trajectory,
        result=result,
        safety=safety,
        commit=commit,
    )
    if before_write is not None:
        before_write()
    recorded: dict[str, Any] = dict(
        spec=spec,
        result=result,
        planned=trajectory.samples(0.01),
        motion_start_ns=round(motion_start_s * 1e9),
        metadata=bag_metadata(episode, settings, robot=spec.name),
        joint_state_decimation=sim.joint_state_decimation,
        tf_rate_hz=sim.tf_rate_hz,
        ros_distro=sim.ros_distro,
    )
    _write_outputs(episode, bag_dir, recorded, force=force)
    # true tracking error from the motion start (the report's definition)
    err = np.abs(result.q_ref[k0:] - result.q_true[k0:])
    # (a run that diverged during the pre-roll has no sample from the motion start)
    t_s = (result.stamp_ns[k0:] - result.stamp_ns[min(k0, result.stamp_ns.size - 1)]) * 1e-9
    in_final = final_window(t_s, motion_end_s=float(trajectory.duration_s))
    return EpisodeOutcome(
        name=episode.name,
        status=result.status,
        reason=result.reason,
        bag=str(bag_dir),
        max_abs_error_rad=float(err.max()) if err.size else float("nan"),
        final_abs_error_rad=float(err[in_final].mean(axis=0).max()) if err.size else float("nan"),
        duration_s=float(result.stamp_ns[-1] * 1e-9) if result.stamp_ns.size else 0.0,
        wall_s=0.0,
        contact=safety.summary() if safety.touched else "",
    )


def _write_outputs(
    episode: Episode, bag_dir: Path, recorded: dict[str, Any], *, force: bool
) -> None:
    """Write the episode's bag and, in a ``keep_bags`` campaign, its metric partial.

    ``recorded``: the episode's arguments of
    :func:`~pipeline.log.bag.write_episode_bag` (but ``bag_dir`` and ``force``). The
    partial is measured from the recording made in memory from the episode's arrays
    (:func:`pipeline.log.whole.episode_recording`: what the bag reads back as), so an
    episode that does not keep its bag writes none; its old bag, if any, goes once the
    partial is written. A recording the reader would read in windows (very long), or one
    the measuring refuses, is written as a bag and measured from it as before (an
    unreadable bag stays a bag, whole, so done: nothing is lost).
    """
    from pipeline.log.bag import write_episode_bag

    def write() -> None:
        write_episode_bag(bag_dir, **recorded, force=force)

    if episode.partial_code is None:
        write()
        return
    from pipeline.log.streams import EpisodeStreams
    from pipeline.log.whole import episode_recording, reads_whole
    from pipeline.stages.campaign_run import keep_partial

    out_dir = bag_dir.parent
    streams = EpisodeStreams.of(**recorded)
    if not reads_whole(streams):
        write()
        with contextlib.suppress(PipelineError):
            keep_partial(out_dir, episode.name, measure_code=episode.partial_code)
            if episode.drop_bag:
                _remove(bag_dir)
        return
    if not episode.drop_bag:
        write()
    try:
        keep_partial(
            out_dir,
            episode.name,
            measure_code=episode.partial_code,
            recording=episode_recording(streams, bag_dir),
        )
    except Exception:  # the bag is the data: whatever failed, keep it
        if episode.drop_bag:
            write()  # the report measures it from the file
        return
    if episode.drop_bag and os.path.lexists(bag_dir):
        _remove(bag_dir)  # a stale bag of an earlier run: the partial stands for it


def _remove(path: Path) -> None:
    """Remove a bag folder (or a symlink standing for one, not what it points to)."""
    if path.is_symlink():
        path.unlink()
    else:
        shutil.rmtree(path)


def final_window(t_s: np.ndarray, *, motion_end_s: float) -> np.ndarray:
    """Which samples (times ``t_s`` [s] from the motion start) the error at the target is
    the mean over: the report's window (``in_final`` of
    :func:`pipeline.analysis.metrics.joint_metrics`), the last min(FINAL_WINDOW_S,
    hold / 2) with hold = end - motion end, so the record console and the report print
    the same number (tests/stages/test_record_report_agree.py)."""
    end_s = float(t_s[-1]) if t_s.size else 0.0
    window_s = min(FINAL_WINDOW_S, max(end_s - motion_end_s, 0.0) / 2)
    mask: np.ndarray = t_s >= end_s - window_s - FINAL_EDGE_S
    return mask


# Work folders of the bag writer (pipeline/log/bag.py: ``.<name>.partial-<pid>`` while
# writing, ``.<name>.old-<pid>`` while replacing with --force).
_STALE_BAG = re.compile(r"\..+\.(?:partial|old)-(?P<pid>\d+)")


def remove_work_folders(out_dir: Path, *, mine: bool = True) -> None:
    """Remove bag work folders of writers that are gone (and this process's own, if ``mine``)."""
    remove_stale(out_dir, _STALE_BAG, also_pids=frozenset({os.getpid()} if mine else ()))
