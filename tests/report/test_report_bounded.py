"""report.md and recording.rrd do not grow with the number of episodes."""

from __future__ import annotations

from pathlib import Path

from pipeline.stages.report import run_report
from tests.report.campaignfactory import campaign_episodes, write_campaign


def _report(root: Path, seeds: int) -> tuple[int, int, int]:
    episodes = campaign_episodes(seeds=seeds)
    write_campaign(root / "recordings", episodes)
    out = root / "reports"
    # jobs=1: a report worker pool's start-up repays nothing on the suite's busy cores, and the
    # outputs do not depend on jobs (tests/stages/test_report_jobs.py)
    run_report(recordings_dir=root / "recordings", out_dir=out, jobs=1)
    return (
        len(episodes),
        (out / "report.md").stat().st_size,
        (out / "recording.rrd").stat().st_size,
    )


def test_report_and_rrd_sizes_are_bounded_for_hundreds_of_episodes(tmp_path: Path) -> None:
    n_small, md_small, rrd_small = _report(tmp_path / "small", seeds=8)
    n_large, md_large, rrd_large = _report(tmp_path / "large", seeds=50)
    assert (n_small, n_large) == (48, 300)
    # same conditions and controllers: the same sample and tables, only counts differ
    assert md_large <= md_small * 1.1, (md_small, md_large)
    assert rrd_large <= rrd_small * 1.1, (rrd_small, rrd_large)
    assert md_large < 100_000
