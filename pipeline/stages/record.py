"""The record stage: params -> plan per scenario -> episodes -> one ROS 2 bag each.

Glue over the pieces: :mod:`~pipeline.experiment.goals` (start and goal),
:mod:`~pipeline.stages.plans` (one plan per distinct plan input, shared by every
controller that tracks it), :mod:`~pipeline.stages.budget` (memory and time, before
any work), :mod:`~pipeline.stages.executors` (where the episodes run) and
:mod:`~pipeline.stages.episode` (one episode, one bag, written atomically). Nothing
here puts a wall-clock reading into a recording.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from pipeline.errors import ParamsError, PipelineError, SimulationError
from pipeline.experiment.goals import resolve_goal
from pipeline.fsutil import ensure_dir
from pipeline.params import Episode, Params
from pipeline.robots.loaders import load_spec
from pipeline.stages.budget import check_budget
from pipeline.stages.episode import EpisodeOutcome, remove_work_folders
from pipeline.stages.executors import make_executor
from pipeline.stages.executors.executor import interrupted
from pipeline.stages.plans import plan_all
from pipeline.stages.provenance import git_commit


def check_outputs_free(episodes: Sequence[Episode], out_dir: Path, *, force: bool) -> None:
    """Refuse up front (before any work) a bad --out or to overwrite a recording.

    Also removes what killed runs left in ``out_dir`` (hidden work folders whose process
    is gone).
    """
    ensure_dir(out_dir)
    remove_work_folders(out_dir, mine=False)
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
    import functools

    from pipeline.control import make_controller
    from pipeline.control.contain import is_builtin

    probed: set[tuple[str, ...]] = set()
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
        # a controller's own plant (controllers.NAME.plant) is named as such
        own = episode.controller.plant is not None
        plant_where = f"controllers.{episode.controller_name}" if own else where
        for key in ("damping", "frictionloss", "armature"):
            value = getattr(scenario.plant, key)
            if isinstance(value, list) and len(value) not in (1, spec.dof):
                raise ParamsError(
                    f"{params.source}: {plant_where}.plant.{key}: "
                    f"expected 1 or {spec.dof} values, got {len(value)}"
                )
        _check_loop(params, episode, where)
        _check_profile(params, spec, scenario, plant_where)
        _check_own_nominal(params, spec, episode)
        build = functools.partial(
            make_controller,
            episode.controller.type,
            spec,
            episode.controller.gains,
            source=f"{params.source}: controllers.{episode.controller_name}",
        )
        if is_builtin(episode.controller.type):
            build()
        else:
            probe_key = (episode.controller.type, repr(episode.controller.gains), spec.name,
                   episode.controller_name)  # fmt: skip
            if probe_key not in probed:
                probed.add(probe_key)
                try:
                    _probe_plugin(episode.controller.type, build)
                except ParamsError as err:  # an unknown name or bad gains: say where it is
                    where_type = f"{params.source}: controllers.{episode.controller_name}"
                    if str(err).startswith(params.source):
                        raise
                    raise ParamsError(f"{where_type}.type: {err}") from err


def _check_own_nominal(params: Params, spec: Any, episode: Episode) -> None:
    """A controller's own ``nominal:`` model file that is missing, unreadable or of another
    robot: refused before any work (one line naming the field)."""
    from pipeline.errors import IdentificationError
    from pipeline.identify.model_file import nominal_path, nominal_spec

    if episode.controller.nominal is None:
        return
    where = f"{params.source}: controllers.{episode.controller_name}"
    try:
        nominal_spec(spec, nominal_path(episode.controller.nominal, seed=episode.seed), where=where)
    except IdentificationError as err:
        text = str(err)
        raise ParamsError(text if text.startswith(where) else f"{where}.nominal: {text}") from err


def _check_profile(params: Params, spec: Any, scenario: Any, where: str) -> None:
    """A published plant profile that does not describe the robot, or a friction spread
    the plant's friction law lacks: refused before any work (one line)."""
    from pipeline.errors import ModelError
    from pipeline.experiment.assemble import draw_scenario_plant

    if not scenario.plant.profile and not scenario.plant.uncertainty.transition_rel:
        return
    try:
        draw_scenario_plant(spec, scenario, seed=0, where=f"{where}.plant.profile")
    except ModelError as err:
        message = str(err)
        if message.startswith("plant."):  # a draw's field: say whose
            message = f"{where}.{message}"
        raise ParamsError(f"{params.source}: {message}") from err


