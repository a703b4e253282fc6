# long: every group a bag records, its validation and the version check, in one place
"""What a recording's settings hold: the typed contract between the recorder and the report.

The recorder builds an :class:`EpisodeSettings` and writes ``to_dict()`` as JSON into
the MCAP metadata record (and ``metadata.yaml``); the report parses it back with
:meth:`EpisodeSettings.from_dict`, and test fixtures build recordings through the same
classes, so a fixture cannot carry keys production never writes.

Validation is declared once, in the field types: each field's type says what it accepts
(``NonNegative``, ``Names``, ..., declared in :mod:`pipeline.contract`), pydantic walks the
frozen dataclasses with those rules, and ``from_dict`` raises :class:`SettingsError`
naming the field path (``planner.trajectory_duration_s: expected a finite number >= 0,
got -1``). Every field must be present (defaults serve the recorder, not old bags);
unknown keys are ignored.

Times are from the recording's first sample: the motion starts at
``protocol.motion_start_s`` (after the pre-roll) and ends
``planner.trajectory_duration_s`` later.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from typing import Annotated, Any, ClassVar, Literal, NoReturn, Self

from pydantic import PlainValidator
from pydantic_core import CoreSchema, core_schema

from pipeline.contract import (
    Contract,
    Count,
    CountFromOne,
    Finite,
    Flag,
    MaybeFlag,
    Names,
    NonNegative,
    NonNegatives,
    Numbers,
    Plain,
    Positive,
    Text,
    expected_error,
    guard,
    is_mapping,
    is_scalar,
    knob,
    listed,
    omit_added,
    plain,
    rule,
    stated_error,
)
from pipeline.contract import SettingsError as SettingsError
from pipeline.errors import SpecError
from pipeline.knobs import LEGACY_FRICTION as LEGACY_FRICTION
from pipeline.knobs import VELOCITY_SOURCES as VELOCITY_SOURCES
from pipeline.knobs import CampaignInfo as CampaignInfo
from pipeline.knobs import LinkInertial as LinkInertial
from pipeline.knobs import LoopSettings as LoopSettings
from pipeline.knobs import PlantSettings as PlantSettings
from pipeline.knobs import SigmoidFrictionSettings as SigmoidFrictionSettings
from pipeline.knobs import Uncertainty as Uncertainty
from pipeline.knobs import VelocitySource as VelocitySource
from pipeline.params import RecordedScenario
from pipeline.robots.recorded import robot_from_dict, robot_to_dict
from pipeline.robots.spec import RobotSpec

SETTINGS_VERSION = 2


ContactKind = Literal["obstacle", "floor", "self"]
KINDS: tuple[ContactKind, ...] = ("obstacle", "floor", "self")

Kind = Annotated[ContactKind, rule(f"one of {', '.join(KINDS)}", lambda v: v in KINDS)]


def _status(value: Any) -> str:
    if not isinstance(value, str):
        raise expected_error("a string")
    if value not in ("ok", "diverged"):
        raise expected_error("'ok' or 'diverged'")
    return value


Status = Annotated[str, PlainValidator(_status)]


def _robot(value: Any) -> RobotSpec:
    if isinstance(value, RobotSpec):
        return value
    try:
        return robot_from_dict(value)
    except SpecError as err:
        raise stated_error(str(err)) from err


Robot = Annotated[RobotSpec, PlainValidator(_robot)]
"""The robot by value (:mod:`pipeline.robots.recorded`): written by ``robot_to_dict``."""
Version = Annotated[
    int, rule(f"settings version {SETTINGS_VERSION}", lambda v: v == SETTINGS_VERSION, int)
]


@dataclass(frozen=True, kw_only=True)
class PlannerSettings(Contract):
    """The planned path and its timing (what the planner and TOPP-RA produced).

    The report's planner line lists the shown fields in this order (the path's shape,
    ``direct`` .. ``simplify``, in words when recorded)."""

    _where = "planner"

    planner: Text
    time_limit_s: Positive
    path_length_rad: NonNegative
    trajectory_duration_s: NonNegative
    velocity_scaling: Positive
    acceleration_scaling: Positive
    check_step_rad: NonNegative
    direct: Flag
    interpolation: Text
    n_states_before_simplify: Count
    n_waypoints: CountFromOne
    padding_m: NonNegative
    seed: Count
    simplify: Flag
    start: Numbers = knob(shown=False, description="the joint-space start it planned from")
    goal: Numbers = knob(shown=False, description="the joint-space goal it planned to")


def plant_as_recorded(
    plant: dict[str, Any], cls: type[PlantSettings] = PlantSettings
) -> dict[str, Any]:
    """A plant's plain data (of ``cls``) as recorded: the fields declared ``added``
    (issue 28's) left out while at their default, so plants without them record the
    same settings as before (absent reads back as the default)."""
    omit_added(Uncertainty, plant["uncertainty"])
    return omit_added(cls, plant)


@dataclass(frozen=True)
class ProtocolSettings(Contract):
    """How the episode was run (the fair-comparison protocol).

    Attributes:
        motion_start_s: when the motion starts, from the recording's first sample [s]: the
            pre-roll before it holds the start pose under the episode's own controller,
            until settled (``pipeline.sim.settling``) or for the scenario's ``preroll_s``.
        hold_s: time kept at the goal after the motion ends [s].
        start_abs_error_rad: |reference - true position| per joint at the motion start.
        start_effort_nm: applied effort per joint at the motion start [N m].
        reproduces_paper: the scenario is the paper's experiment (the report compares it
            with the paper's numbers only then).
        preroll_settled: the pre-roll ended settled, before its cap (``preroll_s``);
            False: the motion started from an unsettled state (a finding in the report).
            Absent in bags written before the settled pre-roll (a fixed pre-roll): True.
        hold_settled: the hold's last window is settled (``pipeline.sim.settling``, the
            same criterion), so the error at the target is a steady state; False: it
            is "not settled" (the hold reached ``hold_max_s``, or ``hold_s`` without
            one). None: not recorded (bags written before the criterion).
    """

    _where = "protocol"
    _may_be_absent = frozenset({"preroll_settled", "hold_settled"})

    motion_start_s: NonNegative
    hold_s: NonNegative
    start_abs_error_rad: NonNegatives
    start_effort_nm: Numbers
    reproduces_paper: Flag = False
    preroll_settled: Flag = True
    hold_settled: MaybeFlag = None


DESIGN_MODES = ("path", "start", "given", "zero")
DesignMode = Annotated[str, rule(f"one of {', '.join(DESIGN_MODES)}", lambda v: v in DESIGN_MODES)]


@dataclass(frozen=True)
class GainDesign(Contract):
    """Where the default gains were designed (``gains.design_at``, docs/control.md).

    Attributes:
        at: ``path`` (per joint the largest nominal inertia along the planned motion),
            ``start`` (the planned motion's first configuration), ``given`` (``q_rad``)
            or ``zero`` (no planned motion: q = 0 clipped into the joint limits).
        inertia_kg_m2: the nominal inertia diagonal the default gains were scaled by.
        q_rad: the given configuration (``at: given``), else empty.
    """

    _where = "controller.design"

    at: DesignMode
    inertia_kg_m2: NonNegatives
    q_rad: Numbers = ()

    @classmethod
    def split_from(cls, gains: Mapping[str, Any]) -> tuple[GainDesign | None, dict[str, Any]]:
        """The design recorded in a controller's ``gains_in_effect()`` (its ``design_at``
        and ``design_inertia_kg_m2``), and the gains without them."""
        rest = {k: v for k, v in gains.items() if k not in ("design_at", "design_inertia_kg_m2")}
        at = gains.get("design_at")
        if at is None:
            return None, rest
        given = not isinstance(at, str)
        design = cls.from_dict(
            {
                "at": "given" if given else at,
                "inertia_kg_m2": gains.get("design_inertia_kg_m2", []),
                "q_rad": list(at) if given else [],
            }
        )
        return design, rest


def _is_json(value: Any) -> bool:
    if isinstance(value, Mapping):
        return all(isinstance(k, str) and _is_json(v) for k, v in value.items())
    if isinstance(value, list | tuple):
        return all(_is_json(v) for v in value)
    if isinstance(value, float):
        return math.isfinite(value)
    return is_scalar(value)


def _per_joint(value: Any) -> bool:
    return isinstance(value, list | tuple) and all(
        not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v) for v in value
    )


class Gains(dict[str, Any]):
    """Every gain a controller ran with, in the order recorded (``gains_in_effect()``
    less its design keys), read only.

    The per-joint gains the built-in laws share are typed (``kp``, ``kd``, ``ki``: one
    number per joint, None when the law has none or records it otherwise); every gain,
    a plug-in's included, is also there by name as recorded (JSON values: numbers,
    flags, text, lists, mappings). A ``dict`` (read only), so it is written as one.
    """

    PER_JOINT: ClassVar[tuple[str, ...]] = ("kp", "kd", "ki")

    def __init__(self, values: Mapping[str, Any] | Iterable[tuple[str, Any]] = ()) -> None:
        """Raises:
        SettingsError: a gain that is not a JSON value (names it)."""
        items = dict(values)
        for key, value in items.items():
            if not isinstance(key, str) or not _is_json(value):
                raise SettingsError(f"controller.gains.{key}: expected a JSON value, got {value!r}")
        super().__init__(plain(items))

    @classmethod
    def __get_pydantic_core_schema__(cls, source: Any, handler: Any) -> CoreSchema:
        def check(value: Any) -> Gains:
            if isinstance(value, Gains):
                return value
            if not isinstance(value, Mapping):
                raise expected_error("a mapping")
            bad = next((k for k, v in value.items() if not _is_json(v)), None)
            if bad is not None:
                raise expected_error(f"JSON gain values ({bad}: {value[bad]!r})")
            return cls(value)

        return core_schema.no_info_plain_validator_function(check)

    def _typed(self, key: str) -> tuple[float, ...] | None:
        value: Any = self.get(key)
        return tuple(float(v) for v in value) if _per_joint(value) else None

    @property
    def kp(self) -> tuple[float, ...] | None:
        """Proportional gain per joint (its unit is the law's: ``stiffness_gains``)."""
        return self._typed("kp")

    @property
    def kd(self) -> tuple[float, ...] | None:
        """Derivative gain per joint."""
        return self._typed("kd")

    @property
    def ki(self) -> tuple[float, ...] | None:
        """Integral gain per joint."""
        return self._typed("ki")

    def _read_only(self, *args: Any, **kwargs: Any) -> NoReturn:
        raise TypeError("recorded gains are read only")

    __setitem__ = __delitem__ = _read_only
    clear = pop = popitem = setdefault = update = _read_only
    __ior__ = _read_only

    def __reduce__(self) -> tuple[type[Gains], tuple[dict[str, Any]]]:
        return (Gains, (dict(self),))  # pickled and copied whole (report workers)

    def __repr__(self) -> str:
        return f"Gains({super().__repr__()})"


@dataclass(frozen=True)
class NominalModelSettings(Contract):
    """A controller's own nominal model file (params ``controllers.NAME.nominal``): the
    path it was read from (``{seed}`` filled in) and the file's SHA-256."""

    _where = "controller.nominal"

    file: Text
    sha256: Text


@dataclass(frozen=True)
class ControllerSettings(Contract):
    """The controller as run: its params name, registry type, every gain in effect, where
    its code came from (``origin``: ``pipeline.control.controller_origin``), where its
    default gains were designed (``design``; None when they do not depend on it) and its
    own nominal model (``nominal``; None: its scenario's, recorded there) and its own plant
    (``plant``: params ``controllers.NAME.plant`` as given; None: its scenario's. Either
    way ``scenario.plant`` records the plant the episode ran on)."""

    _where = "controller"
    # bags written before issue 18: built-in; before issue 28: designed at q = 0, and no
    # controller had a nominal model of its own (left out while None: the same bytes)
    _may_be_absent = frozenset({"origin", "design", "nominal", "plant"})

    name: Text
    type: Text
    gains: Gains
    origin: Plain = field(default_factory=lambda: {"kind": "builtin"})
    design: GainDesign | None = None
    nominal: NominalModelSettings | None = None
    plant: Plain | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.gains, Gains):  # a plain mapping (the recorder's dict)
            object.__setattr__(self, "gains", Gains(self.gains))


