"""`pipeline record` under faults: SIGKILL, Ctrl-C, a second run, leftovers of killed runs.

Each test runs the real command in its own session (so a failing test can clean up the
whole process group) and watches processes through /proc.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from pipeline.fsutil import OutputLock, pid_alive
from pipeline.stages.record import check_outputs_free

REPO = Path(__file__).parents[2]
pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="process checks read /proc"
)


def _params(tmp_path: Path, *, episodes: int, hold_s: float) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = hold_s
    data["episodes"] = {
        f"e{i}": {"scenario": "paper", "controller": ("pid", "ctc")[i % 2], "seed": i}
        for i in range(episodes)
    }
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # as a shell does for a background job


def _start(
    params: Path, out: Path, *extra: str, sigint_ignored: bool = False
) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pipeline", "record", "--params", str(params), "--out", str(out),
         *extra],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        start_new_session=True, preexec_fn=_ignore_sigint if sigint_ignored else None,
    )  # fmt: skip


def _children(pid: int) -> list[int]:
    kids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                kids.append(int(entry))
    return kids


def _wait_for(predicate, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


def _visible(out: Path) -> set[str]:
    return {p.name for p in out.iterdir() if not p.name.startswith(".")} if out.exists() else set()


def _partials(out: Path) -> list[str]:
    return [p.name for p in out.iterdir() if ".partial-" in p.name] if out.exists() else []


@pytest.fixture
def cleanup():
    procs: list[subprocess.Popen[str]] = []
    yield procs
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


@pytest.mark.slow
@pytest.mark.parametrize("trial", range(2))
def test_sigkill_of_the_parent_takes_its_workers_and_publishes_nothing_after(
    tmp_path, cleanup, trial
):
    out = tmp_path / "rec"
    # a 10 s hold: each bag takes a few polls to write (the SIGTERM test below catches 4 s ones)
    proc = _start(_params(tmp_path, episodes=6, hold_s=10.0), out, "--jobs", "2")
    cleanup.append(proc)
    # kill while a worker is writing a bag: the moment a late publish would happen
    assert _wait_for(lambda: bool(_partials(out)), 120), proc.stderr.read() if proc.stderr else ""
    workers = _children(proc.pid)
    assert len(workers) == 2
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    published = _visible(out)
    assert _wait_for(lambda: not any(pid_alive(w) for w in workers), 5), "a worker outlived it"
    time.sleep(2.0)  # a surviving writer would rename its bag into place by now
    assert _visible(out) == published, "a recording appeared after the parent was killed"
    # the next run clears what the killed one left
    check_outputs_free([], out, force=True)
    assert _partials(out) == []


def _interrupted(proc: subprocess.Popen[str], out: Path) -> tuple[list[str], list[str]]:
    """Wait for the run to end after SIGINT; return (finished, not recorded) from its line."""
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    match = re.fullmatch(r"interrupted: finished (\d+) episode\(s\): (.*); not recorded: (.*)",
                         lines[0])  # fmt: skip
    assert match, lines[0]
    finished = [] if match[2] == "none" else [s.split(" ")[0] for s in match[2].split(", ")]
    pending = [] if match[3] == "none" else match[3].split(", ")
    assert int(match[1]) == len(finished)
    return finished, pending


@pytest.mark.slow
@pytest.mark.parametrize(
    ("jobs", "to_group", "ignored"),
    [(2, False, False), (2, True, False), (1, True, False), (2, False, True)],
    ids=["parent", "group", "serial", "background-job"],
)
def test_ctrl_c_stops_the_run_says_what_finished_and_leaves_nothing_half_done(
    tmp_path, cleanup, jobs, to_group, ignored
):
    out = tmp_path / "rec"
    # 4 s holds (as the SIGTERM test's): when the first is done, 3 or more are still queued
    params = _params(tmp_path, episodes=6, hold_s=4.0)
    proc = _start(params, out, "--jobs", str(jobs), sigint_ignored=ignored)
    cleanup.append(proc)
    assert _wait_for(lambda: bool(_visible(out)), 120)  # one episode done, others queued
    workers = _children(proc.pid)
    (os.killpg if to_group else os.kill)(proc.pid, signal.SIGINT)
    t0 = time.monotonic()
    finished, pending = _interrupted(proc, out)
    assert time.monotonic() - t0 < 10, "queued episodes must be cancelled, not run"
    assert pending, "the run was interrupted early: some episodes must be left"
    assert sorted(finished + pending) == [f"e{i}" for i in range(6)]
    assert _visible(out) == set(finished)
    assert not _partials(out)
    assert not any(pid_alive(w) for w in workers)
    assert not (tmp_path / ".rec.lock").exists()


def test_ctrl_c_while_starting_up_prints_no_traceback(tmp_path):
    proc = _start(_params(tmp_path, episodes=2, hold_s=1.0), tmp_path / "rec")
    time.sleep(0.3)  # Python is importing the libraries
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode in (130, -signal.SIGINT), err
    assert "Traceback" not in err, err


def test_a_second_record_into_the_same_out_refuses_at_once(tmp_path):
    out = tmp_path / "rec"
    out.mkdir()
    with OutputLock(out, command="`pipeline record`"):
        result = subprocess.run(
            [sys.executable, "-m", "pipeline", "record", "--params",
             str(_params(tmp_path, episodes=1, hold_s=0.1)), "--out", str(out)],
            cwd=REPO, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    assert result.returncode == 1
    assert result.stderr.strip() == (
        f"error: {out}: another `pipeline record` (pid {os.getpid()}) is writing to this "
        "folder; wait for it to finish or choose another --out"
    )
    assert _visible(out) == set()


def test_a_second_report_into_the_same_out_refuses_at_once(tmp_path):
    from tests.analysis.bagfactory import paper_like, write_bag

    write_bag(tmp_path / "rec", paper_like("paper-pid", "pid", duration_s=0.3, motion_end_s=0.2))
    out = tmp_path / "rep"
    with OutputLock(out, command="`pipeline report`"):
        result = subprocess.run(
            [sys.executable, "-m", "pipeline", "report", "--recordings", str(tmp_path / "rec"),
             "--out", str(out)],
            cwd=REPO, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    assert result.returncode == 1
    assert "another `pipeline report`" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not out.exists()


def _dead_pid() -> int:
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def test_work_folders_of_dead_runs_are_removed_and_live_ones_kept(tmp_path):
    out = tmp_path / "rec"
    out.mkdir()
    dead, alive = _dead_pid(), os.getppid()
    for name in (f".e0.partial-{dead}", f".e1.old-{dead}", f".e2.partial-{alive}", "e3"):
        (out / name).mkdir()
    check_outputs_free([], out, force=True)
    assert sorted(p.name for p in out.iterdir()) == [f".e2.partial-{alive}", "e3"]


def test_report_removes_staging_folders_of_killed_reports(tmp_path):
    from pipeline.stages.report import run_report
    from tests.analysis.bagfactory import paper_like, write_bag

    write_bag(tmp_path / "rec", paper_like("paper-pid", "pid", duration_s=0.3, motion_end_s=0.2))
    dead, alive = _dead_pid(), os.getppid()
    stale = [f".rep.tmp-{dead}-abc123", ".rep.tmp-k2j3h4g5"]  # new and pre-pid names
    kept = [f".rep.tmp-{alive}-abc123", ".other.tmp-xyz"]
    for name in stale + kept:
        (tmp_path / name).mkdir()
        (tmp_path / name / "recording.rrd").write_bytes(b"x" * 1000)
    run_report(recordings_dir=tmp_path / "rec", out_dir=tmp_path / "rep")
    left = {p.name for p in tmp_path.iterdir() if p.name.startswith(".")}
    assert left == set(kept)


@pytest.mark.slow
def test_ctrl_c_during_a_report_keeps_the_earlier_report_and_leaves_no_staging(tmp_path):
    from pipeline.stages.report import run_report
    from tests.analysis.bagfactory import paper_like, write_bag

    rec, out = tmp_path / "rec", tmp_path / "rep"
    for ctrl in ("pid", "ctc"):
        write_bag(rec, paper_like(f"paper-{ctrl}", ctrl, duration_s=3.0, motion_end_s=2.0))
    run_report(recordings_dir=rec, out_dir=out)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    proc = subprocess.Popen(
        [sys.executable, "-m", "pipeline", "report", "--recordings", str(rec), "--out", str(out)],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip
    # interrupt once it is writing (its staging folder exists)
    _wait_for(lambda: any(".rep.tmp-" in p.name for p in tmp_path.iterdir()), 60)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.skip("the report finished before the interrupt arrived")
    assert proc.returncode == 130, err
    assert err.strip() == "interrupted", err
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    if after != before:
        # the interrupt landed after the new outputs were moved in (while cleaning up):
        # then every output is the new one, never a mix
        assert set(after) == set(before)
        assert after[Path("metrics.json")] == before[Path("metrics.json")]  # deterministic
    # Known defect (issue note): now and then (about 1 run in 3 on a loaded machine) the
    # interrupted process's staging folder survives it although its removal sits in a
    # `finally`; the cause is not found yet. The promise that holds and is tested: nothing
    # under a final name changed, and the next run removes the leftover.
    run_report(recordings_dir=rec, out_dir=out)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


# --- SIGTERM (kill, timeout, systemd, CI runners): Ctrl-C's path, exit 143 ---------------


def _terminated(proc: subprocess.Popen[str]) -> str:
    """Wait for the run to end after SIGTERM; return its one stderr line."""
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, err
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.slow
@pytest.mark.parametrize("to_group", [False, True], ids=["parent", "group"])
def test_sigterm_stops_a_parallel_record_like_ctrl_c(tmp_path, cleanup, to_group):
    out = tmp_path / "rec"
    proc = _start(_params(tmp_path, episodes=6, hold_s=4.0), out, "--jobs", "2")
    cleanup.append(proc)
    # terminate while a worker is writing its bag: the partial folder must not survive
    assert _wait_for(lambda: bool(_partials(out)), 120), proc.stderr.read() if proc.stderr else ""
    workers = _children(proc.pid)
    assert len(workers) == 2
    # the whole group, as `timeout` and systemd send it; or the parent alone, as `kill` does
    (os.killpg if to_group else os.kill)(proc.pid, signal.SIGTERM)
    line = _terminated(proc)
    match = re.fullmatch(r"terminated: finished (\d+) episode\(s\): (.*); not recorded: (.*)", line)
    assert match, line
    finished = [] if match[2] == "none" else [s.split(" ")[0] for s in match[2].split(", ")]
    pending = [] if match[3] == "none" else match[3].split(", ")
    assert pending, "the run was terminated early: some episodes must be left"
    assert sorted(finished + pending) == [f"e{i}" for i in range(6)]
    assert _visible(out) == set(finished)
    assert not _partials(out)
    assert not any(pid_alive(w) for w in workers), "a worker survived its parent's SIGTERM"
    assert not (tmp_path / ".rec.lock").exists()


def _two_reports(tmp_path: Path, *, recordings: int) -> tuple[Path, Path]:
    from pipeline.stages.report import run_report
    from tests.analysis.bagfactory import paper_like, write_bag

    rec, out = tmp_path / "rec", tmp_path / "rep"
    for i in range(recordings):
        ctrl = ("pid", "ctc")[i % 2]
        write_bag(rec, paper_like(f"paper-{ctrl}-{i}", ctrl, duration_s=3.0, motion_end_s=2.0))
    run_report(recordings_dir=rec, out_dir=out)
    return rec, out


def _report(rec: Path, out: Path, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pipeline", "report", "--recordings", str(rec), "--out", str(out)],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        start_new_session=True, env=env,
    )  # fmt: skip


@pytest.mark.slow
def test_sigterm_during_a_report_keeps_the_earlier_report_and_leaves_no_staging(tmp_path, cleanup):
    from pipeline.stages.report import run_report
    from pipeline.stages.report_commit import MANIFEST

    rec, out = _two_reports(tmp_path, recordings=4)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    proc = _report(rec, out)
    cleanup.append(proc)
    # terminate once it is writing (its staging folder exists)
    assert _wait_for(lambda: any(".rep.tmp-" in p.name for p in tmp_path.iterdir()), 60)
    proc.send_signal(signal.SIGTERM)
    if proc.wait(timeout=30) == 0:
        pytest.skip("the report finished before SIGTERM arrived")
    assert _terminated(proc) == "terminated"
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    if after != before:
        # SIGTERM landed after the new outputs were moved in: every output is the new
        # one, never a mix (the report is deterministic)
        assert set(after) == set(before)
        assert after[Path("metrics.json")] == before[Path("metrics.json")]
    # no work folder inside --out (its manifest is the one hidden file a report writes)
    assert not any(p.name.startswith(".") and p.name != MANIFEST for p in out.rglob("*"))
    # The known defect of the Ctrl-C test above (a staging folder now and then survives
    # although its removal sits in a `finally`; seen once in ~60 runs here) applies: the
    # promise tested is that nothing under a final name changed and the next run sweeps it.
    run_report(recordings_dir=rec, out_dir=out)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.slow
def test_sigterm_while_reading_a_db3_with_a_wal_removes_the_temporary_copy(tmp_path, cleanup):
    from tests.log.test_salvage_db3 import _KILLED_RECORDER, db3_bag, rows

    rec = tmp_path / "rec"
    for i in range(6):  # a killed recorder's bags: each read from a copy in TMPDIR
        db, _ = db3_bag(rec / f"run{i}", "jazzy", False)
        keep = len(rows(db)) // 2
        subprocess.run([sys.executable, "-c", _KILLED_RECORDER, str(db), str(keep)], check=False)
        assert db.with_name(db.name + "-wal").stat().st_size > 0
    bags = {p.relative_to(rec): p.read_bytes() for p in rec.rglob("*") if p.is_file()}
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = _report(rec, tmp_path / "rep", env={**os.environ, "TMPDIR": str(tmp)})
    cleanup.append(proc)

    def copying() -> bool:
        return any(p.name.startswith("armlab-db3-") for p in tmp.iterdir())

    assert _wait_for(copying, 60), "no temporary copy of a bag seen"
    proc.send_signal(signal.SIGTERM)
    assert _terminated(proc) == "terminated"
    assert not copying(), "the temporary copy of the bag outlived the run"
    assert {p.relative_to(rec): p.read_bytes() for p in rec.rglob("*") if p.is_file()} == bags
    assert not (tmp_path / "rep").exists()
