"""The robot model every format loads into: frozen dataclasses, format-neutral.

A robot is data: its joints (origin, axis, kind, limits, the inertial of the link each
moves, actuator facts) and named frames. Loaders (:mod:`pipeline.robots.loaders`) read DH
YAML (:mod:`pipeline.robots.dh_yaml`), URDF (:mod:`pipeline.robots.urdf_loader`) and MJCF
(:mod:`pipeline.robots.mjcf_loader`) into it. Inside the package everything is radians,
metres, kilograms and newton-metres.
"""

from __future__ import annotations

import dataclasses
import itertools
import re
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
)

from pipeline.errors import SpecError, unknown_name_message

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
    link: str = ""
    """The description's link the shape belongs to (a URDF link merged into this body
    keeps its own name here); empty: the body's own."""


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
    """Viscous joint friction the robot states [N m s/rad] (a sidecar's ``damping``, else
    the URDF's ``<dynamics damping>``): the simulated plant's default where the scenario's
    ``plant.damping`` is not given (:func:`pipeline.experiment.assemble.plant_friction`)."""
    frictionloss_nm: float = 0.0
    """Coulomb joint friction the robot states [N m] (a sidecar's ``frictionloss``, else the
    URDF's ``<dynamics friction>``), a plant default as ``damping_nm_s_rad``."""
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
    armature_source: str = ""
    """Where the joints' ``armature`` values come from (data sheet, estimate, identified)."""

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
    def damping(self) -> tuple[float, ...]:
        """Viscous joint friction the robot states, per joint [N m s/rad] (0: none)."""
        return tuple(j.damping_nm_s_rad for j in self.joints)

    @property
    def frictionloss(self) -> tuple[float, ...]:
        """Coulomb joint friction the robot states, per joint [N m] (0: none)."""
        return tuple(j.frictionloss_nm for j in self.joints)

    @property
    def dh_rows(self) -> tuple[DHRow, ...] | None:
        """The DH rows of a robot given as DH (provenance), None for any other robot."""
        rows = tuple(j.dh for j in self.joints if j.dh is not None)
        return rows if self.convention is not None and len(rows) == self.dof else None

    @property
    def adjacent_pairs(self) -> tuple[tuple[str, str], ...]:
        """The parent and child body of every joint (the base and the first link included),
        sorted: never a collision pair, with or without an SRDF (a link merged into its
        parent through a fixed or locked joint is that body, so its own joints join it
        or its neighbours)."""
        bodies = [self.base_link, *(j.link_name for j in self.joints)]
        return tuple((min(a, b), max(a, b)) for a, b in itertools.pairwise(bodies) if a != b)

    @property
    def collision_pairs_source(self) -> str:
        """Which link pairs collision checks skip, and from where (an SRDF, or the rule
        used without one)."""
        return dict(self.settings_sources).get(
            "collision_pairs",
            "no SRDF: adjacent links and links touching at q = 0 are not checked",
        )

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
