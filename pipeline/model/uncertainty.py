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
from dataclasses import replace

import numpy as np

from pipeline.errors import ModelError
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
