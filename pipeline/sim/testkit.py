"""The controller test kit: what any controller, built-in or plug-in, must do.

``pipeline check-controller NAME`` and :func:`assert_controller_ok` (for a pytest
suite) run the same checks: the interface, output shape/dtype/finiteness, the gains in effect
as JSON naming only declared gains, refusal of an undeclared gain, determinism,
``reset()`` forgetting state, and a closed-loop stability check. It lives in ``sim/``
(not ``control/``) because the last check simulates the closed loop, and control sits
above sim in the import chain.

Every check starts from the robot's own start pose, whatever its joint count
(:func:`kit_start`): the SRDF named state ``ready`` (else the first named state the
robot defines), else the middle of each joint's limits.

The closed-loop check (:func:`_closed_loop`) holds that start pose from a perturbed
start on the *nominal* plant (the Pinocchio model the controllers are designed on,
armature included, torques clipped to the effort limits): joint ``j`` starts
``(-1)^j`` :data:`PERTURB_RAD` away, at rest. Rule: the worst joint's error must fall
by at least :data:`MIN_DECAY_RATIO` within the law's *designed settling time* and stay
there (and below :data:`BOUND_RAD`) to :data:`HORIZON_SETTLING_TIMES` settling times.
The designed settling time is the 2 % settling time of the loop the default gains
place, ``s^2 + 2 zeta w s + w^2`` with the law's ``omega_n_rad_s`` and ``zeta`` (as
its ``gains_in_effect()`` reports them, else the defaults): ``T_s = 5.83 / w`` at
``zeta = 1`` (``(1 + x) e^-x = 0.02``), ``4 / (zeta w)`` below, and the slow pole's
``-ln(0.02) / (w (zeta - sqrt(zeta^2 - 1)))`` above. The measured ratio is the finding.
A law that by design leaves a steady offset under gravity (``pid_humble``'s integral is
off by default) declares why on its class (``KIT_STEADY_OFFSET``, one line); the kit
then measures its error about its own settled pose and reports the offset.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from pipeline.control import Controller, controller_entry, make_controller
from pipeline.control.controller import (
    DEFAULT_OMEGA_N_RAD_S,
    DEFAULT_ZETA,
    F64,
    RECORDED_TUNING_KEYS,
)
from pipeline.errors import ParamsError, PipelineError
from pipeline.robots.loaders import load_spec
from pipeline.robots.spec import RobotSpec
from pipeline.robots.urdf import build_pinocchio_model

ROBOT = "ur5"
"""The kit's arm: the smallest shipped robot with dynamics."""
START_STATE = "ready"
"""The SRDF named state the kit starts from when the robot defines it."""
PERTURB_RAD = 0.1
"""The closed-loop check's initial error on every joint (alternating sign) [rad]."""
MIN_DECAY_RATIO = 10.0
"""The error must fall by at least this factor within the designed settling time."""
HORIZON_SETTLING_TIMES = 3.0
"""How long the closed loop runs, in designed settling times (bounded until then)."""
BOUND_RAD = 0.5
"""A closed loop whose error exceeds this on any joint is called unstable [rad]."""
SETTLE_FRACTION = 0.02
"""The settling-time criterion: the designed loop's error within 2 % of its start."""
DT_S = 0.001
N_STEPS = 50


@dataclass(frozen=True)
class Finding:
    """One check of the kit.

    Attributes:
        check: what was checked (``build``, ``interface``, ``output``, ``gains_in_effect``,
            ``gains``, ``determinism``, ``reset``, ``closed_loop``).
        ok: whether the controller passed.
        detail: one line; why it failed, or what was measured.
    """

    check: str
    ok: bool
    detail: str


