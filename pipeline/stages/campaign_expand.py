"""Campaigns: a sweep in ``params.yaml`` expanded into episodes with stable keys.

A campaign names a base scenario and crosses goals x swept values x controllers x
seeds. Every episode's key is built from its own values only
(``payload_kg-0.5.ctc.s3``), so adding a value to an axis never renames the other
episodes; random draws (values and goals) depend on (seed, axis, index) only, so
drawing more keeps the first ones. Expansion is pure and deterministic: same params,
same episodes, same order.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import re
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import ValidationError

from pipeline.errors import ParamsError, PipelineError, unknown_name_message
from pipeline.experiment.goals import resolve_goal
from pipeline.params import (
    CampaignParams,
    ControllerParams,
    Episode,
    Params,
    RandomAxis,
    RandomGoals,
    ScenarioParams,
    episode_scenario,
)
from pipeline.robots.dh_yaml import format_validation_error
from pipeline.settings import CampaignInfo

GOAL_AXIS = "goal"
MAX_GOAL_ATTEMPTS = 1000  # draws per random goal before giving up (region mostly blocked)
MAX_KEY_CHARS = 200  # a file name holds 255 bytes, with room for ".<key>.partial-<pid>"
KEY_DIGITS = 6  # significant digits of a drawn value in an episode key
_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]")


@dataclass(frozen=True)
class Axis:
    """One swept dimension other than controller and seed.

    Attributes:
        path: params path (``plant.payload_kg``, ``gains.omega_n_rad_s``) or ``goal``.
        label: short name in keys and conditions (the path's last part, unless ambiguous).
        values: the swept values (goal axis: each goal's key), JSON scalars.
        texts: each value as written into keys and conditions.
        drawn: the values are seeded random draws.
        goals: the goal axis's joint vectors [rad], one per value (empty otherwise).
    """

    path: str
    label: str
    values: tuple[float | str, ...]
    texts: tuple[str, ...]
    drawn: bool = False
    goals: tuple[tuple[float, ...], ...] = ()


@dataclass(frozen=True)
class Campaign:
    """A campaign's axes, before crossing them."""

    name: str
    scenario_name: str
    axes: tuple[Axis, ...]
    controllers: tuple[str, ...]
    seeds: tuple[int, ...]

    @property
    def size(self) -> int:
        """Number of episodes."""
        n = len(self.controllers) * len(self.seeds)
        for axis in self.axes:
            n *= len(axis.values)
        return n


def value_text(value: float, *, digits: int = 12) -> str:
    """A number as it appears in keys: ``30``, ``0.5``, ``1e-05`` (30.0 and 30 agree)."""
    return f"{float(value):.{digits}g}"


def _draws(axis: RandomAxis, path: str) -> list[float]:
    low, high = axis.uniform
    tag = zlib.crc32(path.encode())
    return [
        float(np.random.default_rng([axis.seed, tag, i]).uniform(low, high)) for i in range(axis.n)
    ]


def _labels(paths: Sequence[str]) -> dict[str, str]:
    last = [p.rsplit(".", 1)[-1] for p in paths]
    return {
        p: (short if last.count(short) == 1 else p.replace(".", "_"))
        for p, short in zip(paths, last, strict=True)
    }


def campaign_axes(params: Params, name: str) -> Campaign:
    """The axes of campaign ``name`` (random goals drawn here: needs the robot).

    Raises:
        ParamsError: unknown campaign, or goals that cannot be drawn or are invalid.
    """
    if name not in params.campaigns:
        raise ParamsError(
            unknown_name_message("campaign", name, params.campaigns, where=params.source)
        )
    c = params.campaigns[name]
    axes: list[Axis] = []
    if c.goals is not None:
        axes.append(_goal_axis(params, name, c))
    labels = _labels(list(c.sweep))
    for path, spec in c.sweep.items():
        if isinstance(spec, RandomAxis):
            values = _draws(spec, path)
            texts = tuple(value_text(v, digits=KEY_DIGITS) for v in values)
            if len(set(texts)) != len(texts):
                raise ParamsError(
                    f"{params.source}: {params.where(name)}.sweep.{path}: two draws agree to "
                    f"{KEY_DIGITS} digits; widen uniform or draw fewer"
                )
            axes.append(Axis(path, labels[path], tuple(values), texts, drawn=True))
        else:
            values = [float(v) for v in spec]
            axes.append(
                Axis(path, labels[path], tuple(values), tuple(value_text(v) for v in values))
            )
    return Campaign(name, c.scenario, tuple(axes), tuple(c.controllers), c.seed_list)


def _goal_axis(params: Params, name: str, c: CampaignParams) -> Axis:
    goals = c.goals
    if isinstance(goals, RandomGoals):
        vectors = draw_goals(params, c.scenario, goals, where=f"{params.where(name)}.goals")
        keys = [f"r{i}" for i in range(len(vectors))]
    elif isinstance(goals, Mapping):
        keys = list(goals)
        vectors = [tuple(float(x) for x in v) for v in goals.values()]
    else:
        assert goals is not None
        keys = [str(i) for i in range(len(goals))]
        vectors = [tuple(float(x) for x in v) for v in goals]
    for key in keys:
        if not key or _UNSAFE.search(key):
            raise ParamsError(
                f"{params.source}: {params.where(name)}.goals.{key}: goal names become part of "
                "directory names: use letters, digits, '-', '_' and '.' only"
            )
    return Axis(GOAL_AXIS, GOAL_AXIS, tuple(keys), tuple(keys), goals=tuple(vectors))


def draw_goals(
    params: Params, scenario_name: str, goals: RandomGoals, *, where: str
) -> list[tuple[float, ...]]:
    """Random joint goals around the scenario's goal: within the joint limits, clear of
    obstacles and self-collision by the planner's own standard (its start/goal check).

    Goal i depends on (seed, i) alone: asking for more goals keeps the first ones.
    """
    from pipeline.model.scene import Box
    from pipeline.planning.collision import CollisionChecker
    from pipeline.robots.loaders import load_spec

    scenario = params.scenarios[scenario_name]
    spec = load_spec(scenario.robot)
    start, base = resolve_goal(spec, scenario, name=scenario_name, source=params.source)
    obstacles = [Box(b.name, b.center, b.half_size) for b in scenario.obstacles]
    checker = CollisionChecker(spec, obstacles=obstacles)
    out: list[tuple[float, ...]] = []
    for i in range(goals.random):
        rng = np.random.default_rng([goals.seed, i])
        for _ in range(MAX_GOAL_ATTEMPTS):
            q = base + rng.uniform(-goals.radius_rad, goals.radius_rad, size=spec.dof)
            if not checker.within_limits(q):
                continue
            try:
                checker.check_state(q, "goal")
                checker.planning_padding_m(start, q)
            except PipelineError:
                continue
            out.append(tuple(float(x) for x in q))
            break
        else:
            raise ParamsError(
                f"{params.source}: {where}: goal r{i}: no reachable, collision-free goal "
                f"within {goals.radius_rad} rad of the scenario's goal in "
                f"{MAX_GOAL_ATTEMPTS} draws; change radius_rad or the obstacles"
            )
    return out


def _set(data: dict[str, Any], path: Sequence[str], value: Any) -> None:
    for part in path[:-1]:
        data = data.setdefault(part, {})
    data[path[-1]] = value


def _scenario_for(
    params: Params, campaign: Campaign, picks: Sequence[tuple[Axis, int]]
) -> ScenarioParams:
    # what the scenario gives, not its defaults: a key it leaves out keeps meaning "not
    # given" (the robot's own joint friction applies, experiment/assemble.py plant_friction)
    data = params.scenarios[campaign.scenario_name].model_dump(exclude_unset=True)
    for axis, i in picks:
        if axis.path == GOAL_AXIS:
            data["goal"] = {"joints": list(axis.goals[i]), "pose": None}
        elif not axis.path.startswith(("gains.", "controllers.")):
            _set(data, axis.path.split("."), axis.values[i])
    try:
        return ScenarioParams.model_validate(data)
    except ValidationError as err:
        values = ", ".join(f"{a.label}={a.texts[i]}" for a, i in picks)
        where = f"{params.where(campaign.name)} ({values}): scenario"
        raise ParamsError(format_validation_error(f"{params.source}: {where}", err)) from err


def _controller_for(
    params: Params, name: str, picks: Sequence[tuple[Axis, int]], *, robot: str
) -> ControllerParams:
    """The controller with the swept gains: ``gains.K`` for every controller,
    ``controllers.NAME.gains.K`` for one. Sweeping a tuning knob (``omega_n_rad_s``,
    ``zeta``) drops the explicit gains it derives, so the knob takes effect."""
    from pipeline.control.controller import TUNING_KEYS

    base = params.controllers[name]
    gains = dict(base.gains)
    for axis, i in picks:
        parts = axis.path.split(".")
        if parts[0] == "gains" or (parts[0] == "controllers" and parts[1] == name):
            key = parts[-1]
            if key in TUNING_KEYS:
                for derived in _tuned_keys(base.type, robot):
                    gains.pop(derived, None)
            gains[key] = axis.values[i]
    return ControllerParams(type=base.type, gains=gains, nominal=base.nominal, plant=base.plant)


@functools.cache
def _tuned_keys(controller_type: str, robot: str) -> tuple[str, ...]:
    """Gain keys a controller type derives from its tuning knobs (``kp``, ``kd``, ...)."""
    from pipeline.control.registry import controller_entry
    from pipeline.robots.loaders import load_spec

    try:
        entry = controller_entry(controller_type)
    except PipelineError:
        return ()  # validate_episodes names the unknown type
    return tuple(entry.default_gains(load_spec(robot), omega_n_rad_s=40.0, zeta=1.0))


def _own_plant(
    params: Params,
    name: str,
    scenario: ScenarioParams,
    ctrl: str,
    controller: ControllerParams,
    scenario_axes: Sequence[Axis],
) -> ScenarioParams:
    """The scenario ``ctrl``'s episodes run: with the controller's own ``plant:`` if any.

    Raises:
        ParamsError: the campaign sweeps the scenario's plant (the controller's own would
            silently not follow), or the controller's plant does not fit the scenario.
    """
    if controller.plant is None:
        return scenario
    swept = [a.path for a in scenario_axes if a.path.startswith("plant.")]
    if swept:
        raise ParamsError(
            f"{params.source}: {params.where(name)}: sweeps {swept[0]}, but controller "
            f"{ctrl} has its own plant (controllers.{ctrl}.plant), which the sweep would not "
            "change: sweep one or the other"
        )
    try:
        return episode_scenario(scenario, controller)
    except ValidationError as err:
        raise ParamsError(format_validation_error(params.source, err)) from err


def episode_key(picks: Sequence[tuple[Axis, int]], controller: str, seed: int) -> str:
    """``payload_kg-0.5.goal-r3.ctc.s3``: from the episode's own values only."""
    parts = [f"{axis.label}-{axis.texts[i]}" for axis, i in picks]
    return _UNSAFE.sub("_", ".".join([*parts, controller, f"s{seed}"]))


def expand(params: Params, name: str) -> tuple[Episode, ...]:
    """Every episode of campaign ``name``, in a deterministic order.

    Raises:
        ParamsError: unknown campaign, a swept value the scenario refuses (names it),
            too many episodes, or two episodes with one key.
    """
    campaign = campaign_axes(params, name)
    from pipeline.params import MAX_CAMPAIGN_EPISODES

    if campaign.size > MAX_CAMPAIGN_EPISODES:
        raise ParamsError(
            f"{params.source}: {params.where(name)}: {campaign.size:,} episodes, more than "
            f"{MAX_CAMPAIGN_EPISODES:,}; split it into several campaigns"
        )
    scenario_axes = [a for a in campaign.axes if not a.path.startswith(("gains.", "controllers."))]
    episodes: list[Episode] = []
    scenarios: dict[tuple[int, ...], ScenarioParams] = {}
    for combo in itertools.product(*(range(len(a.values)) for a in campaign.axes)):
        picks = list(zip(campaign.axes, combo, strict=True))
        skey = tuple(i for a, i in picks if a in scenario_axes)
        if skey not in scenarios:
            scenarios[skey] = _scenario_for(params, campaign, picks)
        swept_axes = {a.path: (a.values[i]) for a, i in picks}
        condition = ",".join(f"{a.label}={a.texts[i]}" for a, i in picks)
        for ctrl in campaign.controllers:
            controller = _controller_for(params, ctrl, picks, robot=scenarios[skey].robot)
            scenario = _own_plant(params, name, scenarios[skey], ctrl, controller, scenario_axes)
            for seed in campaign.seeds:
                key = episode_key(picks, ctrl, seed)
                episodes.append(
                    Episode(
                        name=key,
                        scenario_name=campaign.scenario_name,
                        scenario=scenario,
                        controller_name=ctrl,
                        controller=controller,
                        seed=seed,
                        sim=params.sim,
                        campaign=CampaignInfo(
                            name=name,
                            condition=condition,
                            swept={"controller": ctrl, "seed": seed, **swept_axes},
                        ),
                    )
                )
    seen: set[str] = set()
    for e in episodes:
        if len(e.name) > MAX_KEY_CHARS:
            raise ParamsError(
                f"{params.source}: {params.where(name)}: episode key '{e.name[:40]}...' is longer "
                f"than {MAX_KEY_CHARS} characters (a directory name); sweep fewer axes"
            )
        if e.name in seen:
            raise ParamsError(
                f"{params.source}: {params.where(name)}: two episodes share the key '{e.name}' "
                "(values that differ only in characters a directory name cannot hold?)"
            )
        seen.add(e.name)
    return tuple(episodes)


def episode_fingerprint(episode: Episode, *, commit: str) -> str:
    """Hash of everything an episode's recording depends on: its full settings as run
    and the recording code's version (``commit``). Equal fingerprints, equal bytes."""
    data = {
        "episode": episode.name,
        "scenario": {"name": episode.scenario_name, **episode.scenario.model_dump()},
        "controller": {"name": episode.controller_name, **episode.controller.model_dump()},
        "seed": episode.seed,
        "sim": episode.sim.model_dump(),
        "campaign": None
        if episode.campaign is None
        else {
            "name": episode.campaign.name,
            "condition": episode.campaign.condition,
            "swept": dict(episode.campaign.swept),
        },
        "commit": commit,
    }
    text = json.dumps(data, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()
