"""Published plants: an arm's link parameters and joint friction as identified on a real
robot and published, for a scenario's ``plant.profile``.

``gaz-panda``: the Franka Emika Panda of C. Gaz, M. Cognetti, A. Oliva, P. Robuffo
Giordano, A. De Luca, "Dynamic Identification of the Franka Emika Panda Robot With
Retrieval of Feasible Parameters Using Penalty-Based Optimization", IEEE RA-L 4(4), 2019.
Transcribed by hand from the paper's supplementary material (revised October 15th, 2019),
``pdf/RA-L_2019_PandaDynIdent_SUPPLEMENTARY_MATERIAL.pdf`` in the authors' repository
github.com/marcocognetti/FrankaEmikaPandaDynModel (commit 24d85ce):

- link masses and centres of mass: Table VIII, column p-hat (their feasible set);
- inertia tensors about the centre of mass, link-frame axes: Table IX, column p-hat;
- friction: Table I, ``tau_f = phi1 / (1 + exp(-phi2 (qd + phi3))) - phi1 / (1 + exp(-phi2
  phi3))`` per joint (their ``get_FrictionTorque.m`` has the same numbers).

Their link frames are Craig's (modified DH) frames of Franka's DH table, which are the
link frames of franka_description's URDF (so of the robot ``panda``): the parameters go
in unchanged. Table VIII gives c1z as "don't care" (it does not enter the dynamics of a
link that turns about its z axis); franka_description's -0.04762 m is kept.

The identified arm ends at link 7 (no hand). The ``panda`` robot carries the Franka Hand
and its fingers, fixed on link 7; the plant lumps them on link 7 with their CAD inertials
(franka_description's ``panda_hand``, ``panda_leftfinger``, ``panda_rightfinger``,
transcribed below), as the robot file does. Gaz et al. publish no rotor inertia (the
Panda's torque sensors sit on the link side): the plant keeps the robot's armature.

Example-robot-data's URDF links 1-7 already carry these feasible parameters (its authors
took them from the same paper), so the published plant's rigid bodies equal the URDF's
CAD nominal within the transcription; what differs is the friction (sigmoid, not
Coulomb + viscous), which is the point: the identifier's friction class is Coulomb +
viscous (+ a tanh), not this one.

``tests/model/test_published_plant.py`` checks the plant's gravity vector and mass matrix
against the authors' own symbolic model (``get_GravityVector.m``, ``get_MassMatrix.m``,
which use the paper's reverse-engineered coefficients).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from pipeline.errors import ModelError
from pipeline.robots.spec import Inertial, RobotSpec

GAZ_SOURCE = (
    "Gaz et al., IEEE RA-L 2019, supplementary material (github.com/marcocognetti/"
    "FrankaEmikaPandaDynModel pdf/, commit 24d85ce): Table VIII, IX (p-hat), Table I"
)

# Table VIII (mass [kg], centre of mass [m]) and Table IX (inertia about the centre of
# mass [kg m^2]: Ixx, Iyy, Izz, Ixy, Ixz, Iyz), column p-hat, links 1..7.
_GAZ_LINKS: tuple[
    tuple[float, tuple[float, float, float], tuple[float, float, float, float, float, float]],
    ...,
] = (
    (
        4.970684,
        (3.875e-03, 2.081e-03, -0.04762),  # c1z: "*" in the paper (franka_description's)
        (7.0337e-01, 7.0661e-01, 9.1170e-03, -1.3900e-04, 6.7720e-03, 1.9169e-02),
    ),
    (
        0.646926,
        (-3.141e-03, -2.872e-02, 3.495e-03),
        (7.9620e-03, 2.8110e-02, 2.5995e-02, -3.9250e-03, 1.0254e-02, 7.0400e-04),
    ),
    (
        3.228604,
        (2.7518e-02, 3.9252e-02, -6.6502e-02),
        (3.7242e-02, 3.6155e-02, 1.0830e-02, -4.7610e-03, -1.1396e-02, -1.2805e-02),
    ),
    (
        3.587895,
        (-5.317e-02, 1.04419e-01, 2.7454e-02),
        (2.5853e-02, 1.9552e-02, 2.8323e-02, 7.7960e-03, -1.3320e-03, 8.6410e-03),
    ),
    (
        1.225946,
        (-1.1953e-02, 4.1065e-02, -3.8437e-02),
        (3.5549e-02, 2.9474e-02, 8.6270e-03, -2.1170e-03, -4.0370e-03, 2.2900e-04),
    ),
    (
        1.666555,
        (6.0149e-02, -1.4117e-02, -1.0517e-02),
        (1.9640e-03, 4.3540e-03, 5.4330e-03, 1.0900e-04, -1.1580e-03, 3.4100e-04),
    ),
    (
        7.35522e-01,
        (1.0517e-02, -4.252e-03, 6.1597e-02),
        (1.2516e-02, 1.0027e-02, 4.8150e-03, -4.2800e-04, -1.1960e-03, -7.4100e-04),
    ),
)

# Table I: phi1 [N m], phi2 [s/rad], phi3 [rad/s], joints 1..7.
_GAZ_PHI1 = (5.4615e-01, 0.87224, 6.4068e-01, 1.2794e00, 8.3904e-01, 3.0301e-01, 5.6489e-01)
_GAZ_PHI2 = (5.1181e00, 9.0657e00, 1.0136e01, 5.5903e00, 8.3469e00, 1.7133e01, 1.0336e01)
_GAZ_PHI3 = (3.9533e-02, 2.5882e-02, -4.6070e-02, 3.6194e-02, 2.6226e-02, -2.1047e-02, 3.5526e-03)

# Franka's DH table (Craig convention) as the authors use it (their Load_Franka_DH.m):
# per joint (a_{i-1} [m], d_i [m], alpha_{i-1} [rad]).
PANDA_CRAIG_DH = (
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -math.pi / 2),
    (0.0, 0.316, math.pi / 2),
    (0.0825, 0.0, math.pi / 2),
    (-0.0825, 0.384, -math.pi / 2),
    (0.0, 0.0, math.pi / 2),
    (0.088, 0.0, math.pi / 2),
)

# The Franka Hand on link 7, CAD (franka_description's panda.urdf as example-robot-data
# ships it): panda_link8 at z = 0.107 m, the hand turned -pi/4 about z; the hand's
# inertial in its frame; each finger 0.015 kg at z = 0.0584 m in the hand frame (closed,
# as the robot file locks them), inertia diag(2.375e-6, 2.375e-6, 7.5e-7) [kg m^2].
_HAND_Z_M = 0.107
_HAND_YAW_RAD = -math.pi / 4
_HAND = (0.73, (-0.01, 0.0, 0.03), (0.001, 0.0025, 0.0017))
_FINGER = (0.015, (0.0, 0.0, 0.0584), (2.375e-06, 2.375e-06, 7.5e-07))
_FINGERS = 2


@dataclass(frozen=True)
class SigmoidFriction:
    """Joint friction ``tau_f(qd) = phi1 / (1 + exp(-phi2 (qd + phi3))) - phi1 / (1 +
    exp(-phi2 phi3))`` per joint (Gaz et al. 2019, Table I): the torque the motor spends
    on friction, zero at rest, odd only when ``phi3`` is 0.

    Attributes:
        phi1_nm: the sigmoid's span [N m] (its saturation levels are ``phi1 - offset``
            and ``-offset``).
        phi2_s_rad: steepness [s/rad] (the transition is ~4/phi2 rad/s wide).
        phi3_rad_s: the sigmoid's centre is at ``qd = -phi3`` [rad/s].
    """

    phi1_nm: tuple[float, ...]
    phi2_s_rad: tuple[float, ...]
    phi3_rad_s: tuple[float, ...]

    def torque_nm(self, qd_rad_s: Sequence[float] | np.ndarray) -> np.ndarray:
        """``tau_f`` at joint velocities ``qd`` [rad/s] (any shape ending in the dof)."""
        a = np.asarray(self.phi1_nm)
        b = np.asarray(self.phi2_s_rad)
        c = np.asarray(self.phi3_rad_s)
        qd = np.asarray(qd_rad_s, dtype=np.float64)
        out: np.ndarray = a / (1.0 + np.exp(-b * (qd + c))) - a / (1.0 + np.exp(-b * c))
        return out


@dataclass(frozen=True)
class PlantProfile:
    """A published plant: link inertials and joint friction identified on a real arm.

    Attributes:
        name: the profile's params name (``plant.profile``).
        robot: the arm it describes, for messages.
        joint_names: the joints of the robot it describes, in order.
        craig_dh: the link frames it is expressed in, per joint ``(a_{i-1}, d_i,
            alpha_{i-1})`` (Craig): a robot whose link frames differ is not described.
        links: per joint the inertial of the link it moves (what the robot carries fixed
            to the last link lumped on it).
        friction: the joint friction.
        source: where the numbers come from.
    """

    name: str
    robot: str
    joint_names: tuple[str, ...]
    craig_dh: tuple[tuple[float, float, float], ...]
    links: tuple[Inertial, ...]
    friction: SigmoidFriction
    source: str


def _tensor(six: Sequence[float]) -> np.ndarray:
    ixx, iyy, izz, ixy, ixz, iyz = six
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def _rot_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def lump(bodies: Sequence[tuple[float, np.ndarray, np.ndarray]]) -> Inertial:
    """One rigid body from several in one frame: ``(mass, com, inertia about the com)``
    each; the result's inertia is about the combined centre of mass (parallel axes)."""
    mass = float(sum(m for m, _, _ in bodies))
    com = np.sum([m * np.asarray(c, dtype=np.float64) for m, c, _ in bodies], axis=0) / mass
    inertia = np.zeros((3, 3))
    for m, c, i in bodies:
        r = np.asarray(c) - com
        inertia += np.asarray(i) + m * (float(r @ r) * np.eye(3) - np.outer(r, r))
    return Inertial(
        mass=float(mass),
        com=(float(com[0]), float(com[1]), float(com[2])),
        inertia=tuple((float(r[0]), float(r[1]), float(r[2])) for r in inertia),
    )