def check_controller(
    name: str,
    *,
    gains: Mapping[str, Any] | None = None,
    robot: str | RobotSpec = ROBOT,
    closed_loop: bool = True,
) -> list[Finding]:
    """Run every check on controller ``name`` (a built-in, entry point or ``module:Object``).

    Args:
        name: the controller's name, as params would give it.
        gains: gains to build it with (default: its defaults).
        robot: robot name or spec (default: :data:`ROBOT`).
        closed_loop: also run the short MuJoCo episode.

    Returns:
        One finding per check; a controller that cannot be built gets one ``build`` finding.
    """
    spec = load_spec(robot) if isinstance(robot, str) else robot
    try:
        entry = controller_entry(name)

        def build() -> Controller:
            return make_controller(name, spec, gains)

        ctl = build()
    except PipelineError as err:
        return [Finding("build", False, str(err))]
    except Exception as err:
        return [Finding("build", False, f"constructor raised {type(err).__name__}: {err}")]
    declared = {g.key for g in entry.gain_specs}
    out = [Finding("build", True, f"{entry.summary or name} ({spec.name}, {spec.dof} joints)")]
    out.append(_guard("interface", lambda: _interface(ctl)))
    if not out[-1].ok:
        return out
    out.append(_guard("output", lambda: _output(ctl, spec)))
    out.append(_guard("gains_in_effect", lambda: _gains_in_effect(ctl, declared)))
    out.append(_guard("gains", lambda: _refuses_undeclared(name, spec)))
    out.append(_guard("determinism", lambda: _determinism(build, spec)))
    out.append(_guard("reset", lambda: _reset(build, spec)))
    if closed_loop:
        out.append(
            _guard("closed_loop", lambda: _closed_loop(_build_at_start(name, spec, gains), spec))
        )
    return out


def assert_controller_ok(
    name: str, *, gains: Mapping[str, Any] | None = None, robot: str | RobotSpec = ROBOT
) -> None:
    """Fail (``AssertionError``) listing every check controller ``name`` does not pass."""
    failed = [f for f in check_controller(name, gains=gains, robot=robot) if not f.ok]
    assert not failed, f"controller '{name}': " + "; ".join(
        f"{f.check}: {f.detail}" for f in failed
    )


class _Fail(Exception):
    """A check's failure, with its one-line reason."""


def _guard(check: str, run: Callable[[], str]) -> Finding:
    try:
        return Finding(check, True, run())
    except _Fail as err:
        return Finding(check, False, str(err))
    except Exception as err:
        return Finding(check, False, f"raised {type(err).__name__}: {err}")


def _interface(ctl: Controller) -> str:
    for attr in ("gains_in_effect", "reset", "compute"):
        if not callable(getattr(ctl, attr, None)):
            raise _Fail(f"no method {attr}()")
    if not isinstance(getattr(ctl, "name", None), str):
        raise _Fail(f"name must be a str, got {getattr(ctl, 'name', None)!r}")
    return f"name '{ctl.name}'"


def _inputs(spec: RobotSpec, n: int, seed: int) -> list[tuple[F64, F64, F64, F64, F64]]:
    """``n`` control instants near the start pose, with a persistent tracking error."""
    rng = np.random.default_rng(seed)
    start = kit_start(spec)
    rows = []
    for _ in range(n):
        q = start + rng.normal(0.0, 0.05, spec.dof)
        rows.append(
            (
                q,
                rng.normal(0.0, 0.1, spec.dof),
                q + 0.05 + rng.normal(0.0, 0.01, spec.dof),
                rng.normal(0.0, 0.1, spec.dof),
                rng.normal(0.0, 0.5, spec.dof),
            )
        )
    return rows


def _run(ctl: Controller, rows: list[tuple[F64, F64, F64, F64, F64]]) -> F64:
    return np.array([np.array(ctl.compute(*row, DT_S), dtype=float) for row in rows])


def _output(ctl: Controller, spec: RobotSpec) -> str:
    ctl.reset()
    for k, row in enumerate(_inputs(spec, 5, seed=1)):
        tau = ctl.compute(*row, DT_S)
        if not isinstance(tau, np.ndarray):
            raise _Fail(f"compute() returned {type(tau).__name__}, expected a numpy array")
        if tau.shape != (spec.dof,):
            raise _Fail(f"compute() returned shape {tau.shape}, expected ({spec.dof},)")
        if tau.dtype != np.float64:
            raise _Fail(f"compute() returned dtype {tau.dtype}, expected float64")
        if not np.isfinite(tau).all():
            raise _Fail(f"compute() returned non-finite torque at call {k}: {tau.tolist()}")
    return f"({spec.dof},) float64, finite"


