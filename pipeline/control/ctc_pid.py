"""Computed torque with integral action: eq. 18 with a PID outer loop, and anti-windup.

``tau = M_n(q) a + h_n(q, qd)`` (one RNEA call, as ``ctc``) with the outer loop

    a = qdd_r + Kd e' + Kp e + Ki z,   z' = e,   |z_j| <= i_clamp_j

where ``e = q_r - q`` and ``z`` is the integral of the error [rad s]. With a
perfect model ``qdd = a``, so per joint ``e''' + Kd e'' + Kp e' + Ki e = 0``.
Under model mismatch (payload, friction, link parameters) eq. 18 leaves a
steady-state error ``e = M_n^-1 (h_plant - h_n) / Kp``; the integral removes
it, which is why practitioners add it.

Anti-windup clamps the integral *state* per joint (as control_toolbox's
``antiwindup: true``): ``z += e dt``, then ``z = clip(z, -i_clamp, i_clamp)``,
then the output uses the clamped ``z``.
"""

from __future__ import annotations

from collections.abc import Mapping
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
    nominal_mass_diagonal,
)
from pipeline.control.pid import INTEGRAL_POLE_FRACTION
from pipeline.robots.spec import RobotSpec

NAME = "ctc_pid"
GAINS = (
    GainSpec("kp", unit="1/s^2", default="w^2 + 2 zeta w p"),
    GainSpec("kd", unit="1/s", default="2 zeta w + p"),
    GainSpec("ki", unit="1/s^3", default="p w^2, p = 0.1 w"),
    GainSpec("i_clamp", unit="rad s", default="0.5 effort_j / (m_jj ki)"),
    *FRICTION_GAINS,
)
INTEGRAL_EFFORT_FRACTION = 0.5
"""Default clamp: the integral may ask for at most this share of a joint's effort limit."""


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """Gains placing the linearized loop's poles at ``(s + p)(s^2 + 2 zeta w s + w^2)``.

    Expanding, ``s^3 + (2 zeta w + p) s^2 + (w^2 + 2 zeta w p) s + p w^2``; matching
    ``s^3 + Kd s^2 + Kp s + Ki`` gives ``Kd = 2 zeta w + p`` [1/s], ``Kp = w^2 + 2 zeta
    w p`` [1/s^2] and ``Ki = p w^2`` [1/s^3], with ``p = 0.1 w`` (the PID's integral
    pole fraction): the PD pair stays at ``w`` and the integrator adds a slow pole a
    decade below it.

    The clamp ``i_clamp_j`` [rad s] lets the integral command at most
    ``INTEGRAL_EFFORT_FRACTION`` of the joint's effort limit through the nominal
    inertia at ``q_config``: ``m_jj Ki i_clamp_j = 0.5 effort_j``. Half the torque
    authority covers any model error the arm can hold against at all, and leaves
    the other half to the PD and feed-forward terms (the PID lets its integral take
    the whole effort limit, having no model terms). The clamp does not follow an
    overridden ``ki``: give ``i_clamp`` too.
    """
    check_tuning(omega_n_rad_s, zeta)
    w = float(omega_n_rad_s)
    p = INTEGRAL_POLE_FRACTION * w
    ki = p * w**2
    m = nominal_mass_diagonal(spec, q_config)
    i_clamp = INTEGRAL_EFFORT_FRACTION * spec.effort_limits / (m * ki)
    return {
        "kp": [w**2 + 2.0 * zeta * w * p] * spec.dof,
        "kd": [2.0 * zeta * w + p] * spec.dof,
        "ki": [ki] * spec.dof,
        "i_clamp": i_clamp.tolist(),
    }


class ComputedTorquePidController(NominalPDController):
    """CTC whose outer loop is a PID with a clamped integral state."""

    NAME = NAME
    COLOR = (44, 160, 44)
    GAINS = GAINS
    DEFAULT_GAINS = staticmethod(default_gains)

    def __init__(
        self, spec: RobotSpec, gains: Mapping[str, Any] | None = None, *, where: str = "gains"
    ) -> None:
        super().__init__(spec, gains, where=where)
        self._ki: F64 = self._gains["ki"]
        self._i_clamp: F64 = self._gains["i_clamp"]
        self._i_clamp_low: F64 = -self._i_clamp
        self._integral: F64 = np.zeros(spec.dof)
        self._tmp: F64 = np.zeros(spec.dof)

    @property
    def integral_rad_s(self) -> F64:
        """A copy of the (clamped) integral of the position error [rad s]."""
        return self._integral.copy()

    @property
    def integral_rad(self) -> F64:
        """The integral term as the position error it stands for: its torque (or, for
        computed torque, its acceleration) over ``kp`` [rad] (0 where ``kp`` is 0). The
        settling criterion (``pipeline.sim.settling``) waits for it to stop moving."""
        a = self._ki * self._integral
        return np.divide(a, self._kp, out=np.zeros_like(a), where=self._kp != 0)

    def reset(self) -> None:
        """Forget the integral."""
        self._integral[:] = 0.0

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        # z += e dt, clip z; a = qdd_r + Kd (qd_r - qd) + Kp e + Ki z: the same operations
        # in the same order as those expressions, into preallocated buffers
        sub, mul, add = np.subtract, np.multiply, np.add
        e, z, a, tmp = self._e, self._integral, self._a, self._tmp
        sub(q_ref, q, e)
        add(z, mul(e, dt_s, tmp), z)
        z.clip(self._i_clamp_low, self._i_clamp, z)  # np.clip's own ufunc, without its wrapper
        add(qdd_ref, mul(self._kd, sub(qd_ref, qd, a), a), a)
        add(a, mul(self._kp, e, tmp), a)
        add(a, mul(self._ki, z, tmp), a)
        tau: F64 = pin.rnea(self._model, self._data, q, qd, a)
        if not self._friction_ff:
            return tau
        friction = friction_feedforward(self._gains, qd_ref)
        return tau if friction is None else tau + friction
