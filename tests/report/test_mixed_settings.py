"""A report over a group whose episodes were recorded with different settings warns, naming them."""

from __future__ import annotations

from pathlib import Path

from pipeline.stages.report import run_report
from tests.report.campaignfactory import campaign_episodes, write_campaign


def test_mixed_hold_in_one_campaign_condition_is_named(tmp_path: Path) -> None:
    episodes = campaign_episodes(seeds=3, payloads=(0.0,))  # pid and ctc x 3 seeds
    for ep in episodes:
        ep.hold_s = 0.8
    episodes[0].hold_s = episodes[1].hold_s = 0.3  # an interrupted re-run, another hold
    write_campaign(tmp_path / "rec", episodes)
    result = run_report(recordings_dir=tmp_path / "rec", out_dir=tmp_path / "out")
    notes = [(where, note) for where, note in result.warnings if "settings differ" in note]
    assert len(notes) == 1, result.warnings
    where, note = notes[0]
    assert where == "sweep/plant.payload_kg=0"
    assert "hold_s: 0.8 vs 0.3 in 2 of 6 episodes" in note
    assert episodes[0].episode in note and episodes[1].episode in note
    text = (tmp_path / "out" / "report.md").read_text()
    assert "**Settings differ within this group**" in text
    assert "hold_s: 0.8 vs 0.3 in 2 of 6 episodes" in text


def test_one_setup_per_group_says_nothing(tmp_path: Path) -> None:
    episodes = campaign_episodes(seeds=2, payloads=(0.0, 0.5))
    write_campaign(tmp_path / "rec", episodes)
    result = run_report(recordings_dir=tmp_path / "rec", out_dir=tmp_path / "out")
    assert not [n for _, n in result.warnings if "settings differ" in n], result.warnings
    assert "Settings differ" not in (tmp_path / "out" / "report.md").read_text()
