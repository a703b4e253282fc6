"""What a recording's settings hold: the typed contract between the recorder and the report.

The recorder builds an :class:`EpisodeSettings` and writes ``to_dict()`` as JSON into
the MCAP metadata record (and ``metadata.yaml``); the report parses it back with
:meth:`EpisodeSettings.from_dict`, and test fixtures build recordings through the same
classes, so a fixture cannot carry keys production never writes. ``from_dict``
validates types and ranges and raises :class:`SettingsError` naming the field path
(``planner.trajectory_duration_s: expected a finite number >= 0, got -1``).

Times are from the recording's first sample: the motion starts at
``protocol.motion_start_s`` (after the pre-roll) and ends
``planner.trajectory_duration_s`` later.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Literal, TypeVar

from pipeline.constants import PLANT_FRICTION, PLANT_INTEGRATOR
from pipeline.errors import RecordingError

SETTINGS_VERSION = 2


class SettingsError(RecordingError):
    """A recording's settings do not follow the contract (names the field path)."""


T = TypeVar("T")


def _fail(path: str, expected: str, value: Any) -> SettingsError:
    return SettingsError(f"{path}: expected {expected}, got {value!r}")


def _number(value: Any, path: str, *, minimum: float | None = None, strict: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise _fail(path, "a finite number", value)
    if minimum is not None and (value <= minimum if strict else value < minimum):
        raise _fail(path, f"a finite number {'>' if strict else '>='} {minimum:g}", value)
    return float(value)


def _int(value: Any, path: str, *, minimum: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise _fail(path, f"an integer >= {minimum}", value)
    return int(value)


def _str(value: Any, path: str) -> str:
    if not isinstance(value, str):
        raise _fail(path, "a string", value)
    return value


def _bool(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise _fail(path, "true or false", value)
    return value


def _vector(value: Any, path: str, *, minimum: float | None = None) -> tuple[float, ...]:
    if not isinstance(value, list | tuple):
        raise _fail(path, "a list of numbers", value)
    return tuple(_number(v, f"{path}[{i}]", minimum=minimum) for i, v in enumerate(value))


def _mapping(value: Any, path: str) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise _fail(path, "a mapping", value)
    return dict(value)


def _plain(value: Any) -> Any:
    """JSON-ready: tuples to lists, recursively."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _check_keys(data: Mapping[str, Any], cls: type, path: str) -> None:
    names = {f.name for f in fields(cls)}
    missing = [n for n in names if n not in data]
    if missing:
        where = f"{path}." if path else ""
        raise SettingsError(f"{where}{sorted(missing)[0]}: missing (required by the contract)")


@dataclass(frozen=True)
class PlannerSettings:
    """The planned path and its timing (what the planner and TOPP-RA produced)."""

    planner: str
    seed: int
    time_limit_s: float
    simplify: bool
    direct: bool
    n_waypoints: int
    n_states_before_simplify: int
    path_length_rad: float
    padding_m: float
    check_step_rad: float
    interpolation: str
    trajectory_duration_s: float
    velocity_scaling: float
    acceleration_scaling: float
    start: tuple[float, ...]
    goal: tuple[float, ...]

    @classmethod
    def from_dict(cls, data: Any, path: str = "planner") -> PlannerSettings:
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        return cls(
            planner=_str(d["planner"], f"{path}.planner"),
            seed=_int(d["seed"], f"{path}.seed"),
            time_limit_s=_number(d["time_limit_s"], f"{path}.time_limit_s", minimum=0, strict=True),
            simplify=_bool(d["simplify"], f"{path}.simplify"),
            direct=_bool(d["direct"], f"{path}.direct"),
            n_waypoints=_int(d["n_waypoints"], f"{path}.n_waypoints", minimum=1),
            n_states_before_simplify=_int(
                d["n_states_before_simplify"], f"{path}.n_states_before_simplify"
            ),
            path_length_rad=_number(d["path_length_rad"], f"{path}.path_length_rad", minimum=0),
            padding_m=_number(d["padding_m"], f"{path}.padding_m", minimum=0),
            check_step_rad=_number(d["check_step_rad"], f"{path}.check_step_rad", minimum=0),
            interpolation=_str(d["interpolation"], f"{path}.interpolation"),
            trajectory_duration_s=_number(
                d["trajectory_duration_s"], f"{path}.trajectory_duration_s", minimum=0
            ),
            velocity_scaling=_number(
                d["velocity_scaling"], f"{path}.velocity_scaling", minimum=0, strict=True
            ),
            acceleration_scaling=_number(
                d["acceleration_scaling"], f"{path}.acceleration_scaling", minimum=0, strict=True
            ),
            start=_vector(d["start"], f"{path}.start"),
            goal=_vector(d["goal"], f"{path}.goal"),
        )


@dataclass(frozen=True)
class LinkInertial:
    """One link's rigid-body inertia as the plant has it (DH frame of its joint).

    Attributes:
        mass: [kg]. com: centre of mass [m].
        inertia: [ixx, iyy, izz, ixy, ixz, iyz] about the centre of mass [kg m^2].
    """

    mass: float
    com: tuple[float, float, float]
    inertia: tuple[float, float, float, float, float, float]

    @classmethod
    def from_dict(cls, data: Any, path: str) -> LinkInertial:
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        com = _vector(d["com"], f"{path}.com")
        inertia = _vector(d["inertia"], f"{path}.inertia")
        if len(com) != 3:
            raise _fail(f"{path}.com", "3 numbers", d["com"])
        if len(inertia) != 6:
            raise _fail(f"{path}.inertia", "6 numbers (ixx iyy izz ixy ixz iyz)", d["inertia"])
        return cls(
            mass=_number(d["mass"], f"{path}.mass", minimum=0, strict=True),
            com=(com[0], com[1], com[2]),
            inertia=(inertia[0], inertia[1], inertia[2], inertia[3], inertia[4], inertia[5]),
        )


@dataclass(frozen=True)
class Uncertainty:
    """How far the plant may differ from the nominal model (uniform draws per episode seed).

    Attributes:
        mass_rel: link mass factor in ``[1 - r, 1 + r]``.
        com_m: centre-of-mass offset per axis in ``[-r, r]`` [m].
        inertia_rel: per-axis scale of the link's second moments in ``[1 - r, 1 + r]``
            (keeps the tensor physical: positive definite, triangle inequality).
        armature_rel: rotor armature factor in ``[1 - r, 1 + r]``.
    """

    mass_rel: float = 0.0
    com_m: float = 0.0
    inertia_rel: float = 0.0
    armature_rel: float = 0.0

    @property
    def any(self) -> bool:
        return any(v > 0 for v in (self.mass_rel, self.com_m, self.inertia_rel, self.armature_rel))

    @classmethod
    def from_dict(cls, data: Any, path: str) -> Uncertainty:
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        return cls(
            **{f.name: _number(d[f.name], f"{path}.{f.name}", minimum=0) for f in fields(cls)}
        )


@dataclass(frozen=True)
class PlantSettings:
    """The simulated plant, exactly enough to rebuild it (with the robot's geometry).

    Attributes:
        exact: the nominal model is the plant (no mismatch of any kind, no noise): the
            controllers' model-based terms are exact by construction.
        links: the plant's link inertials (drawn from ``uncertainty`` or the nominal ones).
        armature: the plant's rotor armature per joint [kg m^2] (nominal + mismatch).
        nominal_armature: the nominal model's armature per joint [kg m^2].
        damping, frictionloss: per joint [N m s/rad], [N m] (the nominal model has none).
        payload_kg: point mass at the flange the nominal model does not know [kg].
        position_noise_std_rad, velocity_noise_std_rad_s: sensor noise (std).
        uncertainty: the spread the links and armature were drawn from.
        physics_dt_s, control_period_s: MuJoCo step and control period [s].
        integrator, engine: MuJoCo's integrator, "mujoco".
        friction_model: the joint friction law the plant ran (``frictionloss`` and ``damping``).
    """

    exact: bool
    links: tuple[LinkInertial, ...]
    armature: tuple[float, ...]
    nominal_armature: tuple[float, ...]
    damping: tuple[float, ...]
    frictionloss: tuple[float, ...]
    payload_kg: float
    position_noise_std_rad: float
    velocity_noise_std_rad_s: float
    uncertainty: Uncertainty
    physics_dt_s: float
    control_period_s: float
    integrator: str = PLANT_INTEGRATOR
    engine: str = "mujoco"
    friction_model: str = PLANT_FRICTION

    @classmethod
    def from_dict(cls, data: Any, path: str = "plant") -> PlantSettings:
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        links = d["links"]
        if not isinstance(links, list):
            raise _fail(f"{path}.links", "a list of link inertials", links)
        return cls(
            exact=_bool(d["exact"], f"{path}.exact"),
            links=tuple(
                LinkInertial.from_dict(x, f"{path}.links[{i}]") for i, x in enumerate(links)
            ),
            armature=_vector(d["armature"], f"{path}.armature", minimum=0),
            nominal_armature=_vector(d["nominal_armature"], f"{path}.nominal_armature", minimum=0),
            damping=_vector(d["damping"], f"{path}.damping", minimum=0),
            frictionloss=_vector(d["frictionloss"], f"{path}.frictionloss", minimum=0),
            payload_kg=_number(d["payload_kg"], f"{path}.payload_kg", minimum=0),
            position_noise_std_rad=_number(
                d["position_noise_std_rad"], f"{path}.position_noise_std_rad", minimum=0
            ),
            velocity_noise_std_rad_s=_number(
                d["velocity_noise_std_rad_s"], f"{path}.velocity_noise_std_rad_s", minimum=0
            ),
            uncertainty=Uncertainty.from_dict(d["uncertainty"], f"{path}.uncertainty"),
            physics_dt_s=_number(d["physics_dt_s"], f"{path}.physics_dt_s", minimum=0, strict=True),
            control_period_s=_number(
                d["control_period_s"], f"{path}.control_period_s", minimum=0, strict=True
            ),
            integrator=_str(d["integrator"], f"{path}.integrator"),
            engine=_str(d["engine"], f"{path}.engine"),
            friction_model=_str(d["friction_model"], f"{path}.friction_model"),
        )


@dataclass(frozen=True)
class ProtocolSettings:
    """How the episode was run (the fair-comparison protocol).

    Attributes:
        motion_start_s: when the motion starts, from the recording's first sample [s]: the
            pre-roll before it holds the start pose under the episode's own controller.
        hold_s: time kept at the goal after the motion ends [s].
        start_abs_error_rad: |reference - true position| per joint at the motion start.
        start_effort_nm: applied effort per joint at the motion start [N m].
        reproduces_paper: the scenario is the paper's experiment (the report compares it
            with the paper's numbers only then).
    """

    motion_start_s: float
    hold_s: float
    start_abs_error_rad: tuple[float, ...]
    start_effort_nm: tuple[float, ...]
    reproduces_paper: bool = False

    @classmethod
    def from_dict(cls, data: Any, path: str = "protocol") -> ProtocolSettings:
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        return cls(
            motion_start_s=_number(d["motion_start_s"], f"{path}.motion_start_s", minimum=0),
            hold_s=_number(d["hold_s"], f"{path}.hold_s", minimum=0),
            start_abs_error_rad=_vector(
                d["start_abs_error_rad"], f"{path}.start_abs_error_rad", minimum=0
            ),
            start_effort_nm=_vector(d["start_effort_nm"], f"{path}.start_effort_nm"),
            reproduces_paper=_bool(d["reproduces_paper"], f"{path}.reproduces_paper"),
        )


@dataclass(frozen=True)
class ControllerSettings:
    """The controller as run: its params name, registry type and every gain in effect."""

    name: str
    type: str
    gains: Mapping[str, Any]

    @classmethod
    def from_dict(cls, data: Any, path: str = "controller") -> ControllerSettings:
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        return cls(
            name=_str(d["name"], f"{path}.name"),
            type=_str(d["type"], f"{path}.type"),
            gains=_mapping(d["gains"], f"{path}.gains"),
        )


def _pair(value: Any, path: str) -> tuple[str, str]:
    if not (isinstance(value, list | tuple) and len(value) == 2):
        raise _fail(path, "two names", value)
    return (_str(value[0], f"{path}[0]"), _str(value[1], f"{path}[1]"))


ContactKind = Literal["obstacle", "floor", "self"]
KINDS: tuple[ContactKind, ...] = ("obstacle", "floor", "self")


def _kind_of(value: Any, path: str) -> ContactKind:
    for kind in KINDS:
        if value == kind:
            return kind
    raise _fail(path, f"one of {', '.join(KINDS)}", value)


@dataclass(frozen=True)
class ContactSpan:
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

    bodies: tuple[str, str]
    kind: ContactKind
    first_ns: int
    last_ns: int
    samples: int
    max_depth_m: float
    deepest_ns: int

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
        return {
            "bodies": list(self.bodies),
            "kind": self.kind,
            "first_ns": self.first_ns,
            "last_ns": self.last_ns,
            "samples": self.samples,
            "max_depth_m": self.max_depth_m,
            "deepest_ns": self.deepest_ns,
        }

    @classmethod
    def from_dict(cls, data: Any, path: str = "safety.contacts[0]") -> ContactSpan:
        """Inverse of ``to_dict``, validated (:class:`SettingsError` names the field)."""
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        return cls(
            bodies=_pair(d["bodies"], f"{path}.bodies"),
            kind=_kind_of(d["kind"], f"{path}.kind"),
            first_ns=_int(d["first_ns"], f"{path}.first_ns"),
            last_ns=_int(d["last_ns"], f"{path}.last_ns"),
            samples=_int(d["samples"], f"{path}.samples", minimum=1),
            max_depth_m=_number(d["max_depth_m"], f"{path}.max_depth_m", minimum=0),
            deepest_ns=_int(d["deepest_ns"], f"{path}.deepest_ns"),
        )


@dataclass(frozen=True)
class Clearance:
    """The closest approach of one kind of pair during the episode.

    Attributes:
        kind: ``obstacle``, ``self`` or ``floor``.
        bodies: the closest pair, ordered as in ``ContactSpan``.
        distance_m: its signed distance [m] (negative: penetration depth).
        stamp_ns: when [ns].
    """

    kind: ContactKind
    bodies: tuple[str, str]
    distance_m: float
    stamp_ns: int

    def summary(self) -> str:
        """E.g. ``obstacle 11.2 mm (wrist_2_link–blocker at t=0.007 s)``."""
        a, b = self.bodies
        t_s = self.stamp_ns * 1e-9
        return f"{self.kind} {self.distance_m * 1e3:.1f} mm ({a}–{b} at t={t_s:.3f} s)"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "kind": self.kind,
            "bodies": list(self.bodies),
            "distance_m": self.distance_m,
            "stamp_ns": self.stamp_ns,
        }

    @classmethod
    def from_dict(cls, data: Any, path: str = "safety.clearances[0]") -> Clearance:
        """Inverse of ``to_dict``, validated."""
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        return cls(
            kind=_kind_of(d["kind"], f"{path}.kind"),
            bodies=_pair(d["bodies"], f"{path}.bodies"),
            distance_m=_number(d["distance_m"], f"{path}.distance_m"),
            stamp_ns=_int(d["stamp_ns"], f"{path}.stamp_ns"),
        )


@dataclass(frozen=True)
class ExecutionSafety:
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

    padding_m: float
    every: int
    samples_checked: int
    clearances: tuple[Clearance, ...]
    contacts: tuple[ContactSpan, ...]
    skip_within_m: float = 0.0

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
        and ``summary`` are derived, for readers of the JSON alone."""
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

    @classmethod
    def from_dict(cls, data: Any, path: str = "safety") -> ExecutionSafety:
        """Inverse of ``to_dict`` (derived keys are not read), validated."""
        d = {"skip_within_m": 0.0, **_mapping(data, path)}  # absent before it existed
        _check_keys(d, cls, path)
        clearances, contacts = d["clearances"], d["contacts"]
        if not isinstance(clearances, list):
            raise _fail(f"{path}.clearances", "a list", clearances)
        if not isinstance(contacts, list):
            raise _fail(f"{path}.contacts", "a list", contacts)
        return cls(
            padding_m=_number(d["padding_m"], f"{path}.padding_m", minimum=0),
            every=_int(d["every"], f"{path}.every", minimum=1),
            samples_checked=_int(d["samples_checked"], f"{path}.samples_checked"),
            skip_within_m=_number(d["skip_within_m"], f"{path}.skip_within_m", minimum=0),
            clearances=tuple(
                Clearance.from_dict(c, f"{path}.clearances[{i}]") for i, c in enumerate(clearances)
            ),
            contacts=tuple(
                ContactSpan.from_dict(c, f"{path}.contacts[{i}]") for i, c in enumerate(contacts)
            ),
        )


@dataclass(frozen=True)
class CampaignInfo:
    """Where an episode sits in a campaign (a sweep), for the report's summaries.

    Attributes:
        name: the campaign's name in params.
        condition: stable key of the swept values other than the controller and the
            seed (e.g. ``"payload_kg=0.5,frictionloss=1"``; ``""`` when only those vary):
            episodes of one condition differ only by controller and seed.
        swept: every swept axis and this episode's value (controller and seed included),
            JSON scalars, keyed by the params path (``plant.payload_kg``).
    """

    name: str
    condition: str
    swept: Mapping[str, Any]

    @classmethod
    def from_dict(cls, data: Any, path: str = "campaign") -> CampaignInfo:
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        swept = _mapping(d["swept"], f"{path}.swept")
        for key, value in swept.items():
            if not (value is None or isinstance(value, str | int | float | bool)):
                raise _fail(f"{path}.swept.{key}", "a JSON scalar", value)
        return cls(
            name=_str(d["name"], f"{path}.name"),
            condition=_str(d["condition"], f"{path}.condition"),
            swept=swept,
        )


@dataclass(frozen=True)
class EpisodeSettings:
    """Everything a recording says about how it was made (its ``settings`` JSON).

    Attributes:
        episode: the episode key (the recording's name).
        robot: the robot spec as plain data (YAML form, radians).
        scenario: the scenario's params as given (with ``name``).
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
        version: settings layout version.
    """

    episode: str
    robot: Mapping[str, Any]
    scenario: Mapping[str, Any]
    controller: ControllerSettings
    plant: PlantSettings
    planner: PlannerSettings
    protocol: ProtocolSettings
    safety: ExecutionSafety
    seed: int
    status: str
    reason: str
    package_version: str
    git_commit: str
    mujoco_warnings: Mapping[str, int] = field(default_factory=dict)
    campaign: CampaignInfo | None = None
    version: int = SETTINGS_VERSION

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready plain data (lists, not tuples)."""
        out: dict[str, Any] = _plain(asdict(self))
        out["safety"] = self.safety.to_dict()  # with its derived keys, for readers of the JSON
        return out

    @classmethod
    def from_dict(cls, data: Any) -> EpisodeSettings:
        """Validate plain data (parsed JSON) into settings.

        Raises:
            SettingsError: a missing or ill-typed field, a value out of range (names it).
        """
        d = _mapping(data, "settings")
        version = d.get("version")
        if version != SETTINGS_VERSION:
            raise _fail("version", f"settings version {SETTINGS_VERSION}", version)
        _check_keys(d, cls, "")
        status = _str(d["status"], "status")
        if status not in ("ok", "diverged"):
            raise _fail("status", "'ok' or 'diverged'", status)
        warnings = _mapping(d["mujoco_warnings"], "mujoco_warnings")
        return cls(
            episode=_str(d["episode"], "episode"),
            robot=_mapping(d["robot"], "robot"),
            scenario=_mapping(d["scenario"], "scenario"),
            controller=ControllerSettings.from_dict(d["controller"]),
            plant=PlantSettings.from_dict(d["plant"]),
            planner=PlannerSettings.from_dict(d["planner"]),
            protocol=ProtocolSettings.from_dict(d["protocol"]),
            safety=ExecutionSafety.from_dict(d["safety"]),
            seed=_int(d["seed"], "seed"),
            status=status,
            reason=_str(d["reason"], "reason"),
            package_version=_str(d["package_version"], "package_version"),
            git_commit=_str(d["git_commit"], "git_commit"),
            mujoco_warnings={str(k): _int(v, f"mujoco_warnings.{k}") for k, v in warnings.items()},
            campaign=None if d["campaign"] is None else CampaignInfo.from_dict(d["campaign"]),
            version=SETTINGS_VERSION,
        )

    @property
    def motion_end_s(self) -> float:
        """When the reference stops, from the recording's first sample [s]."""
        return self.protocol.motion_start_s + self.planner.trajectory_duration_s


def per_joint(values: Sequence[float], n: int) -> tuple[float, ...]:
    """Expand one value (or ``n`` values) to one per joint."""
    vals = tuple(float(v) for v in values)
    if len(vals) == 1:
        return vals * n
    if len(vals) != n:
        raise ValueError(f"expected 1 or {n} values, got {len(vals)}")
    return vals
