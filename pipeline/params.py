# long: every params knob at one edge: pydantic models, cross-field checks, file-relative paths
"""``params.yaml``: scenarios, controllers and episodes, validated once at the edge.

An episode is scenario x controller x seed, keyed by a name (``paper-ctc``) that
is also its recording directory and its DVC stage (``record@paper-ctc``). Field
paths in errors match the YAML (``params.yaml: scenarios.paper.hold_s: ...``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import re
import typing
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, cast

from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    GetCoreSchemaHandler,
    SerializerFunctionWrapHandler,
    Tag,
    ValidationError,
    create_model,
    model_serializer,
    model_validator,
)
from pydantic_core import CoreSchema, core_schema

from pipeline.constants import MAX_SEED
from pipeline.contract import added_defaults, given_fields, meta_of, omit_added, plain
from pipeline.errors import ParamsError, unknown_name_message
from pipeline.knobs import MAX_LOOP_DELAY_S as MAX_LOOP_DELAY_S
from pipeline.knobs import CampaignInfo, LoopSettings, PlantSettings, Uncertainty
from pipeline.robots.dh_yaml import format_validation_error
from pipeline.robots.spec import Name
from pipeline.yamlio import parse_yaml, refuse_bool_numbers

NonNegative = Annotated[float, Field(ge=0, le=1e6, allow_inf_nan=False)]
PerJoint = NonNegative | list[NonNegative]  # one value for every joint, or one per joint
MAX_HOLD_S = 3600.0
MIN_PHYSICS_DT_S = 1e-5  # 100 kHz: finer than any arm simulation needs
MAX_CONTROL_PERIOD_S = 0.1  # 10 Hz: slower is not joint-level control
MAX_WORLD_M = 100.0  # obstacles: centres and sizes, a robot cell is metres wide
MIN_BOX_M = 1e-4
MAX_GAIN = 1e9  # |gain| above this is a typo: no actuator realises it
MAX_EPISODE_CHARS = 100  # keys become file names (with a .partial-<pid> prefix, < 255 bytes)
_RESERVED_GEOMS = ("ground", "pedestal")  # the plant's own geoms (pipeline/model/mjcf.py)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _no_bool_numbers(cls, data: Any) -> Any:
        refuse_bool_numbers(cls.model_fields, data)  # `hold_s: true` is not 1.0 s
        return data


def _knob_fields(cls: type, only: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Pydantic field definitions of a settings dataclass's fields (or of ``only``): each
    with its plain type, its default and the range its ``knob`` declares."""
    hints = typing.get_type_hints(cls, include_extras=True)
    fields_: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if only is not None and f.name not in only:
            continue
        hint = hints[f.name]
        plain_type = typing.get_args(hint)[0] if typing.get_origin(hint) is Annotated else hint
        declared: dict[str, Any] = {"default": f.default, **meta_of(f).bounds}
        fields_[f.name] = (plain_type, Field(**declared))
    return fields_


@functools.cache
def params_model(cls: type) -> type[BaseModel]:
    """The params form of a shared settings dataclass (:mod:`pipeline.knobs`): each field
    with its plain type, its default and the range its ``knob`` declares, unknown keys
    refused, as every params model."""
    fields_ = _knob_fields(cls)
    return cast(type[BaseModel], create_model(f"{cls.__name__}Params", __base__=_Strict, **fields_))


def _dump_knobs(value: Any) -> dict[str, Any]:
    """A shared settings dataclass as params dump it: issue 28's draws left out while
    unused (the same dumps, so the same campaign fingerprints, as before them)."""
    return omit_added(type(value), plain(dataclasses.asdict(value)))


class AsParams:
    """``Annotated[LoopSettings, AsParams()]``: a params field holding a shared settings
    dataclass, validated by :func:`params_model` (pydantic's errors and field paths, as
    every params field) and kept as the dataclass itself (dumped as its fields)."""

    def __get_pydantic_core_schema__(
        self, source: type, handler: GetCoreSchemaHandler
    ) -> CoreSchema:
        model = params_model(source)

        def validate(value: Any, inner: core_schema.ValidatorFunctionWrapHandler) -> Any:
            if isinstance(value, source):  # already the dataclass (validated when made)
                return value
            return source(**dict(inner(value)))

        return core_schema.no_info_wrap_validator_function(
            validate,
            handler.generate_schema(model),
            serialization=core_schema.plain_serializer_function_ser_schema(_dump_knobs),
        )


