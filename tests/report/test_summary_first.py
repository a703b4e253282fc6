"""report.md leads with its answer; a foreign bag's missing data is n/a, never a pass."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from pipeline.stages.report import run_report
from tests.analysis.bagfactory import default_settings, paper_like, write_bag

FIRST_SCREEN = 40


def _report(root: Path, *, seeds: int, foreign: bool = False, baseline: str = "pid") -> str:
    for seed in range(seeds):
        for controller, scale in (("pid", 1e-3), ("ctc", 1.2e-3 + 1e-4 * seed)):
            ep = paper_like(f"{controller}-{seed}", controller, seed=seed, error_scale=scale)
            ep.episode_metadata = not foreign
            write_bag(root / "recordings", ep)
    run_report(recordings_dir=root / "recordings", out_dir=root / "reports", baseline=baseline)
    return (root / "reports" / "report.md").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def three_seeds(tmp_path_factory: pytest.TempPathFactory) -> str:
    """report.md of pid and ctc over 3 seeds (shared by the tests that only read it)."""
    return _report(tmp_path_factory.mktemp("three"), seeds=3)


def test_the_first_screen_holds_the_headline_table_and_the_verdicts(three_seeds: str) -> None:
    text = three_seeds
    screen = "\n".join(text.splitlines()[:FIRST_SCREEN])
    assert "## Answer" in screen
    assert "| 2 shoulder_lift_joint [rad] |" in screen
    assert "| TCP max position error [mm] |" in screen
    assert "| TCP max orientation error [mrad] |" in screen
    verdict = next(line for line in screen.splitlines() if line.startswith("- **ctc vs pid**"))
    # the report's one rule behind it, in both spaces: 3 pairs are too few for a test
    assert "One rule for every comparison of this report" in screen
    assert "too few pairs for a test (fewer than 6): signs untested" in verdict
    assert "higher (untested) on joints 1, 2, 3, 4, 5" in verdict
    assert "task space (TCP), max position error higher (untested)" in verdict
    assert "## Episodes" not in screen.split("### Verdicts")[0]
    assert "Physical checks failed" not in text  # every check passes: no banner


def test_physical_checks_are_one_controller_by_joint_table(three_seeds: str) -> None:
    text = three_seeds
    section = text.split("## Physical checks", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ")]
    assert rows[0].startswith("| controller | contacts | 1 shoulder_pan_joint |")
    assert sorted(r.split(" | ")[0] for r in rows[2:]) == ["| ctc", "| pid"]
    assert not any(line.startswith("- ") for line in section.splitlines())


def test_a_foreign_bag_shows_na_for_what_it_does_not_hold_and_no_pass(tmp_path: Path) -> None:
    text = _report(tmp_path, seeds=1, foreign=True, baseline="pid-0")
    section = text.split("## Physical checks", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ")][2:]
    for row in rows:
        cells = row.strip("| ").split(" | ")
        assert cells[1] == "n/a (not in the bag)"  # contacts: no safety record
        # no effort limit, goal, gains or friction: nothing to check on any joint
        assert cells[2:] == ["n/a (not in the bag)"] * 6
    assert "No contact during execution" not in text
    assert "paper Fig." not in text
    # saturation without an effort limit is n/a, not 0 %
    episodes = text.split("## Episodes", 1)[1].split("\n\n", 2)[1]
    assert not re.search(r"\| 0\.0 % \|", episodes)


@pytest.mark.slow
def test_a_failed_physical_check_is_a_banner_on_the_first_screen(tmp_path: Path) -> None:
    for controller in ("pid", "ctc"):
        ep = paper_like(f"{controller}-0", controller)
        t = ep.stamp_ns * 1e-9
        ep.q[:, 0] -= 0.05 * np.clip(t - 1.0, 0.0, 1.0)  # both end 0.05 rad short on joint 1
        if controller == "pid":  # kp = 100 N m/rad against 2 N m of friction on joint 6
            settings = default_settings(ep)
            settings["plant"]["frictionloss"] = [0.0, 0.0, 0.0, 0.0, 0.0, 2.0]
            ep.settings = settings
        write_bag(tmp_path / "recordings", ep)
    run_report(recordings_dir=tmp_path / "recordings", out_dir=tmp_path / "reports")
    lines = (tmp_path / "reports" / "report.md").read_text(encoding="utf-8").splitlines()
    screen = lines[: lines.index("## Answer")]
    assert "> **Physical checks failed**: read the comparison below with these in mind." in screen
    banner = [line for line in screen if line.startswith("> - ")]
    assert banner == [
        "> - **pid**, joint 6 `wrist_3_joint`: friction dead band 0.02 rad (friction / position "
        "stiffness); the joint may stop anywhere within that band, so its error and settling "
        "numbers measure the friction, not the control law.",
        "> - every controller (**ctc**, **pid**), joint 1 `shoulder_pan_joint`: goal missed by "
        "0.05 rad in 2/2 episodes; every controller shows it: on joint 1 `shoulder_pan_joint` "
        "the comparison measures the setup (friction, limits, obstacles), not the controllers.",
    ]
