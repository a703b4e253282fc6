"""``params.yaml``: scenarios, controllers and episodes, validated once at the edge.

An episode is scenario x controller x seed, keyed by a name (``paper-ctc``) that
is also its recording directory and its DVC stage (``record@paper-ctc``). Field
paths in errors match the YAML (``params.yaml: scenarios.paper.hold_s: ...``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from pipeline.constants import MAX_SEED
from pipeline.errors import ParamsError
from pipeline.robots.spec import format_validation_error
from pipeline.yamlio import parse_yaml

NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
PerJoint = NonNegative | list[NonNegative]  # one value for every joint, or one per joint
MAX_HOLD_S = 3600.0


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


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
    joints: list[float] | None = None
    pose: PoseGoal | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> Goal:
        if (self.joints is None) == (self.pose is None):
            raise ValueError("give exactly one of joints or pose")
        return self


class BoxParams(_Strict):
    name: str = Field(min_length=1)
    center: tuple[float, float, float]
    half_size: tuple[float, float, float]

    @model_validator(mode="after")
    def _positive(self) -> BoxParams:
        if min(self.half_size) <= 0:
            raise ValueError(f"half_size must be > 0 on every axis, got {list(self.half_size)}")
        return self


class PlannerParams(_Strict):
    time_limit_s: float = Field(default=5.0, gt=0)
    simplify: bool = True
    seed: int = Field(default=0, ge=0, le=MAX_SEED)


class TimingParams(_Strict):
    velocity_scaling: float = Field(default=1.0, gt=0, le=1)
    acceleration_scaling: float = Field(default=1.0, gt=0, le=1)


RelativeSpread = Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)]
MAX_PREROLL_S = 60.0


class UncertaintyParams(_Strict):
    """Link-parameter and armature uncertainty: the plant draws its values per episode seed."""

    mass_rel: RelativeSpread = 0.0  # link mass x U[1 - r, 1 + r]
    com_m: float = Field(default=0.0, ge=0, le=0.5, allow_inf_nan=False)  # per axis U[-r, r]
    inertia_rel: RelativeSpread = 0.0  # second moments scaled per axis by U[1 - r, 1 + r]
    armature_rel: RelativeSpread = 0.0  # rotor armature x U[1 - r, 1 + r]


class PlantParams(_Strict):
    """How the simulated plant differs from the nominal model (zero = identical)."""

    damping: PerJoint = 0.0
    frictionloss: PerJoint = 0.0
    armature: PerJoint = 0.0  # added to the robot's own armature (the plant's only)
    uncertainty: UncertaintyParams = UncertaintyParams()
    payload_kg: float = Field(default=0.0, ge=0)
    position_noise_std_rad: float = Field(default=0.0, ge=0)
    velocity_noise_std_rad_s: float = Field(default=0.0, ge=0)


class ScenarioParams(_Strict):
    robot: str = Field(min_length=1)
    start: list[float]
    goal: Goal
    obstacles: list[BoxParams] = []
    planner: PlannerParams = PlannerParams()
    timing: TimingParams = TimingParams()
    plant: PlantParams = PlantParams()
    hold_s: float = Field(default=1.0, ge=0, le=MAX_HOLD_S)
    # the controller holds the start pose this long before the motion (settled start)
    preroll_s: float = Field(default=2.0, ge=0, le=MAX_PREROLL_S)
    # compare with the paper's numbers in the report (only the paper's experiment)
    reproduces_paper: bool = False


class ControllerParams(_Strict):
    type: str = Field(min_length=1)
    # numbers, per-joint lists or flags (antiwindup): the controller validates each key
    gains: dict[str, Any] = {}


class EpisodeParams(_Strict):
    scenario: str
    controller: str
    seed: int = Field(default=0, ge=0)


class SimParams(_Strict):
    physics_dt_s: float = Field(default=0.001, gt=0, le=0.01)
    control_period_steps: int = Field(default=1, ge=1)
    joint_state_decimation: int = Field(default=1, ge=1)
    tf_rate_hz: float = Field(default=50.0, gt=0)
    # Whose message definitions and metadata layout the bags use (Humble subscribers need
    # control_msgs 4.x's JointTrajectoryControllerState, Jazzy ones 5.3's).
    ros_distro: Literal["jazzy", "humble"] = "jazzy"


class _Params(_Strict):
    sim: SimParams = SimParams()
    scenarios: dict[str, ScenarioParams] = Field(min_length=1)
    controllers: dict[str, ControllerParams] = Field(min_length=1)
    episodes: dict[str, EpisodeParams] = Field(min_length=1)

    @model_validator(mode="after")
    def _references(self) -> _Params:
        for name, ep in self.episodes.items():
            if not _NAME.fullmatch(name):
                raise ValueError(
                    f"episodes.{name}: episode names are directory names: use letters, "
                    "digits, '-', '_' and '.' only"
                )
            if ep.scenario not in self.scenarios:
                raise ValueError(
                    f"episodes.{name}.scenario: unknown scenario '{ep.scenario}' "
                    f"(defined: {', '.join(sorted(self.scenarios))})"
                )
            if ep.controller not in self.controllers:
                raise ValueError(
                    f"episodes.{name}.controller: unknown controller '{ep.controller}' "
                    f"(defined: {', '.join(sorted(self.controllers))})"
                )
        return self


_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


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


@dataclass(frozen=True)
class Params:
    """Validated ``params.yaml``."""

    source: str
    sim: SimParams
    scenarios: Mapping[str, ScenarioParams]
    controllers: Mapping[str, ControllerParams]
    episodes: tuple[Episode, ...] = field(default_factory=tuple)

    def select(self, only: list[str] | None) -> tuple[Episode, ...]:
        """Episodes named in ``only`` (all when empty); unknown names are an error."""
        if not only:
            return self.episodes
        only = list(dict.fromkeys(only))  # --only X --only X runs X once
        known = {e.name: e for e in self.episodes}
        missing = [n for n in only if n not in known]
        if missing:
            raise ParamsError(
                f"{self.source}: unknown episode '{missing[0]}' (episodes: {', '.join(known)})"
            )
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
    episodes = tuple(
        Episode(
            name=name,
            scenario_name=e.scenario,
            scenario=raw.scenarios[e.scenario],
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
    return parse_params(parse_yaml(text, source=str(p), error=ParamsError), source=str(p))
