"""The controller test kit: every built-in passes it, deliberately broken controllers fail it.

The broken controllers live here and are loaded by name, ``tests.control.test_testkit:Class``,
exactly as a user's ``module:Object`` controller would be.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from pipeline.control import controller_names, ctc
from pipeline.control.controller import F64, GainSpec, NominalPDController
from pipeline.control.pd_gravity import default_gains as pd_default_gains
from pipeline.robots.loaders import load_spec
from pipeline.sim.testkit import (
    Finding,
    assert_controller_ok,
    check_controller,
    designed_settling_s,
    kit_start,
)

REPO = Path(__file__).parents[2]
HERE = "tests.control.test_testkit"


class GoodPd(NominalPDController):
    """PD + gravity, written as a user would (a working plug-in)."""

    NAME = "good_pd"
    GAINS = (
        GainSpec("kp", unit="N m/rad", stiffness=True, default="m_jj w^2"),
        GainSpec("kd", unit="N m s/rad", default="2 zeta w m_jj"),
    )
    DEFAULT_GAINS = staticmethod(pd_default_gains)
    COLOR = (188, 189, 34)

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        gravity: F64 = pin.computeGeneralizedGravity(self._model, self._data, q)
        tau: F64 = self._kp * (q_ref - q) + self._kd * (qd_ref - qd) + gravity
        return tau


class WrongShape(GoodPd):
    """Drops the last joint."""

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        return super().compute(q, qd, q_ref, qd_ref, qdd_ref, dt_s)[:-1]


class NonDeterministic(GoodPd):
    """Adds unseeded noise."""

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        tau = super().compute(q, qd, q_ref, qd_ref, qdd_ref, dt_s)
        return tau + np.random.default_rng().normal(0.0, 1e-3, tau.shape)


class Unstable(GoodPd):
    """Positive position feedback: pushes away from the reference."""

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        gravity: F64 = pin.computeGeneralizedGravity(self._model, self._data, q)
        tau: F64 = -self._kp * (q_ref - q) + gravity
        return tau


class ForgetsNothing(GoodPd):
    """An integrator that reset() does not clear."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._z = np.zeros(6)

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        self._z += (q_ref - q) * dt_s
        return super().compute(q, qd, q_ref, qd_ref, qdd_ref, dt_s) + 10.0 * self._z


class ReportsUndeclared(GoodPd):
    """Its gains_in_effect() name a gain it does not declare."""

    def gains_in_effect(self) -> dict[str, Any]:
        return {**super().gains_in_effect(), "secret_gain": 1.0}


class AcceptsAnyGain(GoodPd):
    """Ignores the gains it is given."""

    def __init__(self, spec: Any, gains: Any = None, *, where: str = "gains") -> None:
        super().__init__(spec, None, where=where)


class ZeroTorque(NominalPDController):
    """Commands nothing: the arm falls under gravity."""

    NAME = "zero_torque"
    GAINS = ctc.GAINS
    DEFAULT_GAINS = staticmethod(ctc.default_gains)

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        return np.zeros_like(q)


class GravityOnly(ZeroTorque):
    """Holds the arm against gravity wherever it is, and never corrects an error."""

    NAME = "gravity_only"

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        tau: F64 = pin.computeGeneralizedGravity(self._model, self._data, q).copy()
        return tau


class NegativeDamping(ctc.ComputedTorqueController):
    """Computed torque with kd = -4 1/s: the linearized loop's poles in the right half-plane."""

    NAME = "ctc_negative_damping"
    GAINS = (ctc.GAINS[0], GainSpec("kd", nonnegative=False, unit="1/s"))

    @staticmethod
    def DEFAULT_GAINS(spec: Any, **kwargs: Any) -> dict[str, Any]:
        return {**ctc.default_gains(spec, **kwargs), "kd": [-4.0] * spec.dof}


NOT_A_CONTROLLER = 42


def _failed(name: str) -> dict[str, str]:
    return {f.check: f.detail for f in check_controller(name) if not f.ok}


@pytest.mark.parametrize("robot", ["ur5", "panda"])
@pytest.mark.parametrize("name", controller_names())
def test_every_built_in_controller_passes_the_kit(name, robot):
    assert_controller_ok(name, robot=robot)


@pytest.mark.parametrize("robot", ["ur5", "panda"])
@pytest.mark.parametrize("cls", ["ZeroTorque", "GravityOnly", "NegativeDamping"])
def test_the_closed_loop_check_fails_a_law_that_does_not_regulate(cls, robot):
    findings = check_controller(f"{HERE}:{cls}", robot=robot)
    failed = {f.check: f.detail for f in findings if not f.ok}
    assert list(failed) == ["closed_loop"], failed
    assert failed["closed_loop"].startswith(("unstable: error", "not stable enough: error fell"))


