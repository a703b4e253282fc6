"""The issue-28 studies (docs/control.md, "The studies on the fair footing"): their params
files are valid outside the demo, and the table script decides each cell by the report's
one verdict rule, Holm-corrected over a comparison's row."""

from __future__ import annotations

import sys
from pathlib import Path

import polars as pl
import pytest

from pipeline.params import load_params

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "studies"))

import study_table  # noqa: E402

CAD = ("pid", "pid_ff", "ctc", "ctc_pid")


@pytest.mark.parametrize(
    ("file", "campaign", "controllers", "scenario"),
    [
        ("panda_published.yaml", "panda-published", 10, "panda-gaz"),
        ("panda_published.yaml", "panda-published-links", 4, "panda-gaz-links"),
        ("ur5_friction_class.yaml", "ur5-friction-class", 10, "ur5-draws"),
        ("ur5_friction_class.yaml", "ur5-friction-class-own", 3, "ur5-draws"),
    ],
)
def test_each_study_is_a_valid_campaign_of_ten_seeds_outside_the_demo(
    file: str, campaign: str, controllers: int, scenario: str
) -> None:
    from pipeline.stages.campaign_expand import expand
    from pipeline.stages.record import validate_episodes

    study = load_params(REPO / "studies" / file)
    episodes = expand(study, campaign)
    assert len(episodes) == controllers * 10
    assert {e.scenario_name for e in episodes} == {scenario}
    assert {e.seed for e in episodes} == set(range(10))
    # the laws on the CAD model need no identified model file (the others are written by
    # studies/run_study.py before they record)
    cad = [e for e in episodes if e.controller_name in CAD and e.seed == 0]
    validate_episodes(study, cad)
    assert campaign not in load_params(REPO / "params.yaml").campaigns


def _frame(values: dict[str, list[float]]) -> pl.DataFrame:
    """A campaign table as `pipeline report` writes it: one joint and the TCP [mm]."""
    rows = []
    for controller, errors in values.items():
        for seed, error in enumerate(errors):
            base = {"episode": f"{controller}.s{seed}", "controller": controller, "seed": seed}
            rows.append({**base, "status": "ok", "joint": "j1", "max_abs_error": error,
                         "tcp_max_position_error": None})  # fmt: skip
            rows.append({**base, "status": "ok", "joint": "tcp", "max_abs_error": None,
                         "tcp_max_position_error": error * 1e3})  # fmt: skip
    return pl.DataFrame(rows)


def test_a_law_lower_on_every_seed_is_lower_and_an_equal_one_equivalent(capsys) -> None:
    pid = [0.010 + 0.001 * s for s in range(10)]
    study = study_table.Study(
        _frame({"pid": pid, "ctc": [x / 2 for x in pid], "pid_ff": [x * (1 + 1e-4) for x in pid]})
    )
    study.min_p = 2 * 2.0 / 2**10
    study_table.comparison_table(
        study, "t", [("ctc", "ctc", "pid"), ("pid_ff", "pid_ff", "pid")], ["tcp", "j1"], print
    )
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    ctc, pid_ff = rows[-2], rows[-1]
    assert ctc.count("-50 ± 0 (lower)") == 2
    assert pid_ff.count("(equivalent)") == 2


def test_holm_corrects_a_row_s_p_values_step_down() -> None:
    assert study_table.holm([0.01, 0.04, None, 0.03]) == [0.03, 0.06, None, 0.06]
    assert study_table.holm([0.002, 0.002]) == [0.004, 0.004]