def _probe_plugin(name: str, build: Callable[[], object]) -> None:
    """Build a plug-in controller once in a forked child, contained: its settings errors
    (an unknown gain, a module that does not import) refuse the run here in one line; plug-in
    code that misbehaves (raises, exits, hangs, ``os._exit``) is left to fail its own
    episode in its worker, with the others going on. This process never runs plug-in code.
    """
    import multiprocessing as mp

    from pipeline.control.contain import Budget, PluginError, contained_controller

    def probe(conn: Any) -> None:
        message = ""
        try:
            with contained_controller(name, build):
                pass
        except PluginError:
            pass
        except PipelineError as err:
            message = str(err)
        except BaseException:
            pass
        with contextlib.suppress(Exception):
            conn.send(message)
        os._exit(0)  # no atexit handlers, no flushing of the parent's buffers

    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=probe, args=(send,), daemon=True)
    proc.start()
    send.close()
    budget = Budget.from_env()
    message = ""
    if recv.poll(2 * budget.call_s + 30.0):
        with contextlib.suppress(EOFError, OSError):
            message = recv.recv()
    recv.close()
    if proc.is_alive():
        proc.kill()
    proc.join()
    if message:
        raise ParamsError(message)


def _check_loop(params: Params, episode: Episode, where: str) -> None:
    """The scenario's loop against the physics step (a delay is whole physics steps)."""
    from pipeline.experiment.assemble import loop_settings
    from pipeline.sim.loop import check_loop

    try:
        check_loop(
            loop_settings(episode.scenario),
            physics_dt_s=episode.sim.physics_dt_s,
            velocity_noise_std_rad_s=episode.scenario.plant.velocity_noise_std_rad_s,
        )
    except SimulationError as err:
        raise ParamsError(f"{params.source}: {where}.{err}") from err


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


def missing_fact_lines(episodes: Sequence[Episode]) -> list[str]:
    """The warnings for the facts the episodes' robots do not state (armature, acceleration
    and velocity limits), one line per robot and field (:mod:`pipeline.robots.facts`)."""
    from pipeline.experiment.assemble import scenario_spec
    from pipeline.robots.facts import fact_warnings, missing_facts

    scenarios = {ep.scenario.robot: ep.scenario for ep in episodes}
    facts = tuple(f for sc in scenarios.values() for f in missing_facts(scenario_spec(sc)))
    return fact_warnings(facts)


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
    :mod:`pipeline.stages.executors.ray`). ``commit``: the recording code's version to
    record (default: :func:`git_commit`). The bytes do not depend on the executor.

    Raises:
        ParamsError: an episode would not fit in memory or time (before any runs).
        Interrupted: (:class:`pipeline.stages.executors.Interrupted`) Ctrl-C or SIGTERM;
            nothing half-written is left under a final name.
    """
    emit = on_event or (lambda kind, name, value: None)
    started_s = time.time()
    commit = commit if commit is not None else git_commit()
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
        run = make_executor(executor, jobs=jobs, address=address).run
        outcomes = run(episodes, plan_by_episode, out_dir=out_dir, force=force, commit=commit,
                       emit=emit)  # fmt: skip
    except KeyboardInterrupt as err:  # while planning (an executor reports its own)
        remove_work_folders(out_dir)
        raise interrupted(episodes, {}, out_dir, started_s=started_s, cause=err) from None
    return [outcomes[e.name] for e in episodes]