def _gains_in_effect(ctl: Controller, declared: set[str]) -> str:
    gains = ctl.gains_in_effect()
    if not isinstance(gains, dict):
        raise _Fail(f"gains_in_effect() returned {type(gains).__name__}, expected a dict")
    try:
        json.dumps(gains, allow_nan=False)
    except (TypeError, ValueError) as err:
        raise _Fail(f"gains_in_effect() is not JSON-serializable: {err}") from err
    # REPORTS: facts that are not gains (a warning, final estimates), declared by the class
    reports = set(getattr(type(ctl), "REPORTS", ()))
    undeclared = sorted(set(gains) - declared - reports - set(RECORDED_TUNING_KEYS))
    if undeclared:
        raise _Fail(
            f"gains_in_effect() reports gains it does not declare: {', '.join(undeclared)} "
            f"(declared: {', '.join(sorted(declared))})"
        )
    return f"{len(gains)} keys, JSON"


def _refuses_undeclared(name: str, spec: RobotSpec) -> str:
    try:
        make_controller(name, spec, {"undeclared_gain": 1.0})
    except ParamsError:
        return "refuses 'undeclared_gain'"
    raise _Fail("accepted a gain it does not declare ('undeclared_gain')")


def _determinism(build: Callable[[], Controller], spec: RobotSpec) -> str:
    rows = _inputs(spec, N_STEPS, seed=2)
    a, b = build(), build()
    a.reset()
    b.reset()
    ta, tb = _run(a, rows), _run(b, rows)
    if not np.array_equal(ta, tb):
        worst = float(np.max(np.abs(ta - tb)))
        raise _Fail(f"two fresh instances differ on the same inputs by up to {worst:.3g} N m")
    return f"{N_STEPS} steps identical"


def _reset(build: Callable[[], Controller], spec: RobotSpec) -> str:
    rows = _inputs(spec, N_STEPS, seed=3)
    fresh = build()
    fresh.reset()
    expected = _run(fresh, rows)
    used = build()
    used.reset()
    _run(used, _inputs(spec, N_STEPS, seed=4))
    used.reset()
    got = _run(used, rows)
    if not np.array_equal(got, expected):
        worst = float(np.max(np.abs(got - expected)))
        raise _Fail(f"after reset() the output differs from a fresh one by up to {worst:.3g} N m")
    return "reset() equals a fresh controller"


def kit_start(spec: RobotSpec) -> F64:
    """The kit's start pose [rad]: the SRDF named state :data:`START_STATE` if the robot
    defines it, else its first named state, else the middle of each joint's limits."""
    states = dict(spec.named_states)
    if states:
        name = START_STATE if START_STATE in states else spec.named_states[0][0]
        return np.array(spec.named_state(name), dtype=float)
    lower, upper = spec.lower, spec.upper
    mid: F64 = np.where(np.isfinite(lower) & np.isfinite(upper), 0.5 * (lower + upper), 0.0)
    return mid


def designed_settling_s(gains: Mapping[str, Any]) -> float:
    """The law's designed settling time [s]: the 2 % settling time of its slowest
    designed pole.

    The PD pair ``s^2 + 2 zeta w s + w^2`` of its tuning knobs (``omega_n_rad_s``,
    ``zeta`` in its gains in effect, else the defaults): ``5.83 / w`` at ``zeta = 1``
    (``(1 + x) e^-x = 0.02``), ``3.91 / (zeta w)`` below, ``3.91 / (w (zeta - sqrt(zeta^2
    - 1)))`` above. A law with an integral gain adds the PI zero ``ki / kp`` (the pole the
    integrator's mode settles to, from below): ``3.91 / min_j(ki_j / kp_j)`` when longer.
    """
    w = float(gains.get("omega_n_rad_s", DEFAULT_OMEGA_N_RAD_S))
    zeta = float(gains.get("zeta", DEFAULT_ZETA))
    x = -math.log(SETTLE_FRACTION)  # one real pole: e^-x = 2 %
    if zeta < 1.0:
        t_s = x / (zeta * w)
    elif zeta == 1.0:
        # double pole: (1 + x) e^-x = 2 %, by Newton from the single pole's x
        y = x
        for _ in range(50):
            y -= ((1.0 + y) * math.exp(-y) - SETTLE_FRACTION) / (-y * math.exp(-y))
        t_s = y / w
    else:
        t_s = x / (w * (zeta - math.sqrt(zeta * zeta - 1.0)))
    kp, ki = gains.get("kp"), gains.get("ki")
    if isinstance(kp, list) and isinstance(ki, list) and len(kp) == len(ki):
        zeros = [i / p for p, i in zip(kp, ki, strict=True) if p > 0 and i > 0]
        if zeros:
            t_s = max(t_s, x / min(zeros))
    return t_s


