"""The controller test kit: what any controller, built-in or plug-in, must do.

``pipeline check-controller NAME`` and :func:`assert_controller_ok` (for a pytest
suite) run the same checks: the interface, output shape/dtype/finiteness, the gains in effect
as JSON naming only declared gains, refusal of an undeclared gain, determinism,
``reset()`` forgetting state, and a short closed-loop episode on a small arm that
stays bounded. It lives in ``sim/`` (not ``control/``) because the last check runs
the closed loop, and control sits above sim in the import chain.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.control import Controller, controller_entry, make_controller
from pipeline.control.base import F64, RECORDED_TUNING_KEYS
from pipeline.errors import ParamsError, PipelineError
from pipeline.robots.loaders import load_spec
from pipeline.robots.spec import RobotSpec
from pipeline.sim.references import PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode

ROBOT = "ur5"
"""The kit's arm: the smallest shipped robot with dynamics."""
STEP_RAD = 0.1
"""Size of the closed-loop check's step on every joint [rad]."""
MOTION_S = 0.25
"""Duration of the closed-loop check's motion [s], then :data:`HOLD_S` of hold."""
HOLD_S = 0.5
BOUND_RAD = 0.5
"""A closed loop whose tracking error exceeds this on any joint is called unstable [rad]."""
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
        out.append(_guard("closed_loop", lambda: _closed_loop(build(), spec)))
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
    start = np.asarray(PAPER_START_RAD[: spec.dof], dtype=float)
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


def _closed_loop(ctl: Controller, spec: RobotSpec) -> str:
    start = [float(x) for x in PAPER_START_RAD[: spec.dof]]
    goal = [x + STEP_RAD for x in start]
    reference = QuinticReference.between(start, goal, duration_s=MOTION_S)
    result = run_episode(spec, reference=reference, controller=ctl, seed=0, hold_s=HOLD_S)
    if result.status != "ok":
        raise _Fail(f"the episode diverged: {result.reason}")
    err = np.abs(result.q_ref - result.q_true)
    if not np.isfinite(err).all():
        raise _Fail("the tracking error became non-finite")
    worst = float(err.max())
    if worst > BOUND_RAD:
        joint = int(np.unravel_index(int(err.argmax()), err.shape)[1]) + 1
        raise _Fail(
            f"unstable: tracking error {worst:.3g} rad on joint {joint} > {BOUND_RAD} rad "
            f"({STEP_RAD} rad step in {MOTION_S} s, {HOLD_S} s hold on {spec.name})"
        )
    return f"max error {worst:.3g} rad over {MOTION_S + HOLD_S:g} s ({spec.name})"
