"""Robot descriptions: YAML files validated once at the edge into frozen dataclasses.

A robot is data: one YAML file per robot, shipped in this folder (load by name,
``load_spec("ur5")``) or anywhere on disk (load by path). Inside the package
everything is radians, metres, kilograms and newton-metres.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from pipeline.errors import SpecError, unknown_name_message
from pipeline.yamlio import parse_yaml, refuse_bool_numbers

Convention = Literal["standard", "modified"]

# Names that end up in URDF, MJCF, /tf frames and file names: ROS-style identifiers, plus
# '-' and '.' (both are fine in XML attributes, tf frame ids and file names). Anything else
# ('"', '<', '&', NUL, spaces, '/') is refused here, at the edge; the XML writers escape
# attribute values anyway.
NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_.-]*")
MAX_NAME_CHARS = 100
NAME_RULE = (
    f"a name starts with a letter or '_' and holds only letters, digits, '_', '-' and '.' "
    f"(at most {MAX_NAME_CHARS} characters)"
)


def check_name(value: str) -> str:
    """Return ``value`` if it is a valid robot, joint or obstacle name.

    Raises:
        ValueError: naming the value and :data:`NAME_RULE`.
    """
    if len(value) > MAX_NAME_CHARS or not NAME_PATTERN.fullmatch(value):
        raise ValueError(f"invalid name: {NAME_RULE}")
    return value


Name = Annotated[str, AfterValidator(check_name)]


@dataclass(frozen=True)
class DHRow:
    """One DH row. Standard: ``[alpha_i, a_i, d_i, theta_offset_i]``; modified
    (Craig): ``[alpha_{i-1}, a_{i-1}, d_i, theta_offset_i]``.

    Attributes:
        alpha: link twist [rad].
        a: link length [m].
        d: link offset [m].
        theta_offset: joint zero offset [rad], added to the joint variable.
    """

    alpha: float
    a: float
    d: float
    theta_offset: float


@dataclass(frozen=True)
class JointLimits:
    """Joint limits: position [rad], velocity [rad/s], acceleration [rad/s^2], effort [N m]."""

    lower: float
    upper: float
    velocity: float
    acceleration: float
    effort: float


@dataclass(frozen=True)
class Inertial:
    """Rigid-body inertia of the link moved by a joint, in that link's DH frame.

    Attributes:
        mass: [kg].
        com: centre of mass in DH frame i [m].
        inertia: 3x3 inertia tensor about the centre of mass, DH-frame axes [kg m^2].
    """

    mass: float
    com: tuple[float, float, float]
    inertia: tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class JointSpec:
    """One revolute joint and the link it moves."""

    name: str
    dh: DHRow
    limits: JointLimits
    inertial: Inertial | None
    collision_radius: float
    armature: float = 0.0
    """Rotor (reflected) inertia about the joint axis [kg m^2]: gear ratio^2 x rotor inertia."""


@dataclass(frozen=True)
class RobotSpec:
    """A serial revolute arm: the single source for FK, MuJoCo, URDF and Pinocchio."""

    name: str
    convention: Convention
    joints: tuple[JointSpec, ...]
    source: str
    armature_source: str = ""
    """Where the joints' ``armature`` values come from (data sheet, estimate, identified)."""

    @property
    def dof(self) -> int:
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def has_dynamics(self) -> bool:
        return all(j.inertial is not None for j in self.joints)

    @property
    def lower(self) -> np.ndarray:
        return np.array([j.limits.lower for j in self.joints])

    @property
    def upper(self) -> np.ndarray:
        return np.array([j.limits.upper for j in self.joints])

    @property
    def velocity_limits(self) -> np.ndarray:
        return np.array([j.limits.velocity for j in self.joints])

    @property
    def acceleration_limits(self) -> np.ndarray:
        return np.array([j.limits.acceleration for j in self.joints])

    @property
    def effort_limits(self) -> np.ndarray:
        return np.array([j.limits.effort for j in self.joints])

    @property
    def armature(self) -> np.ndarray:
        """Rotor (reflected) inertia per joint [kg m^2]."""
        return np.array([j.armature for j in self.joints])

    def reach_m(self, first: int = 0) -> float:
        """The summed DH lengths ``|a_j| + |d_j|`` of joints ``first`` onwards [m]: a bound on
        how far the flange gets from joint ``first``'s axis (from the base for 0), in any
        configuration."""
        return sum(abs(j.dh.a) + abs(j.dh.d) for j in self.joints[first:])

    def require_dynamics(self, what: str) -> None:
        """Raise a clear error if ``what`` needs link inertias this robot lacks."""
        if not self.has_dynamics:
            missing = [j.name for j in self.joints if j.inertial is None]
            raise SpecError(
                f"{self.source}: robot '{self.name}' is kinematics-only (no `inertial` for "
                f"{', '.join(missing)}); {what} needs link dynamics: add mass, com and inertia "
                "per joint to the YAML"
            )