class PoseGoal(_Strict):
    """A Cartesian flange goal, turned into joints by IK (solution nearest the start)."""

    position: tuple[float, float, float]
    quaternion_wxyz: tuple[float, float, float, float] | None = None
    rpy: tuple[float, float, float] | None = None
    solver: str = "analytic"

    @model_validator(mode="after")
    def _one_orientation(self) -> PoseGoal:
        if (self.quaternion_wxyz is None) == (self.rpy is None):
            raise ValueError("give exactly one of quaternion_wxyz or rpy")
        return self


class Goal(_Strict):
    """Joint positions, a flange pose, or the name of one of the robot's SRDF named states
    (``goal: ready`` is short for ``goal: {state: ready}``)."""

    joints: list[float] | None = None
    pose: PoseGoal | None = None
    state: str | None = Field(default=None, min_length=1)

    @model_validator(mode="before")
    @classmethod
    def _named(cls, data: Any) -> Any:
        return {"state": data} if isinstance(data, str) else data

    @model_validator(mode="after")
    def _one_kind(self) -> Goal:
        if sum(v is not None for v in (self.joints, self.pose, self.state)) != 1:
            raise ValueError("give exactly one of joints or pose, or a named state (goal: ready)")
        return self


Metres = Annotated[float, Field(ge=-MAX_WORLD_M, le=MAX_WORLD_M)]


class BoxParams(_Strict):
    name: Name
    center: tuple[Metres, Metres, Metres]
    half_size: tuple[Metres, Metres, Metres]

    @model_validator(mode="after")
    def _positive(self) -> BoxParams:
        if min(self.half_size) < MIN_BOX_M:
            raise ValueError(
                f"half_size must be >= {MIN_BOX_M:g} m on every axis, got {list(self.half_size)}"
            )
        return self


class PlannerParams(_Strict):
    time_limit_s: float = Field(default=5.0, ge=0.001, le=600)
    simplify: bool = True
    seed: int = Field(default=0, ge=0, le=MAX_SEED)


class TimingParams(_Strict):
    velocity_scaling: float = Field(default=1.0, ge=0.001, le=1)
    acceleration_scaling: float = Field(default=1.0, ge=0.001, le=1)


MAX_PREROLL_S = 60.0


def _omit_defaults(out: dict[str, Any], defaults: Mapping[str, Any]) -> dict[str, Any]:
    """``out`` without the keys of ``defaults`` that hold their default: fields added after
    recordings were made dump as before while unused (same settings bytes, same campaign
    fingerprints)."""
    return {k: v for k, v in out.items() if k not in defaults or v != defaults[k]}


_NEW_PLANT = {"profile": None, "effort_offset_nm": 0.0}  # and the `added` given fields


class _PlantParamsOwn(_Strict):
    """How the simulated plant differs from the nominal model (zero = identical): the
    fields params expand or draw before they are recorded. The ones recorded as given
    come from :class:`pipeline.knobs.PlantSettings` (``knob(..., given=True)``)."""

    damping: PerJoint = 0.0
    frictionloss: PerJoint = 0.0
    armature: PerJoint = 0.0  # added to the robot's own armature (the plant's only)
    uncertainty: Annotated[Uncertainty, AsParams()] = Uncertainty()
    payload_kg: float = Field(default=0.0, ge=0, le=1000)
    # a published plant (pipeline/model/published.py): its link parameters and friction
    # replace the robot's on the plant only (the controllers keep their nominal model)
    profile: Literal["gaz-panda"] | None = None
    # the joint torque sensor (what is recorded as effort): an offset per joint drawn
    # U[-r, r] per episode seed [N m]
    effort_offset_nm: float = Field(default=0.0, ge=0, le=1000)

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        added = added_defaults(PlantSettings)
        given = [f.name for f in given_fields(PlantSettings)]
        unused = {**_NEW_PLANT, **{k: added[k] for k in given if k in added}}
        return _omit_defaults(handler(self), unused)


