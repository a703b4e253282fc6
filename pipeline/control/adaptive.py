"""Adaptive Slotine–Li control: the passivity law with on-line inertial parameter estimates.

The passivity law's model terms are linear in the inertial parameters,
``M qr_dd + C(q, qd) qr_d + g = Y(q, qd, qr_d, qr_dd) theta``; the controller keeps an
estimate ``theta_hat`` and (signals ``s``, ``qr_d``, ``qr_dd`` and gains ``Lambda``,
``Kd`` exactly as ``passivity``, same bandwidth rule):

    tau           = Y theta_hat + Kd s
    theta_hat'    = Gamma Y^T s,        then projected onto a box around nominal

With ``s = qr_d - qd`` (error-positive, as here) the update is ``+Gamma Y^T s``;
Slotine & Li write ``-Gamma Y^T s`` for ``s = qd - qr_d``: the same law. With the true
parameters in the box, ``V = s^T M s / 2 + (theta_hat - theta)^T Gamma^-1 (theta_hat -
theta) / 2`` gives ``V' = -s^T Kd s`` (the projection only removes energy).

What is implemented, precisely:

- ``theta`` per link: Pinocchio's 10 dynamic parameters ``(m, m c_x, m c_y, m c_z,
  I_xx, I_xy, I_yy, I_xz, I_yz, I_zz)`` (inertia about the joint frame), then one
  rotor armature per joint: ``11 n`` parameters. It starts at the nominal model's.
  Friction is not modelled (``Kd s`` absorbs it; it biases the estimates).
- ``Y`` is exact for the Christoffel ``C``, from ``pin.computeJointTorqueRegressor``
  (``Y_p(q, v, a) pi = rnea(q, v, a)`` without armature) by polarization of the
  quadratic velocity term (gravity cancels in the difference):
  ``Y = [Y_p(q, 0, qr_dd) + (Y_p(q, qd + qr_d, 0) - Y_p(q, qd - qr_d, 0)) / 4,
  diag(qr_dd)]``. At the nominal ``theta`` it reproduces ``passivity`` (tested).
- The update is forward Euler over the control period, after ``tau`` is computed.
- ``Gamma = diag(gamma_j delta_i^2)`` for the parameters of link ``j``: ``delta_i`` the
  half-width of parameter ``i``'s box, ``gamma_j`` [1/J] a per-joint gain. Scaling by
  ``delta^2`` makes the rate dimensionally consistent (``delta^2 / Gamma`` is an
  energy, ``1 / gamma``) and equal across parameters of different units.
- Box (the projection, exact for a diagonal ``Gamma``): nominal ``+-box_rel`` times a
  scale per parameter: the mass ``m0`` (so the mass stays ``>= (1 - box_rel) m0 > 0``),
  the first moments ``m0 l`` with ``l = max(|c0|, 0.05 m)``, the inertia entries
  ``trace(I0) / 3`` (joint frame), the armature ``a0``. Physical consistency of the
  estimated inertia (positive definite, triangle inequality) is not enforced.

``estimates()`` returns ``theta_hat``; ``estimate_history()`` every ``HISTORY_EVERY``-th
control step's; ``gains_in_effect()`` adds the final per-link mass and armature estimates
(``estimates``), so a recording holds where the adaptation ended.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from pipeline.control import passivity
from pipeline.control.controller import (
    DEFAULT_OMEGA_N_RAD_S,
    DEFAULT_ZETA,
    F64,
    GainSpec,
    gains_as_json,
    resolve_tuned_gains,
)
from pipeline.errors import ParamsError
from pipeline.robots.spec import RobotSpec
from pipeline.robots.urdf import build_pinocchio_model

NAME = "adaptive"
GAINS = (
    *passivity.GAINS,
    GainSpec("gamma", unit="1/J", default="1 (scaled per parameter)"),
    GainSpec("box_rel", unit="1", default="0.5"),
)
PARAMS_PER_LINK = 10
DEFAULT_GAMMA_PER_J = 1.0
"""Default adaptation gain ``gamma_j`` [1/J] (see the module docstring)."""
DEFAULT_BOX_REL = 0.5
"""Default box half-width, relative to each parameter's scale."""
MIN_LEVER_M = 0.05
"""Smallest lever arm [m] scaling a link's first-moment box."""
HISTORY_EVERY = 10
"""Keep the estimates of every this many control steps (``estimate_history``)."""


def default_gains(
    spec: RobotSpec,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """``passivity``'s ``lambda`` and ``kd``; ``gamma = 1 /J``, ``box_rel = 0.5``."""
    g = passivity.default_gains(spec, omega_n_rad_s=omega_n_rad_s, zeta=zeta, q_config=q_config)
    return {**g, "gamma": DEFAULT_GAMMA_PER_J, "box_rel": DEFAULT_BOX_REL}


def nominal_parameters(model: pin.Model) -> F64:
    """``theta`` of a Pinocchio model: 10 per link, then the armature per joint."""
    links = [model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)]
    return np.concatenate([*links, np.asarray(model.armature, dtype=float)])


