"""Robot descriptions: YAML files validated once at the edge into frozen dataclasses.

A robot is data: one YAML file per robot, shipped in this folder (load by name,
``load_spec("ur5")``) or anywhere on disk (load by path). Inside the package
everything is radians, metres, kilograms and newton-metres.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import itertools
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


Pose = tuple[tuple[float, float, float, float], ...]
"""A 4x4 homogeneous transform as nested tuples (hashable: specs key per-process caches)."""
IDENTITY: Pose = (
    (1.0, 0.0, 0.0, 0.0),
    (0.0, 1.0, 0.0, 0.0),
    (0.0, 0.0, 1.0, 0.0),
    (0.0, 0.0, 0.0, 1.0),
)
JointKind = Literal["revolute", "continuous", "prismatic"]


def as_pose(t: Any) -> Pose:
    """A 4x4 array-like as a :data:`Pose` (values kept bit for bit)."""
    a = np.asarray(t, dtype=np.float64).reshape(4, 4)
    return tuple((float(r[0]), float(r[1]), float(r[2]), float(r[3])) for r in a)


def pose_matrix(p: Pose) -> np.ndarray:
    """A :data:`Pose` as a 4x4 float64 array."""
    return np.array(p, dtype=np.float64)


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
    """Joint limits: position [rad], velocity [rad/s], acceleration [rad/s^2], effort [N m]
    (metres, m/s, m/s^2 and N for a prismatic joint)."""

    lower: float
    upper: float
    velocity: float
    acceleration: float
    effort: float


@dataclass(frozen=True)
class Inertial:
    """Rigid-body inertia of the link a joint moves, in that link's frame.

    Attributes:
        mass: [kg].
        com: centre of mass in the link frame [m].
        inertia: 3x3 inertia tensor about the centre of mass, link-frame axes [kg m^2].
    """

    mass: float
    com: tuple[float, float, float]
    inertia: tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class Segment:
    """A capsule of link geometry, endpoints in the link frame [m]."""

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Shape:
    """A collision shape of a link (URDF ``<collision>``), pose in the link frame.

    Attributes:
        kind: ``box`` (size = half extents), ``sphere`` (radius), ``cylinder`` (radius,
            half length), ``mesh`` (scale xyz; ``mesh`` the file's absolute path).
    """

    kind: Literal["box", "sphere", "cylinder", "mesh"]
    pose: Pose
    size: tuple[float, ...]
    mesh: str = ""


@dataclass(frozen=True)
class Frame:
    """A named frame fixed to a link (``tool0``, a TCP, a merged fixed link)."""

    name: str
    link: str
    """The link it is fixed to (the base link or a joint's link)."""
    pose: Pose
    """``link_T_frame``."""


@dataclass(frozen=True)
class JointSpec:
    """One controlled joint and the link it moves, in any format's terms.

    The link frame is ``parent link frame @ origin @ motion(axis, q) @ post``: a URDF joint
    has ``post`` = identity (the link frame is the joint frame); a DH row's link frame is
    its DH frame, a fixed transform past the rotation (MJCF-style: the joint need not pass
    through the link frame's origin).
    """

    name: str
    limits: JointLimits
    inertial: Inertial | None
    collision_radius: float
    armature: float = 0.0
    """Rotor (reflected) inertia about the joint axis [kg m^2]: gear ratio^2 x rotor inertia."""
    origin: Pose = IDENTITY
    """``parent_link_T_joint`` at q = 0."""
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    """Unit motion axis in the joint frame."""
    post: Pose = IDENTITY
    """``joint_T_link`` after the motion."""
    kind: JointKind = "revolute"
    link: str = ""
    """Name of the link this joint moves (``elbow_joint`` -> ``elbow_link`` when not given)."""
    capsules: tuple[Segment, ...] = ()
    """Planning / drawing geometry (capsules along the chain), link frame."""
    shapes: tuple[Shape, ...] = ()
    """The description's own collision shapes (URDF), link frame; empty for DH robots."""
    length_m: float = 0.0
    """A bound on how far this link carries the next joint (or the flange) from this
    joint's axis [m] (DH: ``|a| + |d|``); :meth:`RobotSpec.reach_m` sums them."""
    armature_source: str = ""
    """Where ``armature`` comes from (file, sidecar or scenario)."""
    damping_nm_s_rad: float = 0.0
    """Viscous friction the description states [N m s/rad]: a fact for a scenario to use
    (the simulated plant's friction is the scenario's ``plant``, so ``plant: {}`` stays the
    nominal model)."""
    frictionloss_nm: float = 0.0
    """Coulomb friction the description states [N m] (as ``damping_nm_s_rad``)."""
    dh: DHRow | None = None
    """The DH row the joint came from (provenance; the analytic UR solver needs it)."""

    @property
    def link_name(self) -> str:
        return self.link or f"{self.name.removesuffix('_joint')}_link"


@dataclass(frozen=True)
class RobotSpec:
    """A serial arm: the single source for FK, MuJoCo, URDF and Pinocchio, whatever
    format it was loaded from."""

    name: str
    convention: Convention | None
    """The DH convention of a robot given as DH rows, None otherwise."""
    joints: tuple[JointSpec, ...]
    source: str
    base_link: str = "base_link"
    flange: Pose = IDENTITY
    """``last_link_T_flange``: the ``tool0`` frame on the last joint's link."""
    frames: tuple[Frame, ...] = ()
    """Further named fixed frames (merged fixed links, TCPs), addressable in the models."""
    format: str = "dh-yaml"
    """The loader that read ``source`` (its registry key)."""
    source_sha256: str = ""
    """SHA-256 of the description file (URDF: the re-run key of what it drives)."""
    description: str = ""
    """The robot's own description text (a URDF's XML), published as ``/robot_description``;
    empty: generated from the model."""
    disabled_pairs: tuple[tuple[str, str], ...] | None = None
    """Link pairs never checked for collision (an SRDF's); None: those touching at q = 0."""
    named_states: tuple[tuple[str, tuple[float, ...]], ...] = ()
    """Named joint configurations (an SRDF's ``group_state``s, e.g. ``ready``) [rad]."""
    base_shapes: tuple[Shape, ...] = ()
    """Collision shapes of the base link (and links fixed to it), base frame."""
    settings_sources: tuple[tuple[str, str], ...] = ()
    """Where facts the description lacks came from (``armature`` -> sidecar file, ...)."""
    loaded_from: str = ""
    """What :func:`load_spec` was given (a built-in name or a path): loads it again."""

    def __hash__(self) -> int:
        # computed once: specs key the per-process caches of models and FK arrays, and a
        # URDF robot's fields (meshes, description text) take tens of microseconds to hash
        cached: int | None = self.__dict__.get("_hash")
        if cached is None:
            cached = hash(tuple(getattr(self, f.name) for f in dataclasses.fields(self)))
            object.__setattr__(self, "_hash", cached)
        return cached

    def __getstate__(self) -> dict[str, Any]:
        # string hashes differ between processes: a worker computes its own
        return {k: v for k, v in self.__dict__.items() if k != "_hash"}

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

    @property
    def dh_rows(self) -> tuple[DHRow, ...] | None:
        """The DH rows of a robot given as DH (provenance), None for any other robot."""
        rows = tuple(j.dh for j in self.joints if j.dh is not None)
        return rows if self.convention is not None and len(rows) == self.dof else None

    def reach_m(self, first: int = 0) -> float:
        """The summed link lengths (:attr:`JointSpec.length_m`) of joints ``first`` onwards
        [m]: a bound on how far the flange gets from joint ``first``'s axis (from the base
        for 0), in any configuration."""
        return sum(j.length_m for j in self.joints[first:])

    def named_state(self, name: str) -> np.ndarray:
        """A named configuration (SRDF ``group_state``) [rad].

        Raises:
            SpecError: no such state (lists the known ones).
        """
        states = dict(self.named_states)
        if name not in states:
            raise SpecError(
                unknown_name_message("named state", name, list(states), where=self.source)
            )
        return np.array(states[name])

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


_Op = tuple[str, float]
MIN_SEGMENT_M = 1e-6


def _dh_ops(row: DHRow, convention: str) -> tuple[list[_Op], list[_Op]]:
    """A DH row as elementary ops before and after the joint rotation. Both conventions
    factor as ``frame_i = frame_{i-1} @ pre_i @ Rz(q_i) @ post_i``:

    - standard:  pre = I,                           post = Rz(off) Tz(d) Tx(a) Rx(alpha)
    - modified:  pre = Rx(alpha) Tx(a) Tz(d) Rz(off), post = I
    """
    r = row
    if convention == "standard":
        return [], [("rz", r.theta_offset), ("tz", r.d), ("tx", r.a), ("rx", r.alpha)]
    return [("rx", r.alpha), ("tx", r.a), ("tz", r.d), ("rz", r.theta_offset)], []


def _compose(ops: list[_Op]) -> tuple[np.ndarray, list[np.ndarray]]:
    """Matrix of a sequence of elementary ops, and the polyline its translations trace."""
    from pipeline.model import transforms as tf

    t = np.eye(4)
    points = [t[:3, 3].copy()]
    for kind, v in ops:
        step = {
            "rz": lambda x: tf.rot_z(x),
            "rx": lambda x: tf.rot_x(x),
            "tz": lambda x: tf.trans(0, 0, x),
            "tx": lambda x: tf.trans(x, 0, 0),
        }[kind](v)
        t = t @ step
        if kind.startswith("t") and v != 0.0:
            points.append(t[:3, 3].copy())
    return t, points


def _segments(points: list[np.ndarray], to_frame: np.ndarray, radius: float) -> list[Segment]:
    out = []
    pts = [(to_frame @ np.append(p, 1.0))[:3] for p in points]
    for a, b in itertools.pairwise(pts):
        # MuJoCo refuses a capsule shorter than 1e-6 m ("fromto points too close"); a
        # sub-micron DH offset draws no geometry
        if np.linalg.norm(b - a) > MIN_SEGMENT_M:
            out.append(Segment((a[0], a[1], a[2]), (b[0], b[1], b[2]), radius))
    return out


def dh_joint_geometry(
    convention: str, rows: list[DHRow], radii: list[float]
) -> list[tuple[Pose, Pose, tuple[Segment, ...]]]:
    """Per DH row: the joint origin (``pre``, in DH frame i-1), ``post`` (rotated joint
    frame -> DH frame i, the link frame) and the link's capsules in DH frame i, which follow
    the translations of ``post_i`` (moving with link i) and of ``pre_{i+1}``."""
    from pipeline.model import transforms as tf

    decomposed = [_dh_ops(r, convention) for r in rows]
    out = []
    for i, radius in enumerate(radii):
        pre, _ = _compose(decomposed[i][0])
        post, post_pts = _compose(decomposed[i][1])
        # post's polyline is traced from the rotated joint frame: map to DH frame i
        segs = _segments(post_pts, tf.inverse(post), radius)
        if i + 1 < len(rows):
            _, next_pre_pts = _compose(decomposed[i + 1][0])
            segs += _segments(next_pre_pts, np.eye(4), radius)
        out.append((as_pose(pre), as_pose(post), tuple(segs)))
    return out


def with_dh_rows(spec: RobotSpec, rows: list[DHRow]) -> RobotSpec:
    """``spec`` (given as DH rows) with new DH rows: origins, capsules and lengths rebuilt.

    Raises:
        SpecError: the robot is not given as DH rows, or a row count mismatch.
    """
    if spec.convention is None or len(rows) != spec.dof:
        raise SpecError(f"{spec.source}: robot '{spec.name}' takes {spec.dof} DH rows")
    geometry = dh_joint_geometry(spec.convention, rows, [j.collision_radius for j in spec.joints])
    joints = tuple(
        dataclasses.replace(j, origin=o, post=p, capsules=c, length_m=abs(r.a) + abs(r.d), dh=r)
        for j, r, (o, p, c) in zip(spec.joints, rows, geometry, strict=True)
    )
    return dataclasses.replace(spec, joints=joints)


def _to_spec(raw: _Robot, source: str) -> RobotSpec:
    k = math.pi / 180.0 if raw.angle_unit == "deg" else 1.0
    rows = [
        DHRow(alpha=j.dh[0] * k, a=j.dh[1], d=j.dh[2], theta_offset=j.dh[3] * k) for j in raw.joints
    ]
    geometry = dh_joint_geometry(raw.convention, rows, [j.collision.radius for j in raw.joints])
    joints = []
    for j, row, (origin, post, capsules) in zip(raw.joints, rows, geometry, strict=True):
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
                origin=origin,
                post=post,
                capsules=capsules,
                length_m=abs(row.a) + abs(row.d),
                armature_source=source if j.armature else "",
                dh=row,
            )
        )
    return RobotSpec(name=raw.name, convention=raw.convention, joints=tuple(joints), source=source)


