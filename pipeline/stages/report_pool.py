"""The report's reading and measuring on worker processes (``pipeline report --jobs N``).

Each recording is read and measured (:meth:`pipeline.analysis.measure.Measured.measure`:
protocol view, episode row, metrics, the thinned error series) on one of ``jobs`` worker
processes; what comes back is the :class:`~pipeline.stages.partials.Measurement` the report
keeps of it (a campaign episode without its frames). The parent merges the measurements in
the order of the recordings, so the report is the same, byte for byte, whatever ``jobs``.

Workers are spawned, not forked: a process that used Polars' thread pool cannot fork
safely (a forked child can hang on a lock the pool held). Each worker imports the
measuring code once and keeps its caches (the robot's FK chain) for every recording it
measures. One pipe per worker, one recording in flight per worker (memory: ``jobs``
recordings being measured, plus the parent's kept measurements). The pool's mechanics are
:mod:`pipeline.stages.workers`' (the record executor's too): a worker ignores Ctrl-C and
SIGTERM and dies with the parent; on Ctrl-C, SIGTERM or any error the parent kills every
worker before it raises.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
from collections.abc import Callable, Generator, Sequence
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from pipeline.errors import ReportError
from pipeline.memory import OUT_OF_MEMORY_HINT, out_of_memory
from pipeline.stages.workers import WorkerPool, become_worker, ready, tasks

if TYPE_CHECKING:
    from pipeline.log.reader import ReadOptions

# With ``jobs`` left to the default, a worker per this many recordings at least: starting a
# worker costs about a second (importing the measuring code), a recording ~0.1 s.
RECORDINGS_PER_WORKER = 16
# The default never starts more workers than this (memory: a few hundred MB each).
MAX_DEFAULT_JOBS = 8

# What measuring a recording gave: ("ok", its Measurement), ("bad", the text of the
# RecordingError that refused it) or ("raise", any other exception, raised by the parent).
Outcome = tuple[str, Any]


def available_cpus() -> int:
    """CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def default_jobs(recordings: int) -> int:
    """Workers for ``recordings`` when ``--jobs`` is not given: one per CPU (at most
    :data:`MAX_DEFAULT_JOBS`), and none (1: in this process) for a report too small to
    repay starting them (:data:`RECORDINGS_PER_WORKER`)."""
    return max(1, min(available_cpus(), MAX_DEFAULT_JOBS, recordings // RECORDINGS_PER_WORKER))


def _sendable(err: BaseException) -> BaseException:
    """``err`` if it survives pickling, else a ReportError with its text."""
    try:
        pickle.loads(pickle.dumps(err))
    except Exception:
        return ReportError(f"{type(err).__name__}: {err}")
    return err


class Measurer(Protocol):
    """What measures recordings one by one (the report's
    :class:`~pipeline.analysis.measure.Measured`)."""

    def measure(self, source: Path, options: ReadOptions | None) -> Outcome:
        """Read and measure ``source``; keep nothing of it."""
        ...


def _worker_main(
    conn: Connection,
    parent_pid: int,
    options: ReadOptions | None,
    make: Callable[[], Measurer],
) -> None:
    """A worker: measure the recordings the parent sends (a path) until it sends None."""
    become_worker(parent_pid)
    measured: Measurer | None = None
    try:
        measured = make()  # one per worker: its caches serve every recording it measures
    except Exception as err:  # its imports, under a memory limit: said per recording below
        if not out_of_memory(err):
            raise
        failed_start = err
    for source in tasks(conn):
        outcome: Outcome
        try:
            if measured is None:
                raise failed_start
            outcome = measured.measure(Path(source), options)
        except Exception as err:
            oom = out_of_memory(err)
            if oom:  # a MemoryError would reach the parent as a traceback
                err = ReportError(f"{source}: {oom} while measuring it: {OUT_OF_MEMORY_HINT}")
            outcome = ("raise", _sendable(err))
        try:
            conn.send(outcome)
        except (pickle.PicklingError, TypeError, AttributeError) as err:  # not a lost worker
            why = ReportError(f"{source}: cannot pass its measurement back ({err})")
            conn.send(("raise", why))


def measure_in_workers(
    sources: Sequence[Path],
    *,
    jobs: int,
    options: ReadOptions | None,
    make: Callable[[], Measurer],
    progress: Callable[[int], None],
) -> Generator[tuple[Path, Outcome], None, None]:
    """Measure ``sources`` on ``jobs`` worker processes, each with its own ``make()`` (a
    picklable factory: it is sent to the workers); yields (source, outcome) in the order of
    ``sources`` (``progress(done)`` as each one finishes, in any order).

    Every worker is killed when the iteration ends, however it ends (exhausted, an error,
    Ctrl-C or SIGTERM in the parent, the caller stopping early).

    Raises:
        ReportError: a worker died (out of memory, a crash in a library).
    """
    queued = [(k, str(source)) for k, source in enumerate(sources)]
    done: dict[int, Outcome] = {}
    finished = 0
    next_out = 0
    with WorkerPool[int](
        mp.get_context("spawn"), _worker_main, (options, make), name="pipeline-report-worker"
    ) as pool:
        for _ in range(min(jobs, len(queued))):
            pool.feed(pool.start(), queued)
        while next_out < len(sources):
            while next_out in done:
                yield sources[next_out], done.pop(next_out)
                next_out += 1
            if next_out >= len(sources):
                break
            for conn in ready(pool.busy()):
                k = pool.task(conn)
                assert k is not None
                try:
                    outcome = conn.recv()
                except (EOFError, OSError):
                    raise ReportError(
                        f"{sources[k]}: the report worker measuring it died "
                        f"(exit code {pool.drop(conn)}; out of memory?); try fewer --jobs"
                    ) from None
                done[k] = outcome
                finished += 1
                progress(finished)
                pool.feed(conn, queued)


__all__ = [
    "MAX_DEFAULT_JOBS",
    "RECORDINGS_PER_WORKER",
    "Measurer",
    "Outcome",
    "available_cpus",
    "default_jobs",
    "measure_in_workers",
]
