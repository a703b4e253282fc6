"""`pipeline report --jobs N`: recordings read and measured on worker processes give the
same report, byte for byte, as one process; bad recordings are refused or skipped alike;
Ctrl-C, SIGTERM or the parent's death leave no worker behind."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from pipeline.errors import RecordingError
from pipeline.log.reader import ReadOptions
from pipeline.stages import report_pool
from pipeline.stages.report import run_report
from tests.analysis.bagfactory import damage, paper_like, write_bag
from tests.report.campaignfactory import campaign_episodes, write_campaign

RERUN = Path(sys.executable).parent / "rerun"
REPO = Path(__file__).resolve().parents[2]


def _recordings(root: Path) -> Path:
    """A campaign (2 controllers x 2 payloads x 2 seeds) and two hand-listed episodes."""
    write_campaign(root, campaign_episodes("sweep", seeds=2, payloads=(0.0, 1.0)))
    write_bag(root, paper_like("pid_alone", "pid", duration_s=0.6, motion_end_s=0.4))
    write_bag(root, paper_like("ctc_alone", "ctc", duration_s=0.6, motion_end_s=0.4, seed=1))
    return root


def _files(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


def _assert_same_report(a: Path, b: Path) -> None:
    """Every output the same bytes; the .rrd the same content (its chunk ids are random,
    and how the viewer's SDK batches rows into chunks depends on timing)."""
    fa, fb = _files(a), _files(b)
    assert sorted(fa) == sorted(fb)
    differ = [name for name in fa if name != "recording.rrd" and fa[name] != fb[name]]
    assert differ == []
    rrds = [str(a / "recording.rrd"), str(b / "recording.rrd")]
    same = subprocess.run(
        [str(RERUN), "rrd", "compare", "--unordered", *rrds],
        capture_output=True,
        text=True,
        check=False,
    )
    assert same.returncode == 0, same.stdout + same.stderr


@pytest.mark.parametrize("windowed", [False, True], ids=["whole", "windowed"])
def test_report_is_the_same_bytes_whatever_the_jobs(tmp_path: Path, windowed: bool) -> None:
    recordings = _recordings(tmp_path / "recordings")
    options = ReadOptions(stream_above_bytes=0, window_steps=100) if windowed else None
    results = {
        jobs: run_report(
            recordings_dir=recordings, out_dir=tmp_path / f"j{jobs}", jobs=jobs, options=options
        )
        for jobs in (1, 2)
    }
    one, two = results[1], results[2]
    _assert_same_report(one.out_dir, two.out_dir)
    # what the campaign table is built from: every episode, measured the same
    assert (one.out_dir / "campaigns" / "sweep.parquet").is_file()
    assert one.summary.equals(two.summary) and one.summary.height == 10
    assert one.warnings == two.warnings
    assert one.decoded_messages == two.decoded_messages


def test_bad_recording_is_refused_or_skipped_alike_with_workers(tmp_path: Path) -> None:
    recordings = _recordings(tmp_path / "recordings")
    bad = write_bag(recordings, paper_like("bad_one", "pid", duration_s=0.5))
    damage(bad, "truncated")
    with pytest.raises(RecordingError) as refused:
        run_report(recordings_dir=recordings, out_dir=tmp_path / "r", jobs=2)
    assert "bad_one" in str(refused.value) and "--skip-bad" in str(refused.value)
    assert not (tmp_path / "r").exists()
    assert _gone(_workers(psutil.Process()), timeout_s=5.0), "a refusal left workers running"
    skipped = [
        run_report(recordings_dir=recordings, out_dir=tmp_path / f"s{j}", jobs=j, skip_bad=True)
        for j in (1, 2)
    ]
    assert skipped[0].skipped == skipped[1].skipped and len(skipped[0].skipped) == 1
    _assert_same_report(skipped[0].out_dir, skipped[1].out_dir)


def test_default_jobs_is_none_for_a_small_report_and_at_most_the_cpus() -> None:
    assert report_pool.default_jobs(1) == 1
    assert report_pool.default_jobs(report_pool.RECORDINGS_PER_WORKER - 1) == 1
    many = report_pool.default_jobs(100_000)
    assert many == min(report_pool.available_cpus(), report_pool.MAX_DEFAULT_JOBS)


def _workers(proc: psutil.Process) -> list[psutil.Process]:
    """``proc``'s spawned report workers (not multiprocessing's resource tracker)."""
    out = []
    for kid in proc.children(recursive=True):
        with contextlib.suppress(psutil.Error):
            cmd = " ".join(kid.cmdline())
            if "multiprocessing" in cmd and "resource_tracker" not in cmd:
                out.append(kid)
    return out


def _workers_of(proc: psutil.Process, count: int, timeout_s: float) -> list[psutil.Process]:
    """Wait until ``proc`` has ``count`` report workers; return them."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        kids = _workers(proc)
        if len(kids) >= count:
            return kids
        time.sleep(0.05)
    raise AssertionError(f"no {count} report workers within {timeout_s} s")


def _gone(procs: list[psutil.Process], timeout_s: float = 10.0) -> bool:
    _, alive = psutil.wait_procs(procs, timeout=timeout_s)
    return not alive


@pytest.mark.slow
@pytest.mark.parametrize("how", ["ctrl-c", "sigterm", "parent-killed"])
def test_no_worker_outlives_an_interrupted_report(tmp_path: Path, how: str) -> None:
    root = tmp_path / "recordings"
    write_campaign(root, campaign_episodes("sweep", seeds=20, payloads=(0.0, 1.0)))
    cmd = [sys.executable, "-m", "pipeline", "report", "--recordings", str(root),
           "--out", str(tmp_path / "out"), "-j", "2"]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    # its own process group: a terminal's Ctrl-C reaches every process of the group
    child = subprocess.Popen(
        cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, process_group=0
    )
    try:
        workers = _workers_of(psutil.Process(child.pid), 2, timeout_s=120.0)
        time.sleep(0.5)
        if how == "ctrl-c":
            os.killpg(child.pid, signal.SIGINT)
        elif how == "sigterm":
            child.send_signal(signal.SIGTERM)
        else:
            child.kill()
        child.wait(timeout=60)
        assert _gone(workers), "a report worker outlived its parent"
    finally:
        if child.poll() is None:
            child.kill()
    err = child.stderr.read().decode() if child.stderr else ""
    if how != "parent-killed":
        assert child.returncode == (130 if how == "ctrl-c" else 143), err
        assert "Traceback" not in err
        assert err.strip().splitlines()[-1] in ("interrupted", "terminated")
        # (a killed parent leaves its staging folder and lock: the next run removes them)
        assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    assert not (tmp_path / "out").exists()
