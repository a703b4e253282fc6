"""Passivity-based control (Slotine–Li) on the nominal Pinocchio model.

With ``e = q_r - q`` and a per-joint ``Lambda`` [1/s]:

    s     = (qd_r - qd) + Lambda e          sliding variable [rad/s]
    qr_d  = qd_r + Lambda e  (= qd + s)     reference velocity
    qr_dd = qdd_r + Lambda (qd_r - qd)      reference acceleration
    tau   = M_n(q) qr_dd + C_n(q, qd) qr_d + g_n(q) + Kd s

(Slotine & Li 1987; Siciliano et al., *Robotics*, eq. 8.114). ``C`` is the
Christoffel form, for which ``M' - 2 C`` is skew-symmetric: with an exact model
``M s' + (C + Kd) s = 0`` and ``V = s^T M s / 2`` decreases as ``-s^T Kd s``; ``s``
goes to 0 and then ``e' = -Lambda e``. Three RNEA calls give ``tau`` exactly:
``rnea(q, 0, qr_dd) = M qr_dd + g`` and, by polarizing the quadratic velocity term
``c(v) = rnea(q, v, 0) - g``, ``C(q, qd) qr_d = (c(qd + qr_d) - c(qd - qr_d)) / 4``
(the same as ``pin.computeCoriolisMatrix(q, qd) @ qr_d``, tested).

Gain rule (the bandwidth target ``omega_n``, ``zeta``): linearized at rest with an
exact model, each joint taken alone (``m_jj``, as ``pid``) obeys the cascade
``(d/dt + Lambda) e = s``, ``(d/dt + Kd / m_jj) s = 0``, i.e. the poles
``-Lambda`` and ``-Kd/m_jj``. They are placed at the roots of ``s^2 + 2 zeta w s +
w^2``: ``Lambda = w r``, ``Kd_j = (w / r) m_jj`` with ``r = zeta - sqrt(zeta^2 - 1)``.
At the default ``zeta = 1`` both sit at ``-w``, CTC's double pole. For ``zeta < 1``
the target's roots are complex, which the real cascade cannot produce: ``r = 1``
(both poles at ``-w``, the target's natural frequency, critically damped).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from pipeline.control.controller import (
    DEFAULT_OMEGA_N_RAD_S,
    DEFAULT_ZETA,
    F64,
    GainSpec,
    check_tuning,
    gains_as_json,
    nominal_mass_diagonal,
    resolve_tuned_gains,
)
from pipeline.robots.spec import RobotSpec
from pipeline.robots.urdf import build_pinocchio_model

NAME = "passivity"
GAINS = (
    GainSpec("lambda", unit="1/s", default="w r"),
    GainSpec("kd", unit="N m s/rad", default="(w / r) m_jj"),
)


def pole_ratio(zeta: float) -> float:
    """``r`` with ``Lambda = w r`` and ``Kd / m_jj = w / r`` (1 for ``zeta <= 1``)."""
    return zeta - math.sqrt(zeta * zeta - 1.0) if zeta > 1.0 else 1.0


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """``Lambda = w r`` [1/s], ``Kd_j = (w / r) m_jj`` [N m s/rad] (``r``: ``pole_ratio``).

    ``m_jj`` is the nominal mass-matrix diagonal at ``q_config`` (default zeros).
    """
    check_tuning(omega_n_rad_s, zeta)
    m = nominal_mass_diagonal(spec, q_config)
    w = float(omega_n_rad_s)
    r = pole_ratio(float(zeta))
    return {"lambda": [w * r] * spec.dof, "kd": (m * w / r).tolist()}


class SlotineLi:
    """The Slotine–Li signals and the Christoffel-consistent model terms, shared with
    ``adaptive``: ``s``, ``qr_d``, ``qr_dd`` from the state and the reference."""

    def __init__(self, lam: F64) -> None:
        self.lam = lam

    def signals(
        self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64
    ) -> tuple[F64, F64, F64]:
        """``(s, qr_d, qr_dd)`` [rad/s, rad/s, rad/s^2]."""
        e = q_ref - q
        ed = qd_ref - qd
        s = ed + self.lam * e
        return s, qd + s, qdd_ref + self.lam * ed


class PassivityController:
    """Slotine–Li passivity-based tracking on the nominal model (the YAML robot)."""

    NAME = NAME
    COLOR = (140, 86, 75)
    USES_NOMINAL_MODEL = True
    GAINS = GAINS
    DEFAULT_GAINS = staticmethod(default_gains)

    def __init__(
        self, spec: RobotSpec, gains: Mapping[str, Any] | None = None, *, where: str = "gains"
    ) -> None:
        spec.require_dynamics(f"the {NAME} controller")
        self._tuning, self._gains = resolve_tuned_gains(
            NAME, spec, GAINS, default_gains, gains, where=where
        )
        self._law = SlotineLi(self._gains["lambda"])
        self._kd: F64 = self._gains["kd"]
        self._model = build_pinocchio_model(spec)
        self._data = self._model.createData()
        self._zero = np.zeros(spec.dof)

    @property
    def name(self) -> str:
        return NAME

    def gains_in_effect(self) -> dict[str, Any]:
        return {**self._tuning.knobs_in_effect(), **gains_as_json(self._gains)}

    def reset(self) -> None:
        """Stateless: nothing to forget."""

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        s, qr_d, qr_dd = self._law.signals(q, qd, q_ref, qd_ref, qdd_ref)
        model, data, zero = self._model, self._data, self._zero
        tau: F64 = pin.rnea(model, data, q, zero, qr_dd).copy()  # M qr_dd + g
        tau += 0.25 * pin.rnea(model, data, q, qd + qr_d, zero)
        tau -= 0.25 * pin.rnea(model, data, q, qd - qr_d, zero)  # + C(q, qd) qr_d
        tau += self._kd * s
        return tau
