"""PD + nominal gravity + decoupled acceleration feed-forward, as a plug-in.

``tau = Kp (q_r - q) + Kd (qd_r - qd) + g_n(q) + m_ff qdd_r``: ``pd_gravity`` plus the
reference acceleration through the nominal mass-matrix diagonal at the start pose
(no coupling, no Coriolis terms: cheaper than computed torque, better than PD on a
fast motion). The class declares everything the pipeline needs: its gains (units,
default rule, which are stiffnesses), a colour and a one-line description.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pinocchio as pin

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


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: Sequence[float] | None = None,
) -> dict[str, Any]:
    """``kp = m_jj w^2``, ``kd = 2 zeta w m_jj`` (as pd_gravity), ``m_ff = m_jj``."""
    check_tuning(omega_n_rad_s, zeta)
    m = nominal_mass_diagonal(spec, q_config)
    w = float(omega_n_rad_s)
    return {"kp": (m * w**2).tolist(), "kd": (m * 2.0 * zeta * w).tolist(), "m_ff": m.tolist()}


class PdGravityAccFF(NominalPDController):
    """PD + nominal gravity + reference acceleration through diag M_n (an example plug-in)."""

    NAME = "pd_gravity_accff"
    GAINS = (
        GainSpec("kp", unit="N m/rad", stiffness=True, default="m_jj w^2"),
        GainSpec("kd", unit="N m s/rad", default="2 zeta w m_jj"),
        GainSpec("m_ff", unit="kg m^2", default="m_jj (nominal, start pose)"),
    )
    DEFAULT_GAINS = staticmethod(default_gains)
    COLOR = (23, 190, 207)
    DESCRIPTION = "PD + gravity + decoupled acceleration feed-forward (example plug-in)"

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        gravity: F64 = pin.computeGeneralizedGravity(self._model, self._data, q)
        tau: F64 = (
            self._kp * (q_ref - q)
            + self._kd * (qd_ref - qd)
            + gravity
            + self._gains["m_ff"] * qdd_ref
        )
        return tau
