"""The JTC effort PID plus inverse-dynamics feed-forward, as Jazzy's JTC runs it.

Since ros2_controllers PR #1200 (Jazzy), an effort-only joint trajectory
controller adds the trajectory point's effort to its PID output, per joint:

    u = ff_velocity_scale * qd_next + effort_next + pid.compute_command(e, e_dot, dt)

with ``e = q_ref(t) - q``, ``e_dot = qd_ref(t) - qd`` (the error at the current
instant) and the feed-forward terms taken from the setpoint sampled one control
period ahead, ``t + dt`` (``command_next_``, PR #1306: "sample at t + dT"). The
effort comes from the trajectory (MoveIt fills it from its model); here it is the
nominal model's inverse dynamics along the reference,

    effort_next = RNEA_n(q_r(t + dt), qd_r(t + dt), qdd_r(t + dt)),

one Pinocchio call. The controller only sees the reference at ``t``, so the
sample at ``t + dt`` is its Taylor extrapolation with the jerk from the last two
acceleration samples: exact when the acceleration is linear over two periods,
else off by about ``snap dt^2`` (the paper's 1 s quintic at 1 kHz: at most 2e-4
N m on the UR5, against up to 3e-2 N m between the samples at ``t`` and ``t + dt``).
``ff_at_next_sample: false`` evaluates both feed-forward terms at ``t`` instead.
The PID part and its gains are ``pid``'s (same bandwidth design).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from pipeline.control import pid
from pipeline.control.controller import (
    DEFAULT_OMEGA_N_RAD_S,
    DEFAULT_ZETA,
    F64,
    FRICTION_GAINS,
    GainSpec,
    friction_feedforward,
)
from pipeline.robots.spec import RobotSpec
from pipeline.robots.urdf import build_pinocchio_model

NAME = "pid_ff"
GAINS = (*pid.GAINS, GainSpec("ff_at_next_sample", flag=True), *FRICTION_GAINS)


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """``pid``'s gains (per-joint bandwidth design), feed-forward sampled at ``t + dt``."""
    gains = pid.default_gains(spec, omega_n_rad_s=omega_n_rad_s, zeta=zeta, q_config=q_config)
    return {**gains, "ff_at_next_sample": True}


class PidFeedForwardController(pid.PidController):
    """Effort PID + nominal inverse dynamics of the reference (Jazzy JTC with efforts)."""

    NAME = NAME
    COLOR = (214, 39, 40)
    USES_NOMINAL_MODEL = True
    GAINS = GAINS
    DEFAULT_GAINS = staticmethod(default_gains)

    def __init__(
        self, spec: RobotSpec, gains: Mapping[str, Any] | None = None, *, where: str = "gains"
    ) -> None:
        spec.require_dynamics(f"the {NAME} controller")
        super().__init__(spec, gains, where=where)
        self._next: bool = self._gains["ff_at_next_sample"]
        self._model = build_pinocchio_model(spec)
        self._data = self._model.createData()
        self._qdd_prev: F64 | None = None

    def reset(self) -> None:
        """Forget the integral and the acceleration sample the jerk is taken from."""
        super().reset()
        self._qdd_prev = None

    def _sample_ahead(
        self, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float, qdd_prev: F64 | None
    ) -> tuple[F64, F64, F64]:
        if not self._next or dt_s <= 0.0:
            return q_ref, qd_ref, qdd_ref
        jerk = np.zeros_like(qdd_ref) if qdd_prev is None else (qdd_ref - qdd_prev) / dt_s
        h = dt_s
        q = q_ref + h * qd_ref + h * h / 2.0 * qdd_ref + h**3 / 6.0 * jerk
        qd = qd_ref + h * qdd_ref + h * h / 2.0 * jerk
        qdd = qdd_ref + h * jerk
        return q, qd, qdd

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        q_n, qd_n, qdd_n = self._sample_ahead(q_ref, qd_ref, qdd_ref, dt_s, self._qdd_prev)
        self._qdd_prev = np.array(qdd_ref, dtype=float)
        tau = self._pid(q, qd, q_ref, qd_ref, dt_s)
        tau += pin.rnea(self._model, self._data, q_n, qd_n, qdd_n)
        if self._use_ff:
            tau += self._ff * qd_n
        friction = friction_feedforward(self._gains, qd_n)
        if friction is not None:
            tau += friction
        return tau
