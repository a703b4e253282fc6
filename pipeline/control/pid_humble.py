"""The effort PID exactly as ROS 2 Humble's joint trajectory controller runs it.

Humble's JTC (ros2_controllers ``humble``) builds one ``control_toolbox::Pid``
per joint as ``Pid(p, i, d, i_clamp, -i_clamp)``: the ``antiwindup`` argument is
not passed, so it is ``false``, and ``i_clamp`` (a JTC parameter) defaults to
``0.0``. control_toolbox 3.x (``humble``) then computes

    i_error += dt * e;  i_term = clamp(i * i_error, -i_clamp, i_clamp)
    command = p * e + i_term + d * e_dot      (0 when dt == 0)

and the JTC sends ``ff_velocity_scale * qd_ref(t) + command`` (no effort
feed-forward; the setpoint is sampled at ``t``). With the default ``i_clamp = 0``
the integral contributes nothing: a Humble JTC left at its defaults is a PD
controller, and an arm under gravity sags by ``g / kp``. The controller says so
once (a ``IntegralOffWarning``) and in its ``gains_in_effect()`` (``warning``).

The gains ``kp``, ``kd`` and ``ki`` follow ``pid``'s bandwidth design (Humble's own
defaults are 0 for all three); ``i_clamp`` and the absent anti-windup are Humble's.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pipeline.control import pid
from pipeline.control.controller import (
    DEFAULT_OMEGA_N_RAD_S,
    DEFAULT_ZETA,
    F64,
    GainSpec,
    gains_as_json,
    resolve_tuned_gains,
)
from pipeline.robots.spec import RobotSpec

NAME = "pid_humble"
_PID_GAINS = {g.key: g for g in pid.GAINS}
GAINS = (
    _PID_GAINS["kp"],
    _PID_GAINS["ki"],
    _PID_GAINS["kd"],
    GainSpec("i_clamp", unit="N m", default="0 (Humble: integral off)"),
    _PID_GAINS["ff_velocity_scale"],
)
INTEGRAL_OFF = (
    "pid_humble: i_clamp = 0 on {joints} (Humble's JTC default) switches the integral "
    "off there; the arm holds against gravity with kp alone (set gains.i_clamp to enable it)"
)


class IntegralOffWarning(UserWarning):
    """A Humble PID whose integral clamp is 0: its integral term does nothing."""


_warned = False


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """``pid``'s ``kp``, ``ki``, ``kd``; Humble's ``i_clamp = 0`` and ``ff_velocity_scale = 0``."""
    g = pid.default_gains(spec, omega_n_rad_s=omega_n_rad_s, zeta=zeta, q_config=q_config)
    return {
        "kp": g["kp"],
        "ki": g["ki"],
        "kd": g["kd"],
        "i_clamp": 0.0,
        "ff_velocity_scale": 0.0,
    }


class PidHumbleController:
    """Humble JTC + control_toolbox 3.x ``Pid``: no anti-windup, output-clamped integral."""

    NAME = NAME
    COLOR = (23, 190, 207)
    USES_NOMINAL_MODEL = False
    GAINS = GAINS
    REPORTS = ("warning",)  # gains_in_effect() says when the integral is off (not a gain)
    KIT_STEADY_OFFSET = (
        "i_clamp = 0 (Humble's default) switches the integral off: under gravity the arm "
        "settles g / kp away from the reference"
    )
    """Why the controller test kit measures this law's error about its settled pose."""
    DEFAULT_GAINS = staticmethod(default_gains)

    def __init__(
        self, spec: RobotSpec, gains: Mapping[str, Any] | None = None, *, where: str = "gains"
    ) -> None:
        self._tuning, g = resolve_tuned_gains(NAME, spec, GAINS, default_gains, gains, where=where)
        self._gains = g
        self._kp: F64 = g["kp"]
        self._ki: F64 = g["ki"]
        self._kd: F64 = g["kd"]
        self._i_clamp: F64 = g["i_clamp"]
        self._ff: F64 = g["ff_velocity_scale"]
        self._i_error: F64 = np.zeros(spec.dof)  # integral of e [rad s]
        off = (self._i_clamp == 0.0) & (self._ki != 0.0)
        self._warning = ""
        if off.any():
            joints = "all joints" if off.all() else ", ".join(np.array(spec.joint_names)[off])
            self._warning = INTEGRAL_OFF.format(joints=joints)
            _warn_once(self._warning)

    @property
    def name(self) -> str:
        return NAME

    @property
    def integral_on(self) -> bool:
        """Whether the integral term can act on any joint (``ki != 0`` and ``i_clamp > 0``)."""
        return bool(((self._i_clamp > 0.0) & (self._ki != 0.0)).any())

    def gains_in_effect(self) -> dict[str, Any]:
        out = {**self._tuning.knobs_in_effect(), **gains_as_json(self._gains)}
        if self._warning:
            out["warning"] = self._warning
        return out

    @property
    def integral_rad(self) -> F64:
        """The integral term as the position error it stands for: its torque (or, for
        computed torque, its acceleration) over ``kp`` [rad] (0 where ``kp`` is 0). The
        settling criterion (``pipeline.sim.settling``) waits for it to stop moving."""
        i_term = np.clip(self._ki * self._i_error, -self._i_clamp, self._i_clamp)
        return np.divide(i_term, self._kp, out=np.zeros_like(i_term), where=self._kp != 0)

    def reset(self) -> None:
        self._i_error[:] = 0.0

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        tau: F64 = self._ff * qd_ref
        if dt_s == 0.0:  # control_toolbox 3.x returns 0 for a zero period
            return tau
        e = q_ref - q
        self._i_error += dt_s * e
        i_term = np.clip(self._ki * self._i_error, -self._i_clamp, self._i_clamp)
        tau += self._kp * e + self._kd * (qd_ref - qd) + i_term
        return tau


def _warn_once(message: str) -> None:
    global _warned
    if not _warned:
        _warned = True
        warnings.warn(message, IntegralOffWarning, stacklevel=3)