def with_given(name: str, base: type[_Strict], settings: type) -> type[BaseModel]:
    """``base`` plus the fields of ``settings`` declared ``knob(..., given=True)``, as
    :func:`params_model` makes them (a new given field cannot be forgotten here)."""
    given = _knob_fields(settings, tuple(f.name for f in given_fields(settings)))
    model = create_model(name, __base__=base, __module__=__name__, __doc__=base.__doc__, **given)
    return cast(type[BaseModel], model)


if TYPE_CHECKING:

    class PlantParams(_PlantParamsOwn):
        """How the simulated plant differs from the nominal model (zero = identical)."""

        def __getattr__(self, name: str) -> Any: ...  # the given fields (knobs.PlantSettings)

else:
    PlantParams = with_given("PlantParams", _PlantParamsOwn, PlantSettings)


class ScenarioParams(_Strict):
    robot: str = Field(min_length=1)
    start: list[float] | Annotated[str, Field(min_length=1)]  # joints, or a named state
    goal: Goal
    obstacles: list[BoxParams] = []
    planner: PlannerParams = PlannerParams()
    timing: TimingParams = TimingParams()
    plant: PlantParams = PlantParams()
    loop: Annotated[LoopSettings, AsParams()] = LoopSettings()
    hold_s: float = Field(default=1.0, ge=0, le=MAX_HOLD_S)
    # the longest the controller holds the start pose before the motion: the pre-roll ends
    # once settled (pipeline.sim.settling); an episode still unsettled here is flagged
    preroll_s: float = Field(default=2.0, ge=0, le=MAX_PREROLL_S)
    # the longest the goal is held: after hold_s the hold goes on until settled (the error
    # at the target is then a steady state, or flagged "not settled"); None: hold_s exactly
    hold_max_s: float | None = Field(default=None, ge=0, le=MAX_HOLD_S)
    # compare with the paper's numbers in the report (only the paper's experiment)
    reproduces_paper: bool = False
    # the controllers' nominal model: an identified MODEL.yaml (`pipeline identify fit`);
    # None: the robot's own description (its CAD values); `{seed}` in the path is the
    # episode's seed (each drawn plant identified on its own: models/ur5-s{seed}.yaml)
    nominal: str | None = Field(default=None, min_length=1)
    # the robot's rotor armature x this, on the plant and the (CAD) nominal model together:
    # an assumption a campaign sweeps (an identified `nominal:` keeps its own armature)
    armature_scale: float = Field(default=1.0, gt=0, le=100, allow_inf_nan=False)

    @model_validator(mode="after")
    def _unique_obstacles(self) -> ScenarioParams:
        names = [b.name for b in self.obstacles]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"obstacles: duplicate obstacle name(s) {', '.join(dup)}")
        reserved = sorted(set(names) & set(_RESERVED_GEOMS))
        if reserved:
            raise ValueError(
                f"obstacles: name '{reserved[0]}' is reserved for the plant's own geometry"
            )
        if self.loop.velocity == "encoder" and self.plant.velocity_noise_std_rad_s > 0:
            raise ValueError(
                "loop.velocity: 'encoder' differentiates the measured position, so "
                f"plant.velocity_noise_std_rad_s ({self.plant.velocity_noise_std_rad_s:g}) "
                "would not be used: set it to 0"
            )
        return self


class RecordedScenario(ScenarioParams):
    """A scenario as an episode records it (``settings.scenario``): its params as given
    and its name. Read back from a bag, keys this version does not know are ignored."""

    model_config = ConfigDict(extra="ignore")

    name: str

    @classmethod
    def of(cls, name: str, scenario: ScenarioParams) -> RecordedScenario:
        return cls(name=name, **{k: getattr(scenario, k) for k in ScenarioParams.model_fields})

    def recorded(self) -> dict[str, Any]:
        """The JSON form: ``name`` first, then the params as ``model_dump`` gives them."""
        data = self.model_dump(mode="json")
        return {"name": data.pop("name"), **data}


