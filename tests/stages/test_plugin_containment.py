"""Plug-in controllers are contained (ros2_control deactivates a misbehaving controller and
the manager survives): each misbehaviour fails its own episode in one line naming the
controller, its origin, the call and the reason; the other episodes are recorded."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

from pipeline.control.contain import Budget, PluginError, PluginScope

REPO = Path(__file__).parents[2]

HOSTILE = """
import os, sys, time
import numpy as np
from tests.control.test_testkit import GoodPd

class InitRaises(GoodPd):
    def __init__(self, *a, **k):
        raise RuntimeError("no init for you")

class Divides(GoodPd):
    def compute(self, q, qd, q_ref, qd_ref, qdd_ref, dt_s):
        return q / 0 if q[0] > 1e9 else 1 // 0

class Exits(GoodPd):
    def compute(self, *a):
        sys.exit(7)

class Interrupts(GoodPd):
    def reset(self):
        raise KeyboardInterrupt

class NaN(GoodPd):
    def compute(self, *a):
        return np.full(6, np.nan)

class Writes(GoodPd):
    def compute(self, q, qd, q_ref, qd_ref, qdd_ref, dt_s):
        q[:] = 123.0
        return super().compute(q, qd, q_ref, qd_ref, qdd_ref, dt_s)

class Sleeps(GoodPd):
    def compute(self, *a):
        time.sleep(3600)

class Spins(GoodPd):
    def compute(self, *a):
        while True:
            pass

class Quits(GoodPd):
    def compute(self, *a):
        os._exit(0)

class QuitsEarly(GoodPd):
    def __init__(self, *a, **k):
        os._exit(0)
"""

CASES = {  # controller class: what its one line says
    "InitRaises": "__init__: raised RuntimeError: no init for you",
    "Divides": "compute: raised ZeroDivisionError",
    "Exits": "compute: called sys.exit(7)",
    "Interrupts": "reset: raised KeyboardInterrupt",
    "NaN": "compute: returned a non-finite torque",
    "Writes": "compute: raised ValueError: assignment destination is read-only",
    "Sleeps": "compute: took longer than its budget of 0.5 s per call",
    "Spins": "compute: took longer than its budget of 0.5 s per call",
    "Hangs": "import: took longer than its budget of 8 s to import",
    "Quits": "its worker process died (exit code 0) while running plug-in controller",
    "QuitsEarly": "its worker process died (exit code 0) while running plug-in controller",
}


def _params(tmp_path: Path) -> Path:
    (tmp_path / "hostile_plugins.py").write_text(textwrap.dedent(HOSTILE))
    (tmp_path / "hostile_hang.py").write_text("import time\nwhile True:\n    time.sleep(1)\n")
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = 0.1
    data["scenarios"]["paper"]["preroll_s"] = 0.1
    data["controllers"] = {
        **data["controllers"],
        **{c.lower(): {"type": f"hostile_plugins:{c}", "gains": {}} for c in CASES},
        "hangs": {"type": "hostile_hang:Law", "gains": {}},
    }
    data["episodes"] = {
        "ok-pid": {"scenario": "paper", "controller": "pid", "seed": 0},
        **{f"e-{c.lower()}": {"scenario": "paper", "controller": c.lower(), "seed": 0}
           for c in CASES},
    }  # fmt: skip
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.slow
def test_each_misbehaving_plug_in_fails_its_episode_in_one_line_and_the_others_record(
    tmp_path: Path,
) -> None:
    params = _params(tmp_path)
    out = tmp_path / "rec"
    env = {"PYTHONPATH": f"{tmp_path}:{REPO}", "PATH": "/usr/bin:/bin", "HOME": str(tmp_path),
           "ARMLAB_PLUGIN_IMPORT_BUDGET_S": "8"}  # fmt: skip
    done = subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(params), "--out", str(out),
         "-j", "1", "--plugin-call-budget-s", "0.5"],
        cwd=REPO, capture_output=True, text=True, timeout=600, env=env, check=False,
    )  # fmt: skip
    err = done.stderr
    assert done.returncode == 1, err
    assert "Traceback" not in err, err
    assert (out / "ok-pid").is_dir()  # the built-in episode went on
    for cls, words in CASES.items():
        line = next((ln for ln in err.splitlines() if f"e-{cls.lower()}" in ln), "")
        assert words in line, (cls, err)
        if cls not in ("Quits", "QuitsEarly", "Hangs"):
            assert f"controller 'hostile_plugins:{cls}' (module {tmp_path}" in line, line
        assert not (out / f"e-{cls.lower()}").exists()


def test_a_call_past_its_budget_is_interrupted_and_named() -> None:
    budget = Budget(call_s=0.2, episode_s=5.0)
    with PluginScope("mine:Law", budget=budget) as scope, pytest.raises(PluginError) as err:
        scope.call("compute", lambda: __import__("time").sleep(30))
    assert str(err.value) == (
        "controller 'mine:Law' (module mine): compute: took longer than its budget of 0.2 s "
        "per call"
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    ("cls", "words"),
    [("Sleeps", "check: ran past the episode budget of 2 s"), ("Exits", "called sys.exit(7)"),
     ("Interrupts", "raised KeyboardInterrupt"),
     ("Quits", "its process died (exit code 0) during the check")],
)  # fmt: skip
def test_check_controller_contains_a_plug_in_in_one_line(
    tmp_path: Path, cls: str, words: str
) -> None:
    _params(tmp_path)
    env = {"PYTHONPATH": f"{tmp_path}:{REPO}", "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, "-m", "pipeline", "check-controller", f"hostile_plugins:{cls}",
         "--budget-s", "2"],
        cwd=REPO, capture_output=True, text=True, timeout=120, env=env, check=False,
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], done.stderr
    assert lines[0].startswith(f"error: controller 'hostile_plugins:{cls}' (module {tmp_path}")
