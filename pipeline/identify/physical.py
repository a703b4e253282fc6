"""Physical consistency of link parameters: pseudo-inertia and its log-Cholesky map.

A link's ten inertial parameters (mass m, first moment h = m c, rotational inertia
Ibar about the link frame) are those of some rigid body with non-negative density iff
its 4x4 *pseudo-inertia* is positive semidefinite (Wensing, Kim & Slotine, RA-L 2018)::

    J = [[Sigma, h], [h^T, m]],   Sigma = tr(Ibar)/2 I3 - Ibar

Rucker & Wensing (RA-L 2022) write ``J = U U^T`` with ``U = e^alpha [[e^d1, s12, s13,
t1], [0, e^d2, s23, t2], [0, 0, e^d3, t3], [0, 0, 0, 1]]``: every real 10-vector
``(alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3)`` is a physical link (J positive
definite) and every physical link has exactly one such vector, so an unconstrained
optimizer over it never leaves the feasible set.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

LOG_BOUND = 40.0

# Pinocchio order: m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz (Ibar about the link frame)


def inertia_matrix(params: F64) -> F64:
    """The 3x3 rotational inertia about the link frame [kg m^2] of 10 dynamic parameters."""
    _, _, _, _, ixx, ixy, iyy, ixz, iyz, izz = params
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=float)


def pseudo_inertia(params: F64) -> F64:
    """The 4x4 pseudo-inertia J of 10 dynamic parameters."""
    ibar = inertia_matrix(params)
    out = np.empty((4, 4))
    out[:3, :3] = np.trace(ibar) / 2 * np.eye(3) - ibar
    out[:3, 3] = out[3, :3] = params[1:4]
    out[3, 3] = params[0]
    return out


def from_pseudo_inertia(j: F64) -> F64:
    """The 10 dynamic parameters of a pseudo-inertia (inverse of :func:`pseudo_inertia`)."""
    sigma = j[:3, :3]
    ibar = np.trace(sigma) * np.eye(3) - sigma
    return np.array(
        [j[3, 3], j[0, 3], j[1, 3], j[2, 3], ibar[0, 0], ibar[0, 1], ibar[1, 1], ibar[0, 2],
         ibar[1, 2], ibar[2, 2]]
    )  # fmt: skip


def min_eigenvalue(params: F64) -> float:
    """Smallest eigenvalue of the pseudo-inertia: > 0 for a physical link."""
    return float(np.linalg.eigvalsh(pseudo_inertia(params))[0])


def from_log_cholesky(phi: F64) -> F64:
    """The 10 dynamic parameters of a log-Cholesky vector (always physical)."""
    alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3 = phi
    u = np.array(
        [[np.exp(d1), s12, s13, t1], [0.0, np.exp(d2), s23, t2], [0.0, 0.0, np.exp(d3), t3],
         [0.0, 0.0, 0.0, 1.0]]
    ) * np.exp(alpha)  # fmt: skip
    return from_pseudo_inertia(u @ u.T)


def to_log_cholesky(params: F64) -> F64:
    """The log-Cholesky vector of a physical link's 10 dynamic parameters.

    Raises:
        ValueError: the pseudo-inertia is not positive definite.
    """
    j = pseudo_inertia(params)
    flip = j[::-1, ::-1]
    lower = np.linalg.cholesky(flip)  # raises LinAlgError (a ValueError) if not PD
    u = lower[::-1, ::-1]  # upper triangular, U U^T = J
    alpha = np.log(u[3, 3])
    v = u / u[3, 3]
    return np.array(
        [alpha, np.log(v[0, 0]), np.log(v[1, 1]), np.log(v[2, 2]), v[0, 1], v[1, 2], v[0, 2],
         v[0, 3], v[1, 3], v[2, 3]]
    )  # fmt: skip


# (row, col) of U's entry each log-Cholesky coordinate after alpha sets, and whether it is
# exponentiated (d1, d2, d3) or plain (s12, s23, s13, t1, t2, t3)
_ENTRIES = ((0, 0, True), (1, 1, True), (2, 2, True), (0, 1, False), (1, 2, False),
            (0, 2, False), (0, 3, False), (1, 3, False), (2, 3, False))  # fmt: skip


def log_cholesky_jacobian(phi: F64) -> tuple[F64, F64]:
    """The 10 dynamic parameters of ``phi`` and their (10, 10) Jacobian with respect to it."""
    # exponents beyond +-LOG_BOUND are no rigid body worth modelling (e^40 kg m^2); the
    # clip keeps an optimizer's trial step from overflowing
    alpha, d1, d2, d3 = np.clip(phi[:4], -LOG_BOUND, LOG_BOUND)
    s12, s23, s13, t1, t2, t3 = phi[4:]
    scale = np.exp(alpha)
    u = np.array(
        [[np.exp(d1), s12, s13, t1], [0.0, np.exp(d2), s23, t2], [0.0, 0.0, np.exp(d3), t3],
         [0.0, 0.0, 0.0, 1.0]]
    ) * scale  # fmt: skip
    jac = np.empty((10, 10))
    jac[:, 0] = from_pseudo_inertia(2 * u @ u.T)  # dU/dalpha = U
    for i, (r, c, exponentiated) in enumerate(_ENTRIES, start=1):
        du = np.zeros((4, 4))
        du[r, c] = u[r, c] if exponentiated else scale
        dj = du @ u.T
        jac[:, i] = from_pseudo_inertia(dj + dj.T)
    return from_pseudo_inertia(u @ u.T), jac