class ControllerParams(_Strict):
    type: str = Field(min_length=1)
    # numbers, per-joint lists or flags (antiwindup): the controller validates each key
    gains: dict[str, Any] = {}
    # this controller's nominal model, overriding its scenario's `nominal:` (an identified
    # MODEL.yaml; `{seed}` as there): the same law on two models compared in one scenario
    nominal: str | None = Field(default=None, min_length=1)
    # this controller's plant, replacing its scenario's `plant:` for its episodes only (same
    # form): the same law on two plants compared in one scenario, paired by seed
    plant: PlantParams | None = None

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        # unused, left out: the same dumps (campaign fingerprints) as before they existed
        return _omit_defaults(handler(self), {"nominal": None, "plant": None})

    @model_validator(mode="after")
    def _finite_gains(self) -> ControllerParams:
        if "planned_path_rad" in self.gains:
            raise ValueError(
                "gains.planned_path_rad: set from the planned motion, not in params "
                "(choose the design configuration with gains.design_at)"
            )
        for key, value in self.gains.items():
            for v in value if isinstance(value, list) else [value]:
                if isinstance(v, bool) or not isinstance(v, int | float):
                    continue  # flags and the rest: the controller validates them
                # magnitude first: math.isfinite(10**400) overflows
                if not (abs(v) <= MAX_GAIN and math.isfinite(v)):
                    raise ValueError(
                        f"gains.{key}: {v!r} is not a finite gain of magnitude <= {MAX_GAIN:g}"
                    )
        return self


def episode_scenario(scenario: ScenarioParams, controller: ControllerParams) -> ScenarioParams:
    """The scenario an episode of ``controller`` runs: ``scenario`` itself, or with the
    controller's own ``plant:`` in place of the scenario's (validated as a scenario).

    Raises:
        ValueError: the controller's plant does not fit the scenario (its loop).
    """
    if controller.plant is None:
        return scenario
    given = {k: getattr(scenario, k) for k in scenario.model_fields_set}
    return ScenarioParams.model_validate({**given, "plant": controller.plant})


def unpaired_plant(
    episodes: Mapping[str, EpisodeParams], controllers: Mapping[str, ControllerParams]
) -> str | None:
    """A hand-listed comparison of plants that shares no seed: the first controller with
    its own ``plant:`` whose episodes in a scenario have no seed in common with those of
    the scenario's other controllers, as a message (None: every such group pairs)."""
    seeds: dict[str, dict[str, set[int]]] = {}
    for e in episodes.values():
        seeds.setdefault(e.scenario, {}).setdefault(e.controller, set()).add(e.seed)
    for scenario, by_controller in seeds.items():
        for name, own in by_controller.items():
            others = {c: s for c, s in by_controller.items() if c != name}
            if controllers[name].plant is None or not others:
                continue
            if not any(own & s for s in others.values()):
                return (
                    f"controllers.{name}.plant: its episodes of scenario {scenario} share no "
                    f"seed with {', '.join(sorted(others))} (seeds {sorted(own)} vs "
                    f"{sorted(set().union(*others.values()))}): a comparison of plants is "
                    "paired by seed"
                )
    return None


class EpisodeParams(_Strict):
    scenario: str
    controller: str
    seed: int = Field(default=0, ge=0)


MAX_CAMPAIGN_EPISODES = 1_000_000  # expansion holds every episode in memory (~1 kB each)
EXTRA_CAMPAIGNS = "extra_campaigns"  # the params section of campaigns outside `make demo`
EXTRA_RECORDINGS_DIR = "extra"  # where `pipeline record --campaign` puts them by default


class RandomAxis(_Strict):
    """``n`` seeded uniform draws in ``uniform: [low, high]``; draw i depends on (seed, i) only."""

    uniform: tuple[float, float]
    n: int = Field(ge=1, le=MAX_CAMPAIGN_EPISODES)
    seed: int = Field(default=0, ge=0, le=MAX_SEED)

    @model_validator(mode="after")
    def _ordered(self) -> RandomAxis:
        if self.uniform[0] > self.uniform[1]:
            raise ValueError(
                f"uniform: expected [low, high] with low <= high, got {list(self.uniform)}"
            )
        return self


class RandomGoals(_Strict):
    """``random`` joint goals drawn uniformly within ``radius_rad`` of the scenario's goal,
    each inside the joint limits and collision-free (redrawn until it is)."""

    random: int = Field(ge=1, le=100_000)
    seed: int = Field(default=0, ge=0, le=MAX_SEED)
    radius_rad: float = Field(gt=0, le=6.3)


