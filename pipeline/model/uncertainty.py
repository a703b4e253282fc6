"""A plant that differs from the nominal model the way a real arm does: drawn link parameters.

Each episode's plant draws, from its own seed, a factor on every link mass, an offset
of every centre of mass, a per-axis scale of every link's second moments and a factor
on every rotor armature. The controllers keep the nominal spec; only the plant gets
the drawn one. Every drawn tensor is physical by construction: with the second-moment
matrix ``S = tr(I)/2 * 1 - I`` (positive semi-definite for any rigid body) scaled as
``D S D`` (``D`` diagonal, positive), ``I' = tr(S') * 1 - S'`` is positive definite
and satisfies the triangle inequality whatever is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from pipeline.errors import ModelError
from pipeline.model.published import SigmoidFriction
from pipeline.robots.spec import Inertial, RobotSpec
from pipeline.settings import LinkInertial, Uncertainty

# Stream id mixed into the episode seed: the plant draw never shares numbers with the
# sensor noise (which uses the bare seed), and adding noise never changes the plant.
_PLANT_STREAM = 0x504C414E


def _full(inertia: Sequence[float]) -> np.ndarray:
    ixx, iyy, izz, ixy, ixz, iyz = inertia
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def _rows(tensor: np.ndarray) -> tuple[tuple[float, float, float], ...]:
    return tuple((float(r[0]), float(r[1]), float(r[2])) for r in tensor)


def _six(tensor: np.ndarray) -> tuple[float, float, float, float, float, float]:
    t = 0.5 * (tensor + tensor.T)
    return (
        float(t[0, 0]),
        float(t[1, 1]),
        float(t[2, 2]),
        float(t[0, 1]),
        float(t[0, 2]),
        float(t[1, 2]),
    )


def link_inertials(spec: RobotSpec) -> tuple[LinkInertial, ...]:
    """The spec's link inertials in the settings' form."""
    spec.require_dynamics("plant parameters")
    out = []
    for j in spec.joints:
        assert j.inertial is not None
        full = np.array(j.inertial.inertia)
        out.append(LinkInertial(j.inertial.mass, j.inertial.com, _six(full)))
    return tuple(out)


def draw_plant(spec: RobotSpec, uncertainty: Uncertainty, *, seed: int) -> RobotSpec:
    """The plant's spec: ``spec`` with link parameters and armature drawn per ``seed``.

    With no uncertainty the spec itself is returned (the ideal plant).

    Raises:
        ModelError: a relative spread of 1 or more (a mass or scale could reach zero).
    """
    spec.require_dynamics("plant uncertainty")
    if not uncertainty.any:
        return spec
    for name in ("mass_rel", "inertia_rel", "armature_rel"):
        if not 0 <= getattr(uncertainty, name) < 1:
            raise ModelError(
                f"plant.uncertainty.{name}: expected a relative spread in [0, 1), got "
                f"{getattr(uncertainty, name)}"
            )
    rng = np.random.default_rng([int(seed), _PLANT_STREAM])
    n = spec.dof
    # drawn in a fixed order and size whatever the spreads are, so changing one spread
    # does not reshuffle the others' draws
    u_mass = rng.uniform(-1.0, 1.0, n)
    u_com = rng.uniform(-1.0, 1.0, (n, 3))
    u_inertia = rng.uniform(-1.0, 1.0, (n, 3))
    u_armature = rng.uniform(-1.0, 1.0, n)
    joints = []
    for i, j in enumerate(spec.joints):
        assert j.inertial is not None
        inertia = np.array(j.inertial.inertia)
        second = 0.5 * np.trace(inertia) * np.eye(3) - inertia
        d = np.diag(1.0 + uncertainty.inertia_rel * u_inertia[i])
        second = d @ second @ d
        drawn = np.trace(second) * np.eye(3) - second
        com = np.array(j.inertial.com) + uncertainty.com_m * u_com[i]
        inertial = Inertial(
            mass=float(j.inertial.mass * (1.0 + uncertainty.mass_rel * u_mass[i])),
            com=(float(com[0]), float(com[1]), float(com[2])),
            inertia=_rows(drawn),
        )
        armature = j.armature * (1.0 + uncertainty.armature_rel * u_armature[i])
        joints.append(replace(j, inertial=inertial, armature=float(armature)))
    return replace(spec, joints=tuple(joints))


def with_plant(
    spec: RobotSpec, links: Sequence[LinkInertial], armature: Sequence[float]
) -> RobotSpec:
    """``spec`` with the given link inertials and armature (rebuilds a recorded plant).

    Raises:
        ModelError: the counts do not match the robot's joints.
    """
    if len(links) != spec.dof or len(armature) != spec.dof:
        raise ModelError(
            f"plant: expected {spec.dof} links and armature values for {spec.name}, got "
            f"{len(links)} and {len(armature)}"
        )
    joints = tuple(
        replace(
            j,
            inertial=Inertial(
                mass=link.mass,
                com=link.com,
                inertia=_rows(_full(link.inertia)),
            ),
            armature=float(a),
        )
        for j, link, a in zip(spec.joints, links, armature, strict=True)
    )
    return replace(spec, joints=joints)


# The friction, payload and torque-sensor draws use their own streams: adding them
# changes neither the link draws nor the sensor noise of a seed.
_FRICTION_STREAM = 0x46524943
EFFORT_NOISE_STREAM = 0x45464654
"""Stream id of the torque sensor's per-sample noise (``pipeline.sim.runner``)."""


