"""Rigid-link facts shared by the robot loaders: physical checks, merged inertials, capsules."""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.errors import SpecError
from pipeline.robots.spec import Inertial, Segment

__all__ = ["check_physical", "link_capsules", "merged_inertial"]

F64 = np.ndarray[Any, np.dtype[np.float64]]


def check_physical(mass: float, inertia: F64, where: str) -> None:
    """Refuse a non-physical rigid body: negative principal moments, moments that break
    the triangle inequality, or an inertia without mass (naming ``where``)."""
    eig = np.linalg.eigvalsh(inertia)
    tol = 1e-12 * max(1.0, float(np.abs(eig).max()))
    if eig[0] < -tol:
        raise SpecError(f"{where}: non-physical inertia (eigenvalues {eig.tolist()})")
    a, b, c = eig
    if a + b < c - tol:
        raise SpecError(
            f"{where}: non-physical inertia: principal moments violate the triangle "
            f"inequality ({a:.6g} + {b:.6g} < {c:.6g})"
        )
    if mass == 0.0 and float(np.abs(inertia).max()) > 0.0:
        raise SpecError(f"{where}: mass 0 with a non-zero inertia")


def merged_inertial(parts: list[tuple[float, F64, F64]], where: str) -> Inertial:
    """Rigidly joined bodies as one inertial, in the frame their parts are given in.

    Args:
        parts: ``(mass [kg], centre of mass [m], inertia about it [kg m^2])`` per body.
        where: the link, for errors.

    Raises:
        SpecError: zero total mass or a non-physical result (naming ``where``).
    """
    total = sum(m for m, _, _ in parts)
    if total <= 0:
        raise SpecError(f"{where}: zero mass")
    centre: F64 = np.sum([m * c for m, c, _ in parts], axis=0) / total
    tensor = np.zeros((3, 3))
    for m, c, inertia in parts:
        d = c - centre
        tensor += inertia + m * (float(d @ d) * np.eye(3) - np.outer(d, d))
    check_physical(total, tensor, f"{where} (merged)")
    return Inertial(
        mass=float(total),
        com=(float(centre[0]), float(centre[1]), float(centre[2])),
        inertia=tuple((float(r[0]), float(r[1]), float(r[2])) for r in 0.5 * (tensor + tensor.T)),
    )


def link_capsules(end_m: F64, radius_m: float) -> tuple[Segment, ...]:
    """A link's planning capsule: from its frame's origin to ``end_m`` (the next joint or
    the flange, link frame [m]); none for a link that carries nothing further."""
    if float(np.linalg.norm(end_m)) <= 1e-6:
        return ()
    return (
        Segment((0.0, 0.0, 0.0), (float(end_m[0]), float(end_m[1]), float(end_m[2])), radius_m),
    )
