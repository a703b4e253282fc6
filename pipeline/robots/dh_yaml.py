"""The DH YAML loader: one YAML file per robot, validated once at the edge.

DH rows (standard or modified convention) become the format-neutral joint model of
:mod:`pipeline.robots.spec`: each row's transforms are split around the joint rotation
into an origin and a ``post`` transform that keeps the link frame where DH puts it.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from pipeline.errors import SpecError
from pipeline.robots.spec import (
    Convention,
    DHRow,
    Inertial,
    JointLimits,
    JointSpec,
    Name,
    Pose,
    RobotSpec,
    Segment,
    as_pose,
)
from pipeline.yamlio import parse_yaml, refuse_bool_numbers

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


class StrictModel(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=False, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _no_bool_numbers(cls, data: Any) -> Any:
        refuse_bool_numbers(cls.model_fields, data)  # `mass: true` is not 1.0 kg
        return data


class _Limits(StrictModel):
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


class _Inertial(StrictModel):
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


class _Collision(StrictModel):
    radius: float = Field(ge=MIN_RADIUS_M, le=MAX_RADIUS_M, allow_inf_nan=False)


class _Joint(StrictModel):
    name: Name
    dh: tuple[float, float, float, float]
    limits: _Limits
    inertial: _Inertial | None = None
    collision: _Collision = _Collision(radius=0.04)
    armature: float = Field(default=0.0, ge=0, le=1e3, allow_inf_nan=False)


class _Robot(StrictModel):
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
    from pipeline import transforms as tf

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
    from pipeline import transforms as tf

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
                armature_source=(raw.armature_source or source) if j.armature else "",
                dh=row,
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


def load_dh_yaml(path: Path, *, package_path: tuple[str, ...] = ()) -> RobotSpec:
    """The DH YAML loader (``package_path`` unused: a DH robot names no files)."""
    del package_path
    source = str(path)
    try:
        content = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise SpecError(f"{source}: cannot read robot file ({err})") from err
    return parse_dh_text(content, source)


def parse_dh_text(content: str, source: str) -> RobotSpec:
    return parse_spec(parse_yaml(content, source=source, error=SpecError), source=source)
