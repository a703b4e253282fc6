"""The first screen's alerts: failed physical checks grouped by the controllers that share
them, so a failure every controller shows reads as the setup's, not a law's."""

from __future__ import annotations

from pipeline.analysis.findings import (
    CONTACTS,
    DEAD_BAND,
    GOAL,
    CheckAlert,
    CheckCell,
    ContactFinding,
    DeadBandFinding,
    GoalMissFinding,
    check_alerts,
)


def _cells(controller: str, findings: dict[str, list]) -> list[CheckCell]:
    return [CheckCell(controller, "", tuple(findings.get("", [])), (), 1)] + [
        CheckCell(controller, j, tuple(findings.get(j, [])), (), 1) for j in ("j1", "j2", "j3")
    ]


def test_a_failure_every_controller_shares_is_one_alert_marked_as_the_setups():
    grid = [
        *_cells("pid", {
            "j1": [DeadBandFinding("pid-0", "j1", "pid", 0.22, 1.0)],
            "j3": [GoalMissFinding("pid-0", "j3", 0.28)],
        }),
        *_cells("ctc", {
            "j3": [GoalMissFinding("ctc-0", "j3", 0.27)],
            "": [ContactFinding("ctc-0", "obstacle", ("box", "link3"), 0.002, 0.1, 0.2, 4)],
        }),
    ]  # fmt: skip
    assert check_alerts(grid) == (
        CheckAlert(DEAD_BAND, ("pid",), ("j1",), 1.0 / 0.22, 1, 1, False),
        CheckAlert(GOAL, ("pid", "ctc"), ("j3",), 0.28, 2, 2, True),
        CheckAlert(CONTACTS, ("ctc",), (), 0.002, 1, 1, False),
    )


def test_every_check_passing_gives_no_alert_and_one_controller_is_never_every():
    assert check_alerts(_cells("pid", {})) == ()
    alone = check_alerts(_cells("pid", {"j2": [GoalMissFinding("pid-0", "j2", 0.1)]}))
    assert alone == (CheckAlert(GOAL, ("pid",), ("j2",), 0.1, 1, 1, False),)