def gaz_links(*, hand: bool = True) -> tuple[Inertial, ...]:
    """Gaz et al.'s feasible link inertials (links 1-7, their frames), with the Franka
    Hand and its fingers lumped on link 7 (``hand``) or not (the arm as identified)."""
    links = [
        lump([(m, np.array(c), _tensor(six))]) if i < 6 or not hand else None
        for i, (m, c, six) in enumerate(_GAZ_LINKS)
    ]
    if hand:
        m7, c7, six7 = _GAZ_LINKS[6]
        rot = _rot_z(_HAND_YAW_RAD)
        shift = np.array([0.0, 0.0, _HAND_Z_M])
        parts = [(m7, np.array(c7), _tensor(six7))]
        for (m, c, diag), count in ((_HAND, 1), (_FINGER, _FINGERS)):
            com = shift + rot @ np.array(c)
            inertia = rot @ np.diag(diag) @ rot.T
            parts.extend([(m, com, inertia)] * count)
        links[6] = lump(parts)
    return tuple(link for link in links if link is not None)


GAZ_PANDA = PlantProfile(
    name="gaz-panda",
    robot="the Franka Emika Panda (7 joints panda_joint1..7, with its hand)",
    joint_names=tuple(f"panda_joint{i}" for i in range(1, 8)),
    craig_dh=PANDA_CRAIG_DH,
    links=gaz_links(hand=True),
    friction=SigmoidFriction(_GAZ_PHI1, _GAZ_PHI2, _GAZ_PHI3),
    source=GAZ_SOURCE,
)