class KeepBags(_Strict):
    """Which episodes of a campaign keep their full bag: every ``every``-th one (in the
    campaign's order, the first included). The others keep their metric partials and
    settings (``<campaign>/.partials/<key>.arrow``); re-running one by its key reproduces
    its bag byte for byte."""

    every: int = Field(ge=1)


SweepValue = Annotated[float, Field(allow_inf_nan=False)]
# a list of values, or a mapping of random draws: errors come from the branch the input is
Sweep = Annotated[
    Annotated[list[SweepValue], Tag("list")] | Annotated[RandomAxis, Tag("draws")],
    Discriminator(lambda v: "list" if isinstance(v, list) else "draws"),
]


class CampaignParams(_Strict):
    """A sweep: every combination of goals x sweep values x controllers x seeds."""

    scenario: str
    controllers: list[str] = Field(min_length=1)
    seeds: (
        Annotated[int, Field(ge=1, le=MAX_CAMPAIGN_EPISODES)]
        | list[Annotated[int, Field(ge=0, le=MAX_SEED)]]
    ) = 1
    # params path -> values (one value for every joint where the field is per joint)
    sweep: dict[str, Sweep] = {}
    goals: list[list[float]] | dict[str, list[float]] | RandomGoals | None = None
    keep_bags: KeepBags | None = None  # None: every episode keeps its bag

    def problem(self) -> str:
        """What is wrong beyond types ("" if fine), as ``field: message``."""
        lists: tuple[tuple[str, list[Any]], ...] = (
            ("controllers", list(self.controllers)),
            ("seeds", self.seeds if isinstance(self.seeds, list) else []),
        )
        for what, items in lists:
            dup = sorted({str(x) for x, n in Counter(items).items() if n > 1})
            if dup:
                return f"{what}: listed twice: {', '.join(dup)}"
        for path, values in self.sweep.items():
            if isinstance(values, list):
                if not values:
                    return f"sweep.{path}: give at least one value"
                keys = [float(v) for v in values]
                if len(set(keys)) != len(keys):
                    return f"sweep.{path}: a value is listed twice"
        if isinstance(self.goals, list | dict) and not self.goals:
            return "goals: give at least one goal (or leave goals out)"
        return ""

    @property
    def seed_list(self) -> tuple[int, ...]:
        """The seeds: ``seeds: N`` is 0..N-1."""
        return tuple(range(self.seeds)) if isinstance(self.seeds, int) else tuple(self.seeds)


class SimParams(_Strict):
    # Ranges a manipulator experiment can use; beyond them a value is a typo that would
    # exhaust the machine (1e-9 s steps, 1e9 Hz /tf), not a setting. What an in-range
    # episode costs is estimated before it runs (pipeline.stages.budget.estimate_episode).
    physics_dt_s: float = Field(default=0.001, ge=MIN_PHYSICS_DT_S, le=0.01)
    control_period_steps: int = Field(default=1, ge=1, le=1000)
    # MuJoCo's integrator (RK4 by default: the convergence test in tests/sim/test_convergence.py)
    integrator: Literal["RK4", "Euler", "implicit", "implicitfast"] = (
        "RK4"  # = PLANT_INTEGRATOR (a test keeps them equal)
    )
    joint_state_decimation: int = Field(default=1, ge=1, le=1000)
    tf_rate_hz: float = Field(default=50.0, gt=0, le=1000)
    # Whose message definitions and metadata layout the bags use (Humble subscribers need
    # control_msgs 4.x's JointTrajectoryControllerState, Jazzy ones 5.3's).
    ros_distro: Literal["jazzy", "humble"] = "jazzy"

    @model_validator(mode="after")
    def _rates(self) -> SimParams:
        control_period_s = self.physics_dt_s * self.control_period_steps
        if control_period_s > MAX_CONTROL_PERIOD_S:
            raise ValueError(
                f"control period physics_dt_s x control_period_steps = {control_period_s:g} s "
                f"exceeds {MAX_CONTROL_PERIOD_S:g} s (a control rate below "
                f"{1 / MAX_CONTROL_PERIOD_S:g} Hz): lower control_period_steps"
            )
        if self.tf_rate_hz > 1.0 / control_period_s * (1 + 1e-9):
            raise ValueError(
                f"tf_rate_hz ({self.tf_rate_hz:g}) exceeds the control rate "
                f"({1 / control_period_s:g} Hz) it is sampled from"
            )
        return self