@dataclass(frozen=True)
class DrawnFriction:
    """The joint friction, payload and torque-sensor offset one episode's plant draws.

    Attributes:
        damping: viscous friction per joint [N m s/rad].
        frictionloss: MuJoCo's stick-slip Coulomb friction per joint [N m].
        sigmoid: the sigmoid friction (a published profile's), None if none.
        payload_kg: the payload at the flange [kg].
        effort_offset_nm: the torque sensor's offset per joint [N m] (empty: none).
    """

    damping: tuple[float, ...]
    frictionloss: tuple[float, ...]
    sigmoid: SigmoidFriction | None
    payload_kg: float
    effort_offset_nm: tuple[float, ...]


def draw_friction(
    uncertainty: Uncertainty,
    *,
    damping: Sequence[float],
    frictionloss: Sequence[float],
    sigmoid: SigmoidFriction | None,
    payload_kg: float,
    effort_offset_nm: float,
    seed: int,
) -> DrawnFriction:
    """The joint friction, payload and sensor offset drawn per ``seed`` (uniform):
    Coulomb (``frictionloss``, or the sigmoid's ``phi1``) x ``1 + coulomb_rel u``, damping
    x ``1 + viscous_rel u``, the sigmoid's ``phi2`` x ``1 + transition_rel u`` (u in
    [-1, 1] per joint), ``payload_kg + U[0, uncertainty.payload_kg]`` and an offset
    ``U[-effort_offset_nm, effort_offset_nm]`` per joint. ``damping`` and ``frictionloss``
    have one value per joint. Nothing spread: the values as given.

    Raises:
        ModelError: a transition spread on a plant without a sigmoid, or a relative
            spread of 1 or more.
    """
    n = len(damping)
    for name in ("coulomb_rel", "viscous_rel", "transition_rel"):
        if not 0 <= getattr(uncertainty, name) < 1:
            raise ModelError(
                f"plant.uncertainty.{name}: expected a relative spread in [0, 1), got "
                f"{getattr(uncertainty, name)}"
            )
    if uncertainty.transition_rel > 0 and sigmoid is None:
        raise ModelError(
            f"plant.uncertainty.transition_rel: {uncertainty.transition_rel:g} spreads a "
            "sigmoid friction's transition, but this plant's friction is MuJoCo's Coulomb "
            "frictionloss (give a plant.profile with sigmoid friction, or 0)"
        )
    rng = np.random.default_rng([int(seed), _FRICTION_STREAM])
    # a fixed order and size whatever is spread (one spread does not reshuffle another)
    u_coulomb = rng.uniform(-1.0, 1.0, n)
    u_viscous = rng.uniform(-1.0, 1.0, n)
    u_transition = rng.uniform(-1.0, 1.0, n)
    u_payload = float(rng.uniform(0.0, 1.0))
    u_offset = rng.uniform(-1.0, 1.0, n)

    def scaled(values: Sequence[float], spread: float, u: np.ndarray) -> tuple[float, ...]:
        if spread == 0:
            return tuple(float(v) for v in values)
        return tuple(float(v * (1.0 + spread * x)) for v, x in zip(values, u, strict=True))

    drawn_sigmoid = None
    if sigmoid is not None:
        drawn_sigmoid = SigmoidFriction(
            phi1_nm=scaled(sigmoid.phi1_nm, uncertainty.coulomb_rel, u_coulomb),
            phi2_s_rad=scaled(sigmoid.phi2_s_rad, uncertainty.transition_rel, u_transition),
            phi3_rad_s=sigmoid.phi3_rad_s,
        )
    payload = (
        payload_kg + uncertainty.payload_kg * u_payload if uncertainty.payload_kg else payload_kg
    )
    return DrawnFriction(
        damping=scaled(damping, uncertainty.viscous_rel, u_viscous),
        frictionloss=scaled(frictionloss, uncertainty.coulomb_rel, u_coulomb),
        sigmoid=drawn_sigmoid,
        payload_kg=float(payload),
        effort_offset_nm=(
            tuple(float(effort_offset_nm * x) for x in u_offset) if effort_offset_nm else ()
        ),
    )