@dataclass(frozen=True)
class ContactSpan(Contract):
    """One pair that penetrated during the episode.

    Attributes:
        bodies: (robot link, world geom: an obstacle's name, ``ground`` or
            ``pedestal``), or two robot links, sorted.
        kind: ``obstacle``, ``self`` (link vs link) or ``floor`` (ground or pedestal).
        first_ns, last_ns: first and last checked sample in penetration [ns].
        samples: checked samples in penetration (not necessarily contiguous).
        max_depth_m: deepest penetration [m] (> 0).
        deepest_ns: when it was deepest [ns].
    """

    _where = "safety.contacts[0]"

    bodies: Names
    kind: Kind
    first_ns: Count
    last_ns: Count
    samples: CountFromOne
    max_depth_m: NonNegative
    deepest_ns: Count

    def summary(self) -> str:
        """E.g. ``touched box by 0.7 mm at t=1.234-2.111 s (878 samples): forearm_link–box``."""
        what = "itself" if self.kind == "self" else self.bodies[1]
        return (
            f"touched {what} by {self.max_depth_m * 1e3:.1f} mm at "
            f"t={self.first_ns * 1e-9:.3f}-{self.last_ns * 1e-9:.3f} s ({self.samples} "
            f"samples): {self.bodies[0]}–{self.bodies[1]}"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        out: dict[str, Any] = plain(asdict(self))
        return out


@dataclass(frozen=True)
class Clearance(Contract):
    """The closest approach of one kind of pair during the episode.

    Attributes:
        kind: ``obstacle``, ``self`` or ``floor``.
        bodies: the closest pair, ordered as in ``ContactSpan``.
        distance_m: its signed distance [m] (negative: penetration depth).
        stamp_ns: when [ns].
    """

    _where = "safety.clearances[0]"

    kind: Kind
    bodies: Names
    distance_m: Finite
    stamp_ns: Count

    def summary(self) -> str:
        """E.g. ``obstacle 11.2 mm (wrist_2_link–blocker at t=0.007 s)``."""
        a, b = self.bodies
        t_s = self.stamp_ns * 1e-9
        return f"{self.kind} {self.distance_m * 1e3:.1f} mm ({a}–{b} at t={t_s:.3f} s)"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        out: dict[str, Any] = plain(asdict(self))
        return out


@dataclass(frozen=True)
class ExecutionSafety(Contract):
    """Contacts and clearance over an episode's true states.

    Attributes:
        padding_m: distances below this were measured; farther pairs were not [m].
        every: every how many rows of the episode were checked.
        samples_checked: rows checked.
        skip_within_m: rows were skipped only when provably within this of a checked
            row in every distance (0: all checked; see ``assess_execution``) [m].
        clearances: per kind of pair that came within ``padding_m`` (obstacle,
            floor, self, in that order), its closest approach.
        contacts: every pair that penetrated, by first contact time.
    """

    _where = "safety"
    _may_be_absent = frozenset({"skip_within_m"})  # bags written before it existed

    padding_m: NonNegative
    every: CountFromOne
    samples_checked: Count
    clearances: Annotated[tuple[Clearance, ...], listed("a list", tuples=False)]
    contacts: Annotated[tuple[ContactSpan, ...], listed("a list", tuples=False)]
    skip_within_m: NonNegative = 0.0

    @property
    def touched(self) -> bool:
        """Did anything penetrate?"""
        return bool(self.contacts)

    @property
    def min_clearance_m(self) -> float:
        """Smallest signed distance over every pair [m], negative after a penetration;
        ``padding_m`` (a lower bound) when nothing came closer."""
        return min((c.distance_m for c in self.clearances), default=self.padding_m)

    def summary(self) -> str:
        """One line for people: each contact, or the clearances when there was none."""
        if self.contacts:
            return "; ".join(c.summary() for c in self.contacts)
        beyond = f">= {self.padding_m * 1e3:.1f} mm"
        if not self.clearances:
            return f"no contact; clearance {beyond}"
        shown = ", ".join(c.summary() for c in self.clearances)
        return f"no contact; min clearance {shown}; anything else {beyond}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (for a recording's settings); ``touched``, ``min_clearance_m``
        and ``summary`` are derived, for readers of the JSON alone (``from_dict`` ignores
        them)."""
        return {
            "padding_m": self.padding_m,
            "every": self.every,
            "samples_checked": self.samples_checked,
            "skip_within_m": self.skip_within_m,
            "touched": self.touched,
            "min_clearance_m": self.min_clearance_m,
            "clearances": [c.to_dict() for c in self.clearances],
            "contacts": [c.to_dict() for c in self.contacts],
            "summary": self.summary(),
        }


@dataclass(frozen=True)
class EpisodeSettings(Contract):
    """Everything a recording says about how it was made (its ``settings`` JSON).

    Attributes:
        episode: the episode key (the recording's name).
        robot: the robot by value (:mod:`pipeline.robots.recorded`: a DH robot in its
            YAML form, radians; any other with every spec field).
        scenario: the scenario's params as given, with its ``name``
            (:class:`pipeline.params.RecordedScenario`).
        controller: the controller as run.
        plant: the plant as simulated.
        planner: the planned path and timing.
        protocol: pre-roll, hold and the state at the motion start.
        safety: contacts and clearance during execution.
        seed: the episode seed (sensor noise, drawn plant parameters).
        status: "ok" or "diverged"; reason: why it diverged ("" if ok).
        mujoco_warnings: MuJoCo warning counters (non-zero only).
        package_version, git_commit: provenance.
        campaign: the campaign and condition the episode belongs to (None: hand-listed).
        loop: delay, jitter, encoder and velocity estimate between plant and controller
            (bags written before it existed: the ideal loop they ran).
        version: settings layout version.
    """

    _where = ""
    _may_be_absent = frozenset({"loop"})  # bags written before issue 18: the ideal loop

    episode: Text
    robot: Robot
    scenario: RecordedScenario
    controller: ControllerSettings
    plant: PlantSettings
    planner: PlannerSettings
    protocol: ProtocolSettings
    safety: ExecutionSafety
    seed: Count
    status: Status
    reason: Text
    package_version: Text
    git_commit: Text
    mujoco_warnings: Annotated[Mapping[str, Count], guard("a mapping", is_mapping)] = field(
        default_factory=dict
    )
    campaign: CampaignInfo | None = None
    loop: LoopSettings = field(default_factory=LoopSettings)
    version: Version = SETTINGS_VERSION

    def __post_init__(self) -> None:
        if isinstance(self.scenario, Mapping):  # plain data (a test fixture's scenario)
            object.__setattr__(self, "scenario", RecordedScenario.model_validate(self.scenario))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready plain data (lists, not tuples). The robot, the scenario and the
        safety are serialised once, each in its own form."""
        own: dict[str, Callable[[], Any]] = {
            "robot": lambda: robot_to_dict(self.robot),  # by value (pipeline.robots.recorded)
            "scenario": self.scenario.recorded,
            "safety": self.safety.to_dict,  # with its derived keys, for readers of the JSON
        }
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in own:
                out[f.name] = own[f.name]()
            else:
                out[f.name] = plain(
                    asdict(value) if is_dataclass(value) and not isinstance(value, type) else value
                )
        out["plant"] = plant_as_recorded(out["plant"])
        for override in ("nominal", "plant"):  # the scenario's: as before they existed
            if out["controller"].get(override) is None:
                out["controller"].pop(override, None)
        return out

    @classmethod
    def from_dict(cls, data: Any, path: str | None = None) -> Self:
        """Validate plain data (parsed JSON) into settings; another layout version is
        named as such before any of its fields.

        Raises:
            SettingsError: a missing or ill-typed field, a value out of range (names it).
        """
        version = data.get("version") if isinstance(data, Mapping) else SETTINGS_VERSION
        if version != SETTINGS_VERSION:
            raise SettingsError(
                f"version: expected settings version {SETTINGS_VERSION}, got {version!r}"
            )
        return super().from_dict(data, path)

    @property
    def motion_end_from_first_sample_s(self) -> float:
        """When the reference stops, from the recording's first sample [s]: the pre-roll
        plus the trajectory's duration (not the duration alone)."""
        return self.protocol.motion_start_s + self.planner.trajectory_duration_s


def per_joint(values: Sequence[float], n: int) -> tuple[float, ...]:
    """Expand one value (or ``n`` values) to one per joint."""
    vals = tuple(float(v) for v in values)
    if len(vals) == 1:
        return vals * n
    if len(vals) != n:
        raise ValueError(f"expected 1 or {n} values, got {len(vals)}")
    return vals
