"""Output locks and output folders (pipeline/fsutil.py)."""

from __future__ import annotations

import os

import pytest

from pipeline.errors import PipelineError
from pipeline.fsutil import OutputLock, ensure_dir


def test_a_second_lock_on_the_same_folder_refuses_until_the_first_is_released(tmp_path):
    out = tmp_path / "rec"
    first = OutputLock(out, command="`pipeline record`")
    first.acquire()
    assert (tmp_path / ".rec.lock").read_text().strip() == str(os.getpid())
    with pytest.raises(PipelineError, match=rf"another `pipeline record` \(pid {os.getpid()}\)"):
        OutputLock(out, command="`pipeline record`").acquire()
    first.release()
    assert not (tmp_path / ".rec.lock").exists()
    with OutputLock(out, command="`pipeline record`"):
        pass


def test_a_lock_file_left_by_a_killed_run_does_not_block(tmp_path):
    (tmp_path / ".rec.lock").write_text("999999\n")  # no process holds a flock on it
    with OutputLock(tmp_path / "rec", command="`pipeline record`") as lock:
        assert lock.path.read_text().strip() == str(os.getpid())


def test_locks_on_different_folders_are_independent(tmp_path):
    with OutputLock(tmp_path / "a", command="x"), OutputLock(tmp_path / "b", command="x"):
        pass


def test_ensure_dir_names_the_problem(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(PipelineError, match="--out is a file"):
        ensure_dir(tmp_path / "file")
    with pytest.raises(PipelineError, match="cannot create the --out directory"):
        ensure_dir(tmp_path / "file" / "sub")
    assert ensure_dir(tmp_path / "new" / "deep").is_dir()