def parameter_scales(theta0: F64, dof: int) -> F64:
    """Per-parameter scale of the box (mass, first moments, inertia, armature)."""
    scale = np.empty_like(theta0)
    for j in range(dof):
        p = theta0[PARAMS_PER_LINK * j : PARAMS_PER_LINK * (j + 1)]
        mass = p[0]
        lever = max(float(np.linalg.norm(p[1:4])) / mass if mass > 0 else 0.0, MIN_LEVER_M)
        inertia = (p[4] + p[6] + p[9]) / 3.0
        s = scale[PARAMS_PER_LINK * j : PARAMS_PER_LINK * (j + 1)]
        s[0] = mass
        s[1:4] = mass * lever
        s[4:] = inertia
    scale[PARAMS_PER_LINK * dof :] = np.abs(theta0[PARAMS_PER_LINK * dof :])
    return scale


class AdaptiveController:
    """Slotine–Li adaptive control with a projected gradient update of ``theta_hat``."""

    NAME = NAME
    COLOR = (227, 119, 194)
    USES_NOMINAL_MODEL = True
    GAINS = GAINS
    REPORTS = ("estimates",)  # gains_in_effect() also holds the final estimates (not a gain)
    DEFAULT_GAINS = staticmethod(default_gains)

    def __init__(
        self, spec: RobotSpec, gains: Mapping[str, Any] | None = None, *, where: str = "gains"
    ) -> None:
        spec.require_dynamics(f"the {NAME} controller")
        self._tuning, g = resolve_tuned_gains(NAME, spec, GAINS, default_gains, gains, where=where)
        if (g["box_rel"] >= 1.0).any():
            raise ParamsError(
                f"{where}.box_rel: must be < 1 (a link mass must stay positive), "
                f"got {g['box_rel'].tolist()}"
            )
        self._gains = g
        self._law = passivity.SlotineLi(g["lambda"])
        self._kd: F64 = g["kd"]
        self._model = build_pinocchio_model(spec)
        self._data = self._model.createData()
        n = spec.dof
        self._n = n
        self._zero = np.zeros(n)
        self._theta0 = nominal_parameters(self._model)
        half = parameter_scales(self._theta0, n) * np.concatenate(
            [np.repeat(g["box_rel"], PARAMS_PER_LINK), g["box_rel"]]
        )
        self._lower: F64 = self._theta0 - half
        self._upper: F64 = self._theta0 + half
        per_joint_gamma = np.concatenate([np.repeat(g["gamma"], PARAMS_PER_LINK), g["gamma"]])
        self._gamma: F64 = per_joint_gamma * half**2
        self._theta: F64 = self._theta0.copy()
        self._y: F64 = np.zeros((n, self._theta0.size))
        self._rows = np.arange(n)
        self._armature_cols = PARAMS_PER_LINK * n + self._rows
        self._steps = 0
        self._history: list[F64] = []

    @property
    def name(self) -> str:
        return NAME

    def gains_in_effect(self) -> dict[str, Any]:
        n, p = self._n, PARAMS_PER_LINK
        estimates = {
            "mass_kg": [float(x) for x in self._theta[0 : n * p : p]],
            "armature_kg_m2": [float(x) for x in self._theta[n * p :]],
        }
        return {
            **self._tuning.knobs_in_effect(),
            **gains_as_json(self._gains),
            "estimates": estimates,
        }

    def reset(self) -> None:
        """Back to the nominal parameters; forget the history."""
        self._theta[:] = self._theta0
        self._steps = 0
        self._history = []

    def estimates(self) -> F64:
        """A copy of ``theta_hat``: 10 per link (Pinocchio's order), then the armature."""
        return self._theta.copy()

    def nominal(self) -> F64:
        """A copy of the nominal ``theta`` (the estimates' start)."""
        return self._theta0.copy()

    def bounds(self) -> tuple[F64, F64]:
        """Copies of the projection box's lower and upper corners."""
        return self._lower.copy(), self._upper.copy()

    def estimate_history(self) -> F64:
        """``(K, 11 n)``: ``theta_hat`` after every ``HISTORY_EVERY``-th control step."""
        if not self._history:
            return np.empty((0, self._theta.size))
        return np.array(self._history)

    def regressor(self, q: F64, qd: F64, qr_d: F64, qr_dd: F64) -> F64:
        """``Y(q, qd, qr_d, qr_dd)`` with ``Y theta = M qr_dd + C(q, qd) qr_d + g`` (a view)."""
        model, data, zero, n = self._model, self._data, self._zero, self._n
        y = self._y
        inertial = pin.computeJointTorqueRegressor(model, data, q, zero, qr_dd)
        plus = pin.computeJointTorqueRegressor(model, data, q, qd + qr_d, zero)
        minus = pin.computeJointTorqueRegressor(model, data, q, qd - qr_d, zero)
        y[:, : PARAMS_PER_LINK * n] = inertial + 0.25 * (plus - minus)
        y[self._rows, self._armature_cols] = qr_dd
        return y

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        s, qr_d, qr_dd = self._law.signals(q, qd, q_ref, qd_ref, qdd_ref)
        y = self.regressor(q, qd, qr_d, qr_dd)
        tau: F64 = y @ self._theta + self._kd * s
        theta = self._theta
        theta += dt_s * self._gamma * (y.T @ s)
        np.minimum(theta, self._upper, out=theta)  # the projection (diagonal Gamma)
        np.maximum(theta, self._lower, out=theta)
        self._steps += 1
        if self._steps % HISTORY_EVERY == 0:
            self._history.append(theta.copy())
        return tau
