"""Start-up cost of the record path (issue 31): toppra loads without matplotlib.pyplot,
and toppra's plots still find the real pyplot when asked."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).parents[2]


def _run(code: str) -> str:
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin", "MPLBACKEND": "Agg"},
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_the_record_executors_load_without_matplotlib() -> None:
    out = _run(
        "import sys, pipeline.stages.executors, toppra; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib'))"
    )
    assert out == "[]"


def test_toppra_plots_reach_the_real_pyplot_after_a_deferred_import() -> None:
    out = _run(
        "import pipeline.planning.timing, toppra.algorithm.algorithm as a, sys; "
        "plot = a.plt.plot; import matplotlib.pyplot as plt; "
        "print(plot is plt.plot, type(sys.modules['matplotlib']).__name__)"
    )
    assert out == "True module"