class _Params(_Strict):
    sim: SimParams = SimParams()
    scenarios: dict[str, ScenarioParams] = Field(min_length=1)
    controllers: dict[str, ControllerParams] = Field(min_length=1)
    episodes: dict[str, EpisodeParams] = {}
    campaigns: dict[str, CampaignParams] = {}
    # campaigns outside the DVC stage graph (dvc.yaml's foreach reads `campaigns` only)
    extra_campaigns: dict[str, CampaignParams] = {}

    @model_validator(mode="after")
    def _campaign_references(self) -> _Params:
        if not self.episodes and not self.campaigns and not self.extra_campaigns:
            raise ValueError("episodes: give at least one episode or campaign")
        sections = (("campaigns", self.campaigns), (EXTRA_CAMPAIGNS, self.extra_campaigns))
        for section, name, c in ((s, n, c) for s, cs in sections for n, c in cs.items()):
            where = f"{section}.{name}"
            if not _NAME.fullmatch(name):
                raise ValueError(
                    f"{where}: campaign names are directory names: use letters, digits, "
                    "'-', '_' and '.' only"
                )
            if name in self.episodes:
                raise ValueError(f"{where}: also an episode name (both would be {name}/)")
            if section == EXTRA_CAMPAIGNS and name in self.campaigns:
                raise ValueError(f"{where}: also in campaigns (one name, one campaign)")
            if c.problem():
                raise ValueError(f"{where}.{c.problem()}")
            if c.scenario not in self.scenarios:
                raise ValueError(
                    unknown_name_message(
                        "scenario", c.scenario, sorted(self.scenarios), where=f"{where}.scenario"
                    )
                )
            for i, ctrl in enumerate(c.controllers):
                if ctrl not in self.controllers:
                    raise ValueError(
                        unknown_name_message(
                            "controller",
                            ctrl,
                            sorted(self.controllers),
                            where=f"{where}.controllers[{i}]",
                        )
                    )
            for path in c.sweep:
                problem = sweep_path_problem(path, self.controllers)
                if problem:
                    raise ValueError(f"{where}.sweep.{path}: {problem}")
        return self

    @model_validator(mode="after")
    def _references(self) -> _Params:
        for name, ep in self.episodes.items():
            if not _NAME.fullmatch(name) or len(name) > MAX_EPISODE_CHARS:
                shown = name if len(name) <= 40 else name[:37] + "..."
                raise ValueError(
                    f"episodes.{shown}: episode names are directory names: use letters, "
                    f"digits, '-', '_' and '.' only, at most {MAX_EPISODE_CHARS} characters"
                )
            if ep.scenario not in self.scenarios:
                raise ValueError(
                    unknown_name_message(
                        "scenario",
                        ep.scenario,
                        sorted(self.scenarios),
                        where=f"episodes.{name}.scenario",
                    )
                )
            if ep.controller not in self.controllers:
                raise ValueError(
                    unknown_name_message(
                        "controller",
                        ep.controller,
                        sorted(self.controllers),
                        where=f"episodes.{name}.controller",
                    )
                )
        return self


_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")
# scenario fields a sweep may not set: goals have their own axis, the rest is the scenario
_NOT_SWEPT = ("robot", "start", "goal", "obstacles", "reproduces_paper", "nominal")