def _nominal_closed_loop(
    ctl: Controller, spec: RobotSpec, *, q0: F64, q_ref: F64, duration_s: float
) -> F64:
    """Errors ``q_ref - q`` [rad], one row per control period, of ``ctl`` holding ``q_ref``
    on the nominal Pinocchio plant from ``q0`` at rest (semi-implicit Euler at
    :data:`DT_S`, torque clipped to the effort limits); stops early once non-finite or
    past ten times :data:`BOUND_RAD`."""
    model = build_pinocchio_model(spec)
    data = model.createData()
    limit = spec.effort_limits
    zero = np.zeros(spec.dof)
    q, qd = q0.astype(float).copy(), zero.copy()
    rows = []
    ctl.reset()
    for _ in range(round(duration_s / DT_S) + 1):
        err = q_ref - q
        rows.append(err)
        if not np.isfinite(err).all() or np.abs(err).max() > 10.0 * BOUND_RAD:
            break
        tau = np.clip(np.asarray(ctl.compute(q, qd, q_ref, zero, zero, DT_S), float), -limit, limit)
        qdd = pin.aba(model, data, q, qd, tau)
        qd = qd + DT_S * qdd
        q = q + DT_S * qd
    return np.array(rows)


def _build_at_start(name: str, spec: RobotSpec, gains: Mapping[str, Any] | None) -> Controller:
    """Controller ``name`` with the given gains, else its default gains designed at the
    kit's start pose (``default_gains(..., q_config=start)``): the inertia-scaled laws'
    bandwidth then holds where the check runs, not only at q = 0."""
    if gains is None:
        entry = controller_entry(name)
        gains = entry.default_gains(
            spec, omega_n_rad_s=DEFAULT_OMEGA_N_RAD_S, zeta=DEFAULT_ZETA, q_config=kit_start(spec)
        )
    return make_controller(name, spec, gains)


def _closed_loop(ctl: Controller, spec: RobotSpec) -> str:
    t_s = designed_settling_s(ctl.gains_in_effect())
    horizon_s = HORIZON_SETTLING_TIMES * t_s
    start = kit_start(spec)
    sign = np.where(np.arange(spec.dof) % 2 == 0, 1.0, -1.0)
    err = _nominal_closed_loop(
        ctl, spec, q0=start + PERTURB_RAD * sign, q_ref=start, duration_s=horizon_s
    )
    where = f"{PERTURB_RAD} rad perturbed start on nominal {spec.name}"
    if not np.isfinite(err).all() or np.abs(err).max() > BOUND_RAD:
        bad = np.where(np.isfinite(err), np.abs(err), np.inf)
        k, j = np.unravel_index(int(bad.argmax()), bad.shape)
        raise _Fail(
            f"unstable: error {float(bad[k, j]):.3g} rad on joint {j + 1} > {BOUND_RAD} rad "
            f"at {k * DT_S:.3g} s ({where})"
        )
    reason = getattr(type(ctl), "KIT_STEADY_OFFSET", "")
    offset = err[-1].copy() if reason else np.zeros(spec.dof)
    dev = np.abs(err - offset)
    k_s = round(t_s / DT_S)
    e0 = float(dev[0].max())
    late = float(dev[k_s:].max())
    ratio = e0 / late if late > 0 else math.inf
    about = f", about its settled offset {float(np.abs(offset).max()):.3g} rad" if reason else ""
    measured = (
        f"error fell {ratio:.3g}x (from {e0:.3g} to at most {late:.3g} rad{about}) between 0 "
        f"and {t_s:.3g} s, the designed settling time, until {horizon_s:.3g} s ({where})"
    )
    if not ratio >= MIN_DECAY_RATIO:
        raise _Fail(f"not stable enough: {measured}; expected at least {MIN_DECAY_RATIO:g}x")
    return measured
