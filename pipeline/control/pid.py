"""Per-joint effort PID, as ros2_control's joint trajectory controller runs it.

With an effort command interface the JTC sends, per joint,
``ff_velocity_scale * qd_ref + pid.compute_command(e, e_dot, dt)`` with
``e = q_ref - q`` and ``e_dot = qd_ref - qd`` (control_toolbox::Pid):

- ``p_term = kp * e``, ``d_term = kd * e_dot`` (no derivative kick: the D term
  acts on the velocity error, not on a differentiated position error);
- ``i_term += ki * dt * e``; with ``antiwindup`` the *state* is clamped to
  ``[i_clamp_min, i_clamp_max]``, without it only its contribution to the
  output is (the state itself keeps winding up);
- ``command = p_term + clamp(i_term) + d_term``.

No model terms: gravity and inertia are left to the feedback and the integrator.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np
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
from pipeline.errors import ParamsError
from pipeline.robots.spec import RobotSpec

NAME = "pid"
GAINS = (
    GainSpec("kp", unit="N m/rad", stiffness=True, default="m_jj w^2"),
    GainSpec("ki", unit="N m/(rad s)", default="m_jj w^2 0.1 w"),
    GainSpec("kd", unit="N m s/rad", default="2 zeta w m_jj"),
    GainSpec("i_clamp_min", nonnegative=False, unit="N m", default="-effort limit"),
    GainSpec("i_clamp_max", nonnegative=False, unit="N m", default="effort limit"),
    GainSpec("antiwindup", flag=True, default="true"),
    GainSpec("ff_velocity_scale", nonnegative=False, unit="N m s/rad", default="0"),
)
INTEGRAL_POLE_FRACTION = 0.1
"""Default ki puts the integrator's pole near ``-0.1 omega_n`` (see docs/control.md)."""


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """Gains giving each joint, alone, the closed loop ``s^2 + 2 zeta w s + w^2``.

    ``kp_j = m_jj w^2``, ``kd_j = 2 zeta w m_jj`` with ``m_jj`` the nominal
    mass-matrix diagonal at ``q_config`` (default: zeros); ``ki_j = m_jj w^2 p``
    with ``p = 0.1 w`` (integral pole well below the PD poles); the integral
    term may supply up to the joint's effort limit.
    """
    check_tuning(omega_n_rad_s, zeta)
    m = nominal_mass_diagonal(spec, q_config)
    w = float(omega_n_rad_s)
    effort = spec.effort_limits
    return {
        "kp": (m * w**2).tolist(),
        "ki": (m * w**2 * INTEGRAL_POLE_FRACTION * w).tolist(),
        "kd": (m * 2.0 * zeta * w).tolist(),
        "i_clamp_min": (-effort).tolist(),
        "i_clamp_max": effort.tolist(),
        "antiwindup": True,
        "ff_velocity_scale": 0.0,
    }


class PidController:
    """Independent joint PID on effort (ros2_control JTC + control_toolbox::Pid).

    Variants (``pid_ff``) subclass it with their own ``NAME``, ``GAINS`` and
    ``DEFAULT_GAINS`` and add their feed-forward around ``_pid``.
    """

    NAME: ClassVar[str] = NAME
    COLOR: ClassVar[tuple[int, int, int] | None] = (31, 119, 180)
    USES_NOMINAL_MODEL: ClassVar[bool] = False
    GAINS: ClassVar[tuple[GainSpec, ...]] = GAINS
    DEFAULT_GAINS: ClassVar[Callable[..., dict[str, Any]]] = staticmethod(default_gains)

    GAINS = GAINS

    def __init__(
        self, spec: RobotSpec, gains: Mapping[str, Any] | None = None, *, where: str = "gains"
    ) -> None:
        self._tuning, g = resolve_tuned_gains(
            self.NAME, spec, self.GAINS, type(self).DEFAULT_GAINS, gains, where=where
        )
        if (g["i_clamp_min"] > g["i_clamp_max"]).any():
            raise ParamsError(
                f"{where}.i_clamp_min: must be <= i_clamp_max, got {g['i_clamp_min'].tolist()} "
                f"and {g['i_clamp_max'].tolist()}"
            )
        self._gains = g
        self._kp: F64 = g["kp"]
        self._ki: F64 = g["ki"]
        self._kd: F64 = g["kd"]
        self._i_min: F64 = g["i_clamp_min"]
        self._i_max: F64 = g["i_clamp_max"]
        self._antiwindup: bool = g["antiwindup"]
        self._ff: F64 = g["ff_velocity_scale"]
        self._use_ff = bool(self._ff.any())
        self._i_term: F64 = np.zeros(spec.dof)
        self._ki_dt: F64 = self._ki * 0.0
        self._dt_s = 0.0
        # per-step work buffers (the command is returned in ``_tau``: the caller's
        # until the next ``compute``, as the Controller protocol says)
        self._e: F64 = np.zeros(spec.dof)
        self._tmp: F64 = np.zeros(spec.dof)
        self._tau: F64 = np.zeros(spec.dof)

    @property
    def name(self) -> str:
        return self.NAME

    def gains_in_effect(self) -> dict[str, Any]:
        return {**self._tuning.knobs_in_effect(), **gains_as_json(self._gains)}

    @property
    def integral_rad(self) -> F64:
        """The integral term as the position error it stands for: its torque (or, for
        computed torque, its acceleration) over ``kp`` [rad] (0 where ``kp`` is 0). The
        settling criterion (``pipeline.sim.settling``) waits for it to stop moving."""
        i_out = np.clip(self._i_term, self._i_min, self._i_max)
        return np.divide(i_out, self._kp, out=np.zeros_like(i_out), where=self._kp != 0)

    def reset(self) -> None:
        self._i_term[:] = 0.0

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        tau = self._pid(q, qd, q_ref, qd_ref, dt_s)
        if self._use_ff:
            tau += self._ff * qd_ref
        return tau

    def _pid(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, dt_s: float) -> F64:
        """control_toolbox::Pid's command for every joint (no feed-forward).

        ``kp e + kd (qd_ref - qd) + clamp(i)`` in that order, written into preallocated
        buffers (positional ``out``: no allocation, the same operations as the plain
        expression, so the same bits).
        """
        sub, mul, add = np.subtract, np.multiply, np.add
        e = sub(q_ref, q, self._e)
        i_term, tmp = self._i_term, self._tmp
        if dt_s != self._dt_s:  # the period is fixed in an episode: scale ki once
            self._ki_dt = self._ki * dt_s
            self._dt_s = dt_s
        add(i_term, mul(self._ki_dt, e, tmp), i_term)
        if self._antiwindup:
            np.minimum(i_term, self._i_max, out=i_term)
            np.maximum(i_term, self._i_min, out=i_term)
            i_out = i_term
        else:
            i_out = np.maximum(np.minimum(i_term, self._i_max), self._i_min)
        tau = mul(self._kp, e, self._tau)
        add(tau, mul(self._kd, sub(qd_ref, qd, tmp), tmp), tau)
        add(tau, i_out, tau)
        return tau