def parse_spec(data: Any, *, source: str) -> RobotSpec:
    """Validate already-parsed YAML data into a :class:`RobotSpec`."""
    if not isinstance(data, dict):
        raise SpecError(f"{source}: expected a mapping with name, convention and joints")
    try:
        raw = _Robot.model_validate(data)
    except ValidationError as err:
        raise SpecError(format_validation_error(source, err)) from err
    return _to_spec(raw, source)


BUILTIN_SIDECAR = ".armlab.yaml"


def builtin_robot_names() -> list[str]:
    """Names of the robots shipped inside the package."""
    folder = resources.files("pipeline.robots")
    return sorted(
        p.name.removesuffix(BUILTIN_SIDECAR).removesuffix(".yaml")
        for p in folder.iterdir()
        if p.name.endswith(".yaml")
    )


LOADERS: dict[str, str] = {
    ".yaml": "pipeline.robots.spec:load_dh_yaml",
    ".yml": "pipeline.robots.spec:load_dh_yaml",
    ".urdf": "pipeline.robots.urdf_loader:load_urdf",
    ".armlab.yaml": "pipeline.robots.urdf_loader:load_sidecar",
}
"""Robot file loaders by suffix, ``module:function`` taking ``(path, *, package_path)`` and
returning a :class:`RobotSpec`: a new format is one loader file and one entry here."""