PROFILES: dict[str, PlantProfile] = {GAZ_PANDA.name: GAZ_PANDA}


def craig_link_frames(
    dh: Sequence[tuple[float, float, float]], q: Sequence[float] | np.ndarray
) -> list[np.ndarray]:
    """Base-to-link-i transforms of a Craig DH chain at ``q``."""
    t = np.eye(4)
    out = []
    for (a, d, alpha), qi in zip(dh, q, strict=True):
        ca, sa, cq, sq = math.cos(alpha), math.sin(alpha), math.cos(qi), math.sin(qi)
        step = np.array(
            [
                [cq, -sq, 0.0, a],
                [sq * ca, cq * ca, -sa, -sa * d],
                [sq * sa, cq * sa, ca, ca * d],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
        t = t @ step
        out.append(t)
    return out


_FRAME_TOL = 1e-6  # [m] and [-]: the same frames, not merely similar ones


def describes(profile: PlantProfile, spec: RobotSpec) -> str:
    """Why ``profile`` does not describe ``spec`` ("" if it does): other joints, or link
    frames other than the ones its parameters are expressed in."""
    if spec.joint_names != profile.joint_names:
        shown = ", ".join(spec.joint_names[:3]) + (", ..." if spec.dof > 3 else "")
        return f"{spec.name} has {spec.dof} joints ({shown})"
    from pipeline.model.dh import link_frames

    for q in (np.zeros(spec.dof), np.linspace(-0.7, 0.9, spec.dof)):
        theirs = craig_link_frames(profile.craig_dh, q)
        for i, (ours, t) in enumerate(zip(link_frames(spec, q), theirs, strict=True)):
            if np.abs(ours - t).max() > _FRAME_TOL:
                return (
                    f"{spec.name}'s link frame of {spec.joint_names[i]} is not the profile's "
                    "(Craig DH) frame"
                )
    return ""


def profile_plant(spec: RobotSpec, name: str, *, where: str = "plant.profile") -> RobotSpec:
    """``spec`` with the published link inertials of profile ``name`` (armature kept).

    Raises:
        ModelError: an unknown profile, or one that does not describe ``spec``.
    """
    profile = PROFILES.get(name)
    if profile is None:
        raise ModelError(f"{where}: unknown plant profile {name!r} (known: {', '.join(PROFILES)})")
    why = describes(profile, spec)
    if why:
        raise ModelError(f"{where}: {name} describes {profile.robot}, not this robot: {why}")
    joints = tuple(
        replace(j, inertial=link) for j, link in zip(spec.joints, profile.links, strict=True)
    )
    return replace(spec, joints=joints)
