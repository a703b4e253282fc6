"""Out of memory is one line: `report` and `record` under an address-space limit (as
`ulimit -v` sets it) end in one `error: out of memory ...` line and exit 1, never a pyarrow
import traceback or a worker's MemoryError. The limits are the ones measured to fail at
different places (a library's import, a figure, the workers' start)."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.memory import near_address_limit, out_of_memory
from tests.analysis.bagfactory import paper_like, write_bag

REPO = Path(__file__).resolve().parents[2]


def _under_limit(args: list[str], limit_kb: int, cwd: Path) -> subprocess.CompletedProcess[str]:
    def limit() -> None:  # in the child before exec, as `ulimit -v` does
        resource.setrlimit(resource.RLIMIT_AS, (limit_kb * 1024, limit_kb * 1024))

    return subprocess.run(
        [sys.executable, "-m", "pipeline", *args],
        preexec_fn=limit,
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=300,
    )


# Polars' allocator reports a purge thread it could not start on stderr itself, before
# anything of ours runs; it is the library's own line, not a traceback (docs/robustness.md)
_LIBRARY_LINE = "<jemalloc>: "


def _one_oom_line(done: subprocess.CompletedProcess[str]) -> None:
    assert done.returncode == 1, done.stderr[-3000:]
    ours = "".join(
        line for line in done.stderr.splitlines(keepends=True) if not line.startswith(_LIBRARY_LINE)
    )
    assert ours.count("\n") == 1, done.stderr[-3000:]
    assert ours.startswith("error: out of memory"), done.stderr


@pytest.mark.slow
@pytest.mark.parametrize(("limit_kb", "jobs"), [(1_500_000, 1), (2_500_000, 1), (2_500_000, 2)])
def test_report_out_of_memory_is_one_line(tmp_path, limit_kb, jobs):
    for name in ("a", "b", "c"):
        write_bag(tmp_path / "bags" / name, paper_like(name, "pid", duration_s=1.5,
                                                       motion_end_s=1.0))  # fmt: skip
    done = _under_limit(["report", "--recordings", "bags", "--jobs", str(jobs)], limit_kb,
                        tmp_path)  # fmt: skip
    _one_oom_line(done)
    assert not (tmp_path / "reports").exists()


@pytest.mark.slow
def test_record_out_of_memory_is_one_line(tmp_path):
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = 0.3
    data["episodes"] = {"e0": {"scenario": "paper", "controller": "pid", "seed": 0}}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(data))
    done = _under_limit(["record", "--params", "params.yaml", "--out", "rec"], 500_000, tmp_path)
    _one_oom_line(done)
    # refused before any library loads: below its measured need the run could only fail, at
    # a place left to luck (glibc aborts from C while loading a library's thread-local data)
    assert "`pipeline record` needs at least 600 MiB of address space" in done.stderr
    assert not (tmp_path / "rec").exists()


def test_what_counts_as_out_of_memory():
    mapped = ImportError("libarrow.so.2600: failed to map segment from shared object")
    assert out_of_memory(mapped) == "out of memory while loading libarrow.so.2600"
    try:
        try:
            raise MemoryError
        except MemoryError as err:
            raise ValueError("wrapped") from err
    except ValueError as outer:
        assert out_of_memory(outer) == "out of memory"
    assert out_of_memory(ImportError("No module named 'x'")) is None
    assert out_of_memory(ValueError("bad value")) is None


@pytest.mark.parametrize(
    "err",
    [
        SystemError("error return without exception set"),
        SystemError("<built-in function x> returned NULL without setting an exception"),
        OSError(12, "Cannot allocate memory"),
        RuntimeError("can't start new thread"),
    ],
)
def test_the_shortages_seen_under_an_address_limit_read_as_out_of_memory(err):
    # each was seen as the first failure of `report` under RLIMIT_AS (CI logs)
    assert out_of_memory(err) is not None


@pytest.mark.parametrize(
    "err", [SystemError("bad call"), OSError(28, "No space left on device"), RuntimeError("x")]
)
def test_other_failures_are_not_called_out_of_memory(err):
    assert out_of_memory(err) is None


def test_near_the_address_limit_is_told_apart_from_far_below_it():
    mib = 1024 * 1024
    assert near_address_limit(used_bytes=900 * mib, limit_bytes=1000 * mib)
    assert not near_address_limit(used_bytes=100 * mib, limit_bytes=1000 * mib)


_UNKNOWN_WORDING = """
import resource, sys
from pipeline.memory import _virtual_size_bytes, out_of_memory
used = _virtual_size_bytes()
err = ImportError("libfoo.so: some wording no one has seen yet")
print("unlimited:", out_of_memory(err))
resource.setrlimit(resource.RLIMIT_AS, (used + 64 * 1024 * 1024, resource.RLIM_INFINITY))
print("at limit:", out_of_memory(err))
print("other kind:", out_of_memory(ValueError("bad value")))
"""


def test_an_import_that_fails_at_the_address_limit_is_out_of_memory_whatever_its_wording():
    # a real RLIMIT_AS in a child: the same unknown wording is out of memory only at the limit
    done = subprocess.run(
        [sys.executable, "-c", _UNKNOWN_WORDING],
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    lines = dict(line.split(": ", 1) for line in done.stdout.splitlines())
    assert lines["unlimited"] == "None"
    assert lines["at limit"].startswith("out of memory (at the address-space limit")
    assert lines["other kind"] == "None"
