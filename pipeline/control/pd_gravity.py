"""PD with nominal gravity compensation: a third baseline between PID and CTC.

``tau = Kp (q_r - q) + Kd (qd_r - qd) + g_n(q)`` with ``g_n`` from Pinocchio on
the nominal model. It removes the gravity load the PID must integrate away,
but neither feeds forward the inertial torques nor decouples the joints.
"""

from __future__ import annotations

from typing import Any

import pinocchio as pin
from numpy.typing import ArrayLike

from pipeline.control.controller import (
    DEFAULT_OMEGA_N_RAD_S,
    DEFAULT_ZETA,
    F64,
    GainSpec,
    NominalPDController,
    check_tuning,
    nominal_mass_diagonal,
)
from pipeline.robots.spec import RobotSpec

NAME = "pd_gravity"
GAINS = (
    GainSpec("kp", unit="N m/rad", stiffness=True, default="m_jj w^2"),
    GainSpec("kd", unit="N m s/rad", default="2 zeta w m_jj"),
)


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """``kp_j = m_jj w^2``, ``kd_j = 2 zeta w m_jj`` (as the PID, without the integrator)."""
    check_tuning(omega_n_rad_s, zeta)
    m = nominal_mass_diagonal(spec, q_config)
    w = float(omega_n_rad_s)
    return {"kp": (m * w**2).tolist(), "kd": (m * 2.0 * zeta * w).tolist()}


class PdGravityController(NominalPDController):
    """Joint PD plus the nominal gravity torque ``g_n(q)``."""

    NAME = NAME
    COLOR = (148, 103, 189)
    GAINS = GAINS
    DEFAULT_GAINS = staticmethod(default_gains)

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        gravity: F64 = pin.computeGeneralizedGravity(self._model, self._data, q)
        tau: F64 = self._kp * (q_ref - q) + self._kd * (qd_ref - qd) + gravity
        return tau
