"""Importing any report module (or the report command) loads neither Pinocchio nor MuJoCo,
directly or through what it imports: the report reads recorded values and the controllers'
declared facts (pipeline.control.info), it never builds a model."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import pipeline

PACKAGE = Path(pipeline.__file__).parent
MODULES = sorted(
    ".".join(("pipeline", *p.relative_to(PACKAGE).with_suffix("").parts)).removesuffix(".__init__")
    for p in (PACKAGE / "report").rglob("*.py")
)
_PROBE = (
    "import importlib, sys; importlib.import_module(sys.argv[1]); "
    "bad = [m for m in ('pinocchio', 'mujoco') if m in sys.modules]; "
    "assert not bad, f'{sys.argv[1]} loads {bad}'"
)


def test_importing_every_report_module_in_turn_loads_no_physics_engine() -> None:
    """One interpreter, each module in turn, checked after each import."""
    code = (
        "import importlib, sys\n"
        "for m in sys.argv[1:]:\n"
        "    importlib.import_module(m)\n"
        "    bad = [e for e in ('pinocchio', 'mujoco') if e in sys.modules]\n"
        "    assert not bad, f'{m} loads {bad}'\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, *MODULES, "pipeline.cli.report_cmd"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1]


@pytest.mark.slow  # one interpreter per module (~1 s each)
@pytest.mark.parametrize("module", [*MODULES, "pipeline.cli.report_cmd"])
def test_importing_a_report_module_alone_loads_no_physics_engine(module: str) -> None:
    done = subprocess.run([sys.executable, "-c", _PROBE, module], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1]


def test_the_probe_sees_an_engine_loaded_through_an_import() -> None:
    done = subprocess.run(
        [sys.executable, "-c", _PROBE, "pipeline.control.controller"],
        capture_output=True,
        text=True,
    )
    assert done.returncode != 0 and "pinocchio" in done.stderr