def sweep_path_problem(path: str, controllers: Mapping[str, ControllerParams]) -> str:
    """What is wrong with a sweep path ("" if fine).

    Valid: ``gains.<key>`` (every controller of the campaign), ``controllers.<name>.gains.<key>``
    (one controller) and a numeric scenario field such as ``plant.payload_kg``,
    ``plant.uncertainty.mass_rel``, ``hold_s`` or ``timing.velocity_scaling``.
    """
    parts = path.split(".")
    if parts[0] == "gains":
        return "" if len(parts) == 2 and parts[1] else "expected gains.<key>"
    if parts[0] == "controllers":
        if len(parts) != 4 or parts[2] != "gains" or not parts[3]:
            return "expected controllers.<name>.gains.<key>"
        if parts[1] not in controllers:
            return unknown_name_message("controller", parts[1], sorted(controllers))
        return ""
    model: type[BaseModel] = ScenarioParams
    for i, part in enumerate(parts):
        fields_ = model.model_fields
        if part not in fields_ or (i == 0 and part in _NOT_SWEPT):
            valid = [f for f in fields_ if not (i == 0 and f in _NOT_SWEPT)]
            where = ".".join(parts[:i]) or "a scenario"
            extra = "; or gains.<key>, controllers.<name>.gains.<key>" if i == 0 else ""
            return f"'{part}' is not a field of {where} (valid: {', '.join(valid)}{extra})"
        annotation = fields_[part].annotation
        if isinstance(annotation, type) and dataclasses.is_dataclass(annotation):
            annotation = params_model(annotation)  # a shared settings dataclass (knobs)
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            model = annotation
            if i == len(parts) - 1:
                return (
                    f"{path} is a group; sweep one of its fields ({', '.join(model.model_fields)})"
                )
        elif i < len(parts) - 1:
            return f"{'.'.join(parts[: i + 1])} is a value, not a group"
    return ""


@dataclass(frozen=True)
class Episode:
    """One episode to run, with everything it reads from params."""

    name: str
    scenario_name: str
    scenario: ScenarioParams
    controller_name: str
    controller: ControllerParams
    seed: int
    sim: SimParams
    campaign: CampaignInfo | None = None  # None: hand-listed
    # ``keep_bags`` campaigns: the worker measures the bag into its metric partial with
    # this measuring-code commit (None: no partial), and removes the bag if ``drop_bag``.
    # Where the bytes go, not what they are: not in the fingerprint.
    partial_code: str | None = None
    drop_bag: bool = False


@dataclass(frozen=True)
class Params:
    """Validated ``params.yaml``."""

    source: str
    sim: SimParams
    scenarios: Mapping[str, ScenarioParams]
    controllers: Mapping[str, ControllerParams]
    episodes: tuple[Episode, ...] = field(default_factory=tuple)
    # every campaign: the DVC stages' (``campaigns:``) first, then ``extra_campaigns:``
    campaigns: Mapping[str, CampaignParams] = field(default_factory=dict)
    extra_campaigns: frozenset[str] = frozenset()  # names of those outside the stage graph

    def where(self, campaign: str) -> str:
        """The campaign's field path in the params file (``campaigns.NAME`` or
        ``extra_campaigns.NAME``)."""
        section = EXTRA_CAMPAIGNS if campaign in self.extra_campaigns else "campaigns"
        return f"{section}.{campaign}"

    def select(self, only: list[str] | None) -> tuple[Episode, ...]:
        """Episodes named in ``only`` (all when empty); unknown names are an error."""
        if not only:
            return self.episodes
        only = list(dict.fromkeys(only))  # --only X --only X runs X once
        known = {e.name: e for e in self.episodes}
        missing = [n for n in only if n not in known]
        if missing:
            raise ParamsError(unknown_name_message("episode", missing[0], known, where=self.source))
        return tuple(known[n] for n in only)

    def with_ros_distro(self, ros_distro: Literal["jazzy", "humble"]) -> Params:
        """These params with ``sim.ros_distro`` replaced (the CLI's --ros-distro)."""
        sim = self.sim.model_copy(update={"ros_distro": ros_distro})
        episodes = tuple(replace(e, sim=sim) for e in self.episodes)
        return replace(self, sim=sim, episodes=episodes)


def parse_params(data: Any, *, source: str) -> Params:
    """Validate parsed YAML into :class:`Params`."""
    if not isinstance(data, dict):
        raise ParamsError(f"{source}: expected a mapping with scenarios, controllers, episodes")
    try:
        raw = _Params.model_validate(data)
    except ValidationError as err:
        raise ParamsError(format_validation_error(source, err)) from err
    unpaired = unpaired_plant(raw.episodes, raw.controllers)
    if unpaired:
        raise ParamsError(f"{source}: {unpaired}")
    try:
        scenarios = {
            (e.scenario, e.controller): episode_scenario(
                raw.scenarios[e.scenario], raw.controllers[e.controller]
            )
            for e in raw.episodes.values()
        }
    except ValidationError as err:
        raise ParamsError(format_validation_error(source, err)) from err
    episodes = tuple(
        Episode(
            name=name,
            scenario_name=e.scenario,
            scenario=scenarios[e.scenario, e.controller],
            controller_name=e.controller,
            controller=raw.controllers[e.controller],
            seed=e.seed,
            sim=raw.sim,
        )
        for name, e in raw.episodes.items()
    )
    return Params(
        source=source,
        sim=raw.sim,
        scenarios=raw.scenarios,
        controllers=raw.controllers,
        episodes=episodes,
        campaigns={**raw.campaigns, **raw.extra_campaigns},
        extra_campaigns=frozenset(raw.extra_campaigns),
    )