def test_the_closed_loop_check_reports_the_measured_decay_within_the_settling_time():
    found = {f.check: f for f in check_controller("ctc", robot="panda")}["closed_loop"]
    # ctc on its own nominal plant: 2 % by design at 5.83 / 40 s, less the torque clipping
    ratio = float(found.detail.split("error fell ")[1].split("x")[0])
    assert found.ok and 10.0 <= ratio <= 50.0, found.detail
    assert "0.146 s, the designed settling time" in found.detail


def test_designed_settling_time_is_the_slowest_designed_pole():
    assert designed_settling_s({}) == pytest.approx(5.8339 / 40.0, rel=1e-4)
    assert designed_settling_s({"omega_n_rad_s": 10.0, "zeta": 0.5}) == pytest.approx(
        -np.log(0.02) / 5.0
    )
    slow = designed_settling_s({"kp": [100.0, 100.0], "ki": [400.0, 200.0]})
    assert slow == pytest.approx(-np.log(0.02) / 2.0)


def test_the_kit_starts_from_the_named_state_or_mid_range():
    panda, ur5 = load_spec("panda"), load_spec("ur5")
    assert kit_start(panda).tolist() == list(dict(panda.named_states)["default"])
    assert kit_start(ur5).tolist() == ((ur5.lower + ur5.upper) / 2).tolist()


def test_check_controller_cli_runs_a_built_in_on_a_seven_joint_robot():
    proc = _cli("check-controller", "ctc", "--robot", "panda", "--json")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    report = json.loads(proc.stdout)
    assert report["ok"] and "7 joints" in report["findings"][0]["detail"]


def test_a_module_object_controller_passes_the_kit():
    findings = check_controller(f"{HERE}:GoodPd")
    assert all(f.ok for f in findings), findings
    assert [f.check for f in findings] == [
        "build", "interface", "output", "gains_in_effect", "gains", "determinism", "reset",
        "closed_loop",
    ]  # fmt: skip


@pytest.mark.parametrize(
    ("cls", "check", "words"),
    [
        ("WrongShape", "output", "shape (5,), expected (6,)"),
        ("NonDeterministic", "determinism", "two fresh instances differ"),
        ("Unstable", "closed_loop", ""),
        ("ForgetsNothing", "reset", "after reset()"),
        ("ReportsUndeclared", "gains_in_effect", "gains it does not declare: secret_gain"),
        ("AcceptsAnyGain", "gains", "accepted a gain it does not declare"),
    ],
)
def test_the_kit_catches_a_broken_controller(cls, check, words):
    failed = _failed(f"{HERE}:{cls}")
    assert check in failed, failed
    assert words in failed[check] and "\n" not in failed[check]
    with pytest.raises(AssertionError, match=check):
        assert_controller_ok(f"{HERE}:{cls}")


def test_an_unstable_controller_is_called_unstable_or_diverged():
    detail = _failed(f"{HERE}:Unstable")["closed_loop"]
    assert detail.startswith(("unstable: error", "not stable enough")), detail


def test_an_object_that_is_no_controller_fails_the_build_in_one_line():
    findings = check_controller(f"{HERE}:NOT_A_CONTROLLER")
    assert findings == [
        Finding(
            "build",
            False,
            f"controller '{HERE}:NOT_A_CONTROLLER' is not a controller: expected a "
            "ControllerEntry or a class with GAINS and DEFAULT_GAINS, got int 42",
        )
    ]


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pipeline", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )


def test_check_controller_cli_passes_a_built_in_and_fails_a_broken_one():
    ok = _cli("check-controller", "pd_gravity", "--json")
    assert ok.returncode == 0, ok.stderr
    report = json.loads(ok.stdout)
    assert report["ok"] and {f["check"] for f in report["findings"]} >= {"reset", "closed_loop"}
    bad = _cli("check-controller", f"{HERE}:WrongShape")
    assert bad.returncode == 1
    assert "FAIL" in bad.stdout and "output" in bad.stdout


def test_check_controller_cli_refuses_an_unknown_name_in_one_line():
    proc = _cli("check-controller", "pdi")
    assert proc.returncode == 1 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1
    assert proc.stderr.startswith("error: unknown controller 'pdi' (did you mean 'pid'?); valid:")