# --- the YAML edge -----------------------------------------------------------------


# Physical ranges of a manipulator's description. Beyond them a value is a typo (or an
# attack) that breaks the engines downstream: MuJoCo refuses masses and inertias below
# 1e-15, OMPL an unbounded joint range, and 1e308 overflows every transform.
MAX_LENGTH_M = 10.0  # DH a, d, centres of mass
MAX_ANGLE_RAD = 2 * math.pi  # DH alpha, theta_offset
MAX_JOINT_RAD = 4 * math.pi  # |lower|, |upper|: two turns each way
MAX_VELOCITY_RAD_S = 100.0
MAX_ACCELERATION_RAD_S2 = 1e4
MAX_EFFORT_NM = 1e5
MIN_LIMIT = 1e-3  # velocity [rad/s or deg/s], acceleration, effort [N m]
MIN_MASS_KG, MAX_MASS_KG = 1e-6, 1e4
MIN_INERTIA_KG_M2, MAX_INERTIA_KG_M2 = 1e-12, 1e4
MIN_RADIUS_M, MAX_RADIUS_M = 1e-3, 1.0
Length = Annotated[float, Field(ge=-MAX_LENGTH_M, le=MAX_LENGTH_M)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=False, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _no_bool_numbers(cls, data: Any) -> Any:
        refuse_bool_numbers(cls.model_fields, data)  # `mass: true` is not 1.0 kg
        return data


class _Limits(_Strict):
    lower: float
    upper: float
    # lower bounds: a limit of 1e-300 plans a motion of 1e300 s
    velocity: float = Field(ge=MIN_LIMIT, allow_inf_nan=False)
    acceleration: float = Field(ge=MIN_LIMIT, allow_inf_nan=False)
    effort: float = Field(ge=MIN_LIMIT, le=MAX_EFFORT_NM, allow_inf_nan=False)

    @model_validator(mode="after")
    def _ordered(self) -> _Limits:
        if not self.lower < self.upper:
            raise ValueError(f"lower ({self.lower}) must be < upper ({self.upper})")
        return self


class _Inertial(_Strict):
    mass: float = Field(ge=MIN_MASS_KG, le=MAX_MASS_KG, allow_inf_nan=False)
    com: tuple[Length, Length, Length]
    inertia: tuple[float, float, float, float, float, float] = Field(
        description="[ixx, iyy, izz, ixy, ixz, iyz] about the centre of mass [kg m^2]"
    )

    @field_validator("inertia")
    @classmethod
    def _physical(
        cls, v: tuple[float, float, float, float, float, float]
    ) -> tuple[float, float, float, float, float, float]:
        ixx, iyy, izz, ixy, ixz, iyz = v
        tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        if float(np.abs(tensor).max()) > MAX_INERTIA_KG_M2:
            raise ValueError(f"inertia entries must be at most {MAX_INERTIA_KG_M2:g} kg m^2")
        eig = np.linalg.eigvalsh(tensor)
        if eig[0] < MIN_INERTIA_KG_M2:
            raise ValueError(
                "inertia tensor must be positive definite with principal moments >= "
                f"{MIN_INERTIA_KG_M2:g} kg m^2 (eigenvalues {[float(f'{e:.3g}') for e in eig]})"
            )
        a, b, c = eig
        if a + b < c * (1 - 1e-9):
            raise ValueError(
                "principal moments violate the triangle inequality "
                f"({a:.6g} + {b:.6g} < {c:.6g}): no rigid body has this inertia"
            )
        return v


class _Collision(_Strict):
    radius: float = Field(ge=MIN_RADIUS_M, le=MAX_RADIUS_M, allow_inf_nan=False)


class _Joint(_Strict):
    name: Name
    dh: tuple[float, float, float, float]
    limits: _Limits
    inertial: _Inertial | None = None
    collision: _Collision = _Collision(radius=0.04)
    armature: float = Field(default=0.0, ge=0, le=1e3, allow_inf_nan=False)


class _Robot(_Strict):
    name: Name
    convention: Convention
    angle_unit: Literal["rad", "deg"] = "rad"
    joints: list[_Joint] = Field(min_length=1)
    armature_source: str = Field(default="", max_length=1000)

    @model_validator(mode="after")
    def _in_range(self) -> _Robot:
        # angles after the unit: the same bound for a file in degrees and one in radians
        per_rad = 180.0 / math.pi if self.angle_unit == "deg" else 1.0
        u = self.angle_unit
        angle, length = MAX_ANGLE_RAD * per_rad, MAX_LENGTH_M
        for i, j in enumerate(self.joints):
            lim = j.limits
            checks = (  # field, value, bound, unit shown
                ("dh[0] (alpha)", j.dh[0], angle, u),
                ("dh[1] (a)", j.dh[1], length, "m"),
                ("dh[2] (d)", j.dh[2], length, "m"),
                ("dh[3] (theta_offset)", j.dh[3], angle, u),
                ("limits.lower", lim.lower, MAX_JOINT_RAD * per_rad, u),
                ("limits.upper", lim.upper, MAX_JOINT_RAD * per_rad, u),
                ("limits.velocity", lim.velocity, MAX_VELOCITY_RAD_S * per_rad, f"{u}/s"),
                ("limits.acceleration", lim.acceleration, MAX_ACCELERATION_RAD_S2 * per_rad,
                 f"{u}/s^2"),
            )  # fmt: skip
            for field_name, value, bound, unit in checks:
                if abs(value) > bound * (1 + 1e-12):
                    raise ValueError(
                        f"joints[{i}].{field_name}: {value!r} is out of range, expected "
                        f"|value| <= {bound:.6g} {unit}"
                    )
        return self

    @model_validator(mode="after")
    def _unique_names(self) -> _Robot:
        seen: set[str] = set()
        links: dict[str, str] = {}
        for i, j in enumerate(self.joints):
            if j.name in seen:
                raise ValueError(f"joints[{i}].name: duplicate joint name '{j.name}'")
            seen.add(j.name)
            # the URDF / tf link a joint moves is named after it (elbow_joint -> elbow_link)
            link = f"{j.name.removesuffix('_joint')}_link"
            if link in links or link in ("base_link", "tool0"):
                clash = f"joint '{links[link]}'" if link in links else "the base frame"
                raise ValueError(
                    f"joints[{i}].name: '{j.name}' names its link '{link}', already used by "
                    f"{clash}; rename the joint"
                )
            links[link] = j.name
        return self


_UNION_BRANCHES = {
    "function-after",
    "tagged-union",
    "float",
    "int",
    "bool",
    "str",
    "list",
    "constrained-float",
    "constrained-int",
    "constrained-str",
}


def _field_path(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in _UNION_BRANCHES or "[" in str(part):
            continue  # pydantic names the union member it tried: not a YAML field
        else:
            out += ("." if out else "") + str(part)
    return out


def format_validation_error(source: str, err: ValidationError) -> str:
    """Turn pydantic's error into one line: ``file: field.path: what was wrong``."""
    # the deepest location is the most specific (for a union, the branch that got furthest)
    first = max(err.errors(), key=lambda e: len(e["loc"]))
    path = _field_path(tuple(first["loc"]))
    msg = first["msg"].removeprefix("Value error, ")
    given = first.get("input")
    shown = "" if isinstance(given, dict | list) or given is None else f" (got {given!r})"
    where = f"{path}: " if path else ""
    more = f" (+{err.error_count() - 1} more)" if err.error_count() > 1 else ""
    return f"{source}: {where}{msg}{shown}{more}"


def _to_spec(raw: _Robot, source: str) -> RobotSpec:
    k = math.pi / 180.0 if raw.angle_unit == "deg" else 1.0
    joints = []
    for j in raw.joints:
        alpha, a, d, off = j.dh
        lim = j.limits
        inertial = None
        if j.inertial is not None:
            ixx, iyy, izz, ixy, ixz, iyz = j.inertial.inertia
            inertial = Inertial(
                mass=j.inertial.mass,
                com=j.inertial.com,
                inertia=((ixx, ixy, ixz), (ixy, iyy, iyz), (ixz, iyz, izz)),
            )
        joints.append(
            JointSpec(
                name=j.name,
                dh=DHRow(alpha=alpha * k, a=a, d=d, theta_offset=off * k),
                limits=JointLimits(
                    lower=lim.lower * k,
                    upper=lim.upper * k,
                    velocity=lim.velocity * k,
                    acceleration=lim.acceleration * k,
                    effort=lim.effort,
                ),
                inertial=inertial,
                collision_radius=j.collision.radius,
                armature=j.armature,
            )
        )
    return RobotSpec(
        name=raw.name,
        convention=raw.convention,
        joints=tuple(joints),
        source=source,
        armature_source=raw.armature_source,
    )


def parse_spec(data: Any, *, source: str) -> RobotSpec:
    """Validate already-parsed YAML data into a :class:`RobotSpec`."""
    if not isinstance(data, dict):
        raise SpecError(f"{source}: expected a mapping with name, convention and joints")
    try:
        raw = _Robot.model_validate(data)
    except ValidationError as err:
        raise SpecError(format_validation_error(source, err)) from err
    return _to_spec(raw, source)


def builtin_robot_names() -> list[str]:
    """Names of the robots shipped inside the package."""
    folder = resources.files("pipeline.robots")
    return sorted(
        p.name.removesuffix(".yaml") for p in folder.iterdir() if p.name.endswith(".yaml")
    )


def load_spec(name_or_path: str | Path) -> RobotSpec:
    """Load a robot by built-in name (``"ur5"``) or by path to a YAML file.

    Built-in robots are parsed once per process (they are package data).

    Raises:
        SpecError: unknown name (lists the available ones), unreadable file or
            invalid content (names the file and field path).
    """
    text = str(name_or_path)
    path = Path(text)
    # a path has a YAML suffix or a slash; anything else is a built-in name (a stray
    # file or folder called "ur5" in the working directory must not hide the robot)
    if path.suffix in (".yaml", ".yml") or "/" in text or "\\" in text:
        if path.is_dir():
            raise SpecError(f"{text}: is a directory, expected a robot YAML file")
        if not path.is_file():
            raise SpecError(f"{text}: no such robot file")
        source = str(path)
        try:
            content = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise SpecError(f"{source}: cannot read robot file ({err})") from err
    else:
        names = builtin_robot_names()
        if text not in names:
            hint = unknown_name_message("robot", text, names)
            raise SpecError(f"{hint} (or pass a path to a YAML file)")
        return _load_builtin(text)
    return _parse_text(content, source)


@functools.lru_cache(maxsize=16)
def _load_builtin(name: str) -> RobotSpec:
    content = (resources.files("pipeline.robots") / f"{name}.yaml").read_text(encoding="utf-8")
    return _parse_text(content, f"robots/{name}.yaml")


def _parse_text(content: str, source: str) -> RobotSpec:
    return parse_spec(parse_yaml(content, source=source, error=SpecError), source=source)