def load_params(path: str | Path) -> Params:
    """Read and validate a params file.

    Raises:
        ParamsError: missing file, bad YAML, or invalid content (names the field).
    """
    p = Path(path)
    if p.is_dir():
        raise ParamsError(f"{p}: is a directory, expected a params YAML file")
    if not p.is_file():
        raise ParamsError(f"{p}: no such params file (pass --params PATH)")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise ParamsError(f"{p}: cannot read params file ({err})") from err
    data = parse_yaml(text, source=str(p), error=ParamsError)
    return parse_params(_paths_from(data, folder=p.parent, source=str(p)), source=str(p))


def _paths_from(data: Any, *, folder: Path, source: str) -> Any:
    """``data`` with each scenario's relative ``robot`` and ``nominal`` file paths read from
    the params file's ``folder`` (as written relative to the working directory, so a params
    file run from its own folder records the same text as before).

    Raises:
        ParamsError: a ``robot`` path names no file (the field, the path as given and the
            folder it was read from).
    """
    from pipeline.robots.loaders import loader_suffix

    if not isinstance(data, dict):
        return data
    here = Path.cwd().resolve()
    data = _controller_paths_from(data, folder=folder, here=here)
    scenarios = data.get("scenarios")
    if not isinstance(scenarios, dict):
        return data
    moved: dict[Any, Any] = {}
    for name, scenario in scenarios.items():
        if not isinstance(scenario, dict):
            moved[name] = scenario
            continue
        scenario = dict(scenario)  # a YAML alias shares its mapping with the anchor
        for key in ("robot", "nominal"):
            value = scenario.get(key)
            if not isinstance(value, str) or not value:
                continue
            path = Path(value).expanduser()
            is_path = "/" in value or "\\" in value or loader_suffix(path) is not None
            if not is_path:
                continue  # a built-in robot's name
            if not path.is_absolute() and folder.resolve() != here:
                path = Path(os.path.relpath(folder.resolve() / path, here))
                scenario[key] = str(path)
            if key == "robot" and not path.is_file():
                raise ParamsError(
                    f"{source}: scenarios.{name}.robot: no such robot file {value!r} "
                    f"(a relative path is read from the params file's folder, {folder})"
                )
        moved[name] = scenario
    return {**data, "scenarios": moved}


def _relative_to(value: str, *, folder: Path, here: Path) -> str:
    """A path as written in a params file in ``folder``, as seen from ``here``."""
    path = Path(value).expanduser()
    if path.is_absolute() or folder.resolve() == here:
        return value
    return str(Path(os.path.relpath(folder.resolve() / path, here)))


def _controller_paths_from(data: dict[str, Any], *, folder: Path, here: Path) -> dict[str, Any]:
    """``data`` with each controller's relative ``nominal`` model path read from the
    params file's ``folder`` (as a scenario's ``nominal``)."""
    controllers = data.get("controllers")
    if not isinstance(controllers, dict):
        return data
    moved: dict[Any, Any] = {}
    for name, controller in controllers.items():
        value = controller.get("nominal") if isinstance(controller, dict) else None
        if isinstance(value, str) and value:
            controller = {**controller, "nominal": _relative_to(value, folder=folder, here=here)}
        moved[name] = controller
    return {**data, "controllers": moved}


SEED_FIELD = "{seed}"
"""In a scenario's ``nominal:`` path, the episode's seed: each drawn plant's own model."""


def nominal_path(path: str | None, *, seed: int) -> str | None:
    """A `nominal:` path (a scenario's or a controller's) for the episode of `seed`."""
    return None if path is None else path.replace(SEED_FIELD, str(seed))
