"""A recording with many joints draws a bounded number of them, and says so."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest

from pipeline.report.figures import MAX_FIGURE_JOINTS
from pipeline.stages.report import run_report
from tests.analysis.bagfactory import paper_like, write_bag


def _many_joints(root: Path, n: int) -> None:
    ep = paper_like("many", "pid", duration_s=0.2, motion_end_s=0.1)

    def widen(a: np.ndarray) -> np.ndarray:
        return np.tile(a, (1, -(-n // a.shape[1])))[:, :n]

    write_bag(
        root,
        dataclasses.replace(
            ep,
            q=widen(ep.q),
            qd=widen(ep.qd),
            effort=widen(ep.effort),
            q_ref=widen(ep.q_ref),
            qd_ref=widen(ep.qd_ref),
            joint_names=tuple(f"j{i}" for i in range(n)),
        ),
    )


@pytest.mark.slow
def test_a_thousand_joints_draw_the_first_few_and_say_so(tmp_path: Path) -> None:
    _many_joints(tmp_path / "recordings", 1000)
    started = time.monotonic()
    result = run_report(recordings_dir=tmp_path / "recordings", out_dir=tmp_path / "reports")
    # 10,000 joints took 50 s end to end (1 min to write the bag); drawing every one of
    # them used to take hours
    assert time.monotonic() - started < 120
    text = (tmp_path / "reports" / "report.md").read_text(encoding="utf-8")
    assert f"the first {MAX_FIGURE_JOINTS} of 1,000 joints; all are in the CSV files" in text
    assert "plots/errors.csv" in result.files
    assert ",j999," in (tmp_path / "reports" / "plots" / "errors.csv").read_text()
