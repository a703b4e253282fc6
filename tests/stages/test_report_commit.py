"""The report commit is atomic: a kill at any step leaves the whole old or the whole new report."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.stages import report as report_stage
from pipeline.stages import report_commit
from tests.analysis.bagfactory import paper_like, write_bag

ROOT = Path(__file__).resolve().parents[2]
USER_FILES = {"notes.md": b"my notes\n", "plots/.gitignore": b"/errors.csv\n"}
# the CLI with the atomic swap unavailable (a file system without RENAME_EXCHANGE)
NO_EXCHANGE = (
    "import sys; import pipeline.stages.report_commit as r; r.exchange = lambda a, b: False; "
    "from pipeline.cli import main; sys.argv[0] = 'pipeline'; main()"
)


def _snapshot(out: Path) -> dict[str, bytes | bool]:
    """The folder's files and their bytes; the .rrd (whose bytes differ run to run) as
    whether it is whole: Rerun's footer ends it."""
    files: dict[str, bytes | bool] = {}
    for p in out.rglob("*"):
        if p.is_file():
            data = p.read_bytes()
            whole = data.endswith(b"RRF2FOOT\x01\x00\x00\x00")
            files[p.relative_to(out).as_posix()] = whole if p.name == "recording.rrd" else data
    return files


def _report(tmp: Path, out: Path, *, fault: str, swap: bool) -> int:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PIPELINE_FAULT_COMMIT": fault}
    head = ["-m", "pipeline"] if swap else ["-c", NO_EXCHANGE]
    args = ["report", "--recordings", str(tmp / "recordings"), "--out", str(out)]
    done = subprocess.run(
        [sys.executable, *head, *args], cwd=tmp, env=env, capture_output=True, timeout=300
    )
    return done.returncode


@pytest.fixture(scope="module")
def reports(tmp_path_factory: pytest.TempPathFactory) -> Snapshots:
    """Recordings, and the old (one episode) and new (two episodes) reports' files."""
    tmp = tmp_path_factory.mktemp("commit")
    write_bag(tmp / "recordings", paper_like("pid_ok", "pid", duration_s=1.5, motion_end_s=1.0))
    old = tmp / "old"
    report_stage.run_report(recordings_dir=tmp / "recordings", out_dir=old)
    write_bag(tmp / "recordings", paper_like("ctc_ok", "ctc", duration_s=1.5, motion_end_s=1.0))
    new = tmp / "new"
    report_stage.run_report(recordings_dir=tmp / "recordings", out_dir=new)
    for rel, data in USER_FILES.items():
        (old / rel).parent.mkdir(parents=True, exist_ok=True)
        (old / rel).write_bytes(data)
    return tmp, _snapshot(old), {**_snapshot(new), **USER_FILES}


Snapshots = tuple[Path, dict[str, bytes | bool], dict[str, bytes | bool]]


def _fresh_out(tmp: Path, name: str) -> Path:
    out = tmp / name
    shutil.copytree(tmp / "old", out, symlinks=True)
    return out


@pytest.mark.slow
@pytest.mark.parametrize(
    ("step", "swap"),
    [
        *((s, True) for s in report_commit.COMMIT_STEPS if s != "half-swapped"),
        ("half-swapped", False),
    ],
)
def test_kill_at_each_commit_step_leaves_the_whole_old_or_the_whole_new_report(
    reports: Snapshots, step: str, swap: bool
) -> None:
    tmp, old, new = reports
    out = _fresh_out(tmp, f"out-{step}")
    assert _report(tmp, out, fault=step, swap=swap) == 137
    if step == "half-swapped":
        # without an atomic swap the one window is `out` missing, the old report whole beside
        # it; the next run (even one that fails) puts it back before anything else
        assert not out.exists()
        (aside,) = [p for p in tmp.iterdir() if p.name.startswith(f".{out.name}.old-")]
        assert _snapshot(aside) == old
        (tmp / "recordings-none").mkdir()
        done = subprocess.run(
            [sys.executable, "-m", "pipeline", "report", "--recordings", "recordings-none",
             "--out", str(out)],
            cwd=tmp, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, timeout=300,
        )  # fmt: skip
        assert done.returncode == 1
    got = _snapshot(out)
    assert got in (old, new), sorted(set(got) ^ set(old)) or sorted(set(got) ^ set(new))
    assert got == (new if step == "swapped" else old)
    rrd = (out / "recording.rrd").read_bytes()
    assert (rrd == (tmp / "old" / "recording.rrd").read_bytes()) == (step != "swapped")
    # the next run cleans up after the killed one and commits the new report
    assert _report(tmp, out, fault="", swap=True) == 0
    assert _snapshot(out) == new
    assert [p.name for p in tmp.iterdir() if p.name.startswith(f".{out.name}")] == []