def loader_suffix(path: Path) -> str | None:
    """The :data:`LOADERS` key of a file name (the longest suffix that matches), or None."""
    name = path.name.lower()
    found = [s for s in LOADERS if name.endswith(s)]
    return max(found, key=len) if found else None


def package_search_path(extra: tuple[str, ...] = ()) -> tuple[Path, ...]:
    """Folders that ``package://NAME/...`` resolves in: ``extra`` (the option), then
    ``ARMLAB_PACKAGE_PATH`` and ``ROS_PACKAGE_PATH`` (``:``-separated), then the
    example-robot-data share folder when it is installed. ``NAME`` is a sub-folder of one of
    them (or the folder itself, when it is called ``NAME``)."""
    import os
    import sys

    folders = list(extra)
    for var in ("ARMLAB_PACKAGE_PATH", "ROS_PACKAGE_PATH"):
        folders += [f for f in os.environ.get(var, "").split(os.pathsep) if f]
    share = Path(sys.prefix) / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}"
    share = share / "site-packages" / "cmeel.prefix" / "share"
    if (share / "example-robot-data").is_dir():
        folders.append(str(share))
    return tuple(Path(f).expanduser() for f in folders)


def load_spec(name_or_path: str | Path, *, package_path: tuple[str, ...] = ()) -> RobotSpec:
    """Load a robot by built-in name (``"ur5"``) or by path to a robot file (DH YAML, URDF:
    see :data:`LOADERS`).

    Built-in robots are parsed once per process (they are package data); a file once per
    process and content.

    Raises:
        SpecError: unknown name (lists the available ones), unreadable file or
            invalid content (names the file and field path).
    """
    text = str(name_or_path)
    path = Path(text).expanduser()
    # a path has a known suffix or a slash; anything else is a built-in name (a stray
    # file or folder called "ur5" in the working directory must not hide the robot)
    suffix = loader_suffix(path)
    if suffix is not None or "/" in text or "\\" in text:
        if path.is_dir():
            raise SpecError(f"{text}: is a directory, expected a robot YAML or URDF file")
        if not path.is_file():
            raise SpecError(f"{text}: no such robot file")
        if suffix is None:
            raise SpecError(
                f"{text}: unknown robot file type '{path.suffix}'; valid: {', '.join(LOADERS)}"
            )
        try:
            content = path.read_bytes()
        except OSError as err:
            raise SpecError(f"{text}: cannot read robot file ({err})") from err
        return _load_file(str(path), hashlib.sha256(content).hexdigest(), package_path)
    names = builtin_robot_names()
    if text not in names:
        hint = unknown_name_message("robot", text, names)
        raise SpecError(f"{hint} (or pass a path to a robot file: {', '.join(LOADERS)})")
    return _load_builtin(text)


