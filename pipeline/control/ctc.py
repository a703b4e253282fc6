"""Computed-torque control, the paper's eq. 18, on the nominal Pinocchio model.

``tau = M_n(q) (qdd_r + Kd (qd_r - qd) + Kp (q_r - q)) + h_n(q, qd)``, with
``h_n`` the nominal Coriolis, centrifugal and gravity torques. One RNEA call
with the commanded acceleration ``a`` returns exactly ``M_n(q) a + h_n(q, qd)``
(the paper used KDL's ChainIdSolver_RNE for the same quantity). With a
perfect model the closed loop is ``qdd = a``, i.e. ``e'' + Kd e' + Kp e = 0``
per joint (eq. 17).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from pipeline.control.controller import (
    DEFAULT_OMEGA_N_RAD_S,
    DEFAULT_ZETA,
    F64,
    FRICTION_GAINS,
    GainSpec,
    NominalPDController,
    check_tuning,
    friction_feedforward,
)
from pipeline.robots.spec import RobotSpec

NAME = "ctc"
GAINS = (
    GainSpec("kp", unit="1/s^2", default="w^2"),
    GainSpec("kd", unit="1/s", default="2 zeta w"),
    *FRICTION_GAINS,
)


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """``Kp = w^2`` [1/s^2], ``Kd = 2 zeta w`` [1/s]: the linearized loop's poles directly.

    ``q_config`` is accepted for a uniform signature; CTC gains do not depend on it.
    """
    check_tuning(omega_n_rad_s, zeta)
    w = float(omega_n_rad_s)
    return {"kp": [w**2] * spec.dof, "kd": [2.0 * zeta * w] * spec.dof}


class ComputedTorqueController(NominalPDController):
    """Model-based CTC; the model is always the nominal one built from the YAML."""

    NAME = NAME
    COLOR = (255, 127, 14)
    GAINS = GAINS
    DEFAULT_GAINS = staticmethod(default_gains)

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        # a = qdd_r + Kd (qd_r - qd) + Kp (q_r - q), the same operations in the same
        # order as that expression, into preallocated buffers (no per-step allocation)
        sub, mul, add = np.subtract, np.multiply, np.add
        a = add(qdd_ref, mul(self._kd, sub(qd_ref, qd, self._a), self._a), self._a)
        add(a, mul(self._kp, sub(q_ref, q, self._e), self._e), a)
        tau: F64 = pin.rnea(self._model, self._data, q, qd, a)
        if not self._friction_ff:
            return tau
        friction = friction_feedforward(self._gains, qd_ref)
        return tau if friction is None else tau + friction
