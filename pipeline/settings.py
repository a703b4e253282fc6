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
from typing import Any, TypeVar

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
    integrator: str = "Euler"
    engine: str = "mujoco"

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


@dataclass(frozen=True)
class Contact:
    """Robot geometry touching something during the episode (true plant state)."""

    bodies: tuple[str, str]
    first_s: float
    last_s: float
    samples: int
    max_penetration_m: float


@dataclass(frozen=True)
class SafetySettings:
    """Execution safety measured on the plant's true states.

    Attributes:
        min_clearance_m: smallest distance between geometry that may collide, capped at
            ``clearance_cap_m`` (beyond it nothing is measured); negative = penetration.
        clearance_cap_m: the distance up to which clearance is measured [m].
        contacts: every touching pair with its times and depth.
    """

    min_clearance_m: float
    clearance_cap_m: float
    contacts: tuple[Contact, ...] = ()

    @classmethod
    def from_dict(cls, data: Any, path: str = "safety") -> SafetySettings:
        d = _mapping(data, path)
        _check_keys(d, cls, path)
        contacts = d["contacts"]
        if not isinstance(contacts, list):
            raise _fail(f"{path}.contacts", "a list", contacts)
        out = []
        for i, c in enumerate(contacts):
            p = f"{path}.contacts[{i}]"
            cd = _mapping(c, p)
            _check_keys(cd, Contact, p)
            bodies = cd["bodies"]
            if not (isinstance(bodies, list | tuple) and len(bodies) == 2):
                raise _fail(f"{p}.bodies", "two names", bodies)
            out.append(
                Contact(
                    bodies=(_str(bodies[0], f"{p}.bodies[0]"), _str(bodies[1], f"{p}.bodies[1]")),
                    first_s=_number(cd["first_s"], f"{p}.first_s", minimum=0),
                    last_s=_number(cd["last_s"], f"{p}.last_s", minimum=0),
                    samples=_int(cd["samples"], f"{p}.samples", minimum=1),
                    max_penetration_m=_number(
                        cd["max_penetration_m"], f"{p}.max_penetration_m", minimum=0
                    ),
                )
            )
        return cls(
            min_clearance_m=_number(d["min_clearance_m"], f"{path}.min_clearance_m"),
            clearance_cap_m=_number(d["clearance_cap_m"], f"{path}.clearance_cap_m", minimum=0),
            contacts=tuple(out),
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
        version: settings layout version.
    """

    episode: str
    robot: Mapping[str, Any]
    scenario: Mapping[str, Any]
    controller: ControllerSettings
    plant: PlantSettings
    planner: PlannerSettings
    protocol: ProtocolSettings
    safety: SafetySettings
    seed: int
    status: str
    reason: str
    package_version: str
    git_commit: str
    mujoco_warnings: Mapping[str, int] = field(default_factory=dict)
    version: int = SETTINGS_VERSION

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready plain data (lists, not tuples)."""
        out: dict[str, Any] = _plain(asdict(self))
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
            safety=SafetySettings.from_dict(d["safety"]),
            seed=_int(d["seed"], "seed"),
            status=status,
            reason=_str(d["reason"], "reason"),
            package_version=_str(d["package_version"], "package_version"),
            git_commit=_str(d["git_commit"], "git_commit"),
            mujoco_warnings={str(k): _int(v, f"mujoco_warnings.{k}") for k, v in warnings.items()},
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
