"""Which campaign episodes are shown one by one: a salvaged run cut before its motion end
covers part of the motion only, so it is never a group's median or worst run."""

from __future__ import annotations

from pathlib import Path

import polars as pl

from pipeline.analysis.measure import SHOW_ALL_UP_TO
from pipeline.report.inputs import ReportData


def _data(rows: list[tuple[str, float, str, bool, bool]]) -> ReportData:
    episodes = pl.DataFrame(
        {
            "episode": [r[0] for r in rows],
            "group": ["c/x"] * len(rows),
            "controller": ["pid"] * len(rows),
            "status": [r[2] for r in rows],
            "salvaged": [r[3] for r in rows],
            "motion_completed": [r[4] for r in rows],
        }
    )
    metrics = pl.DataFrame(
        {"episode": [r[0] for r in rows], "joint": ["j1"] * len(rows),
         "max_abs_error": [r[1] for r in rows]}
    )  # fmt: skip
    return ReportData(
        recordings=(),
        episodes=episodes,
        metrics=metrics,
        comparisons=pl.DataFrame(),
        baseline="pid",
        skipped=(),
        recordings_dir=Path("."),
    )


def test_a_salvaged_cut_run_is_not_the_worst_or_the_median() -> None:
    rows = [(f"e{k}", 1e-3 * (k + 1), "ok", False, True) for k in range(SHOW_ALL_UP_TO + 2)]
    # the largest max |e| of all, but only over the part of the motion before the damage
    rows.append(("e9-cut", 1.0, "ok", True, False))
    roles = _data(rows).sample_roles
    assert "e9-cut" not in roles
    assert roles[f"e{SHOW_ALL_UP_TO + 1}"] == "worst"
    # a salvaged run that did reach its motion end is a run like any other
    rows[-1] = ("e9-cut", 1.0, "ok", True, True)
    assert _data(rows).sample_roles["e9-cut"] == "worst"