@functools.lru_cache(maxsize=16)
def _load_file(path: str, sha256: str, package_path: tuple[str, ...]) -> RobotSpec:
    """A robot file, parsed once per process and content (``sha256`` keys the cache)."""
    import importlib

    module, func = LOADERS[loader_suffix(Path(path)) or ""].split(":")
    loader = getattr(importlib.import_module(module), func)
    spec: RobotSpec = loader(Path(path), package_path=package_path)
    return dataclasses.replace(spec, source_sha256=sha256, loaded_from=path)


def load_dh_yaml(path: Path, *, package_path: tuple[str, ...] = ()) -> RobotSpec:
    """The DH YAML loader (``package_path`` unused: a DH robot names no files)."""
    del package_path
    source = str(path)
    try:
        content = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise SpecError(f"{source}: cannot read robot file ({err})") from err
    return _parse_text(content, source)


@functools.lru_cache(maxsize=16)
def _load_builtin(name: str) -> RobotSpec:
    sidecar = resources.files("pipeline.robots") / f"{name}{BUILTIN_SIDECAR}"
    if sidecar.is_file():  # a URDF robot: its settings sidecar names the URDF
        from pipeline.robots.urdf_loader import load_sidecar

        spec = load_sidecar(Path(str(sidecar)))
        digest = hashlib.sha256(Path(spec.source).read_bytes()).hexdigest()
        return dataclasses.replace(spec, source_sha256=digest, loaded_from=name)
    content = (resources.files("pipeline.robots") / f"{name}.yaml").read_text(encoding="utf-8")
    return _parse_text(content, f"robots/{name}.yaml")


def _parse_text(content: str, source: str) -> RobotSpec:
    return parse_spec(parse_yaml(content, source=source, error=SpecError), source=source)
