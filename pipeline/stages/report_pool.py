"""The report's reading and measuring on worker processes (``pipeline report --jobs N``).

Each recording is read and measured (:meth:`pipeline.stages.report.Measured.measure`:
protocol view, episode row, metrics, the thinned error series) on one of ``jobs`` worker
processes; what comes back is the :class:`~pipeline.stages.report.Measurement` the report
keeps of it (a campaign episode without its frames). The parent merges the measurements in
the order of the recordings, so the report is the same, byte for byte, whatever ``jobs``.

Workers are spawned, not forked: a process that used Polars' thread pool cannot fork
safely (a forked child can hang on a lock the pool held). Each worker imports the
measuring code once and keeps its caches (the robot's FK chain) for every recording it
measures. One pipe per worker, one recording in flight per worker (memory: ``jobs``
recordings being measured, plus the parent's kept measurements). A worker ignores Ctrl-C
and SIGTERM, and the kernel kills it when the parent dies (``PR_SET_PDEATHSIG``); on
Ctrl-C, SIGTERM or any error the parent kills every worker before it raises.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import os
import pickle
import signal
import sys
import threading
from collections.abc import Callable, Generator, Iterator, Sequence
from multiprocessing import connection as mp_connection
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, cast

from pipeline.errors import ReportError

if TYPE_CHECKING:
    from pipeline.log.reader import ReadOptions

# With ``jobs`` left to the default, a worker per this many recordings at least: starting a
# worker costs about a second (importing the measuring code), a recording ~0.1 s.
RECORDINGS_PER_WORKER = 16
# The default never starts more workers than this (memory: a few hundred MB each).
MAX_DEFAULT_JOBS = 8

_PR_SET_PDEATHSIG = 1

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


def _die_with_parent(parent_pid: int) -> None:
    """Ask the kernel to kill this worker when its parent dies (Linux); exit now if the
    parent is already gone."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent_pid:
        os._exit(1)


@contextlib.contextmanager
def _born_ignoring_interrupts() -> Iterator[None]:
    """Start a process that ignores Ctrl-C and SIGTERM from its first instruction (a
    disposition to ignore survives ``exec``, and Python then installs no Ctrl-C handler),
    not only once its imports are done. The parent's own signals are held meanwhile and
    delivered after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    signal.pthread_sigmask(signal.SIG_BLOCK, held)
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in held}
    try:
        yield
    finally:
        for s, handler in previous.items():
            if handler is not None:  # None: set outside Python, cannot be put back
                signal.signal(s, handler)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, held)


def _sendable(err: BaseException) -> BaseException:
    """``err`` if it survives pickling, else a ReportError with its text."""
    try:
        pickle.loads(pickle.dumps(err))
    except Exception:
        return ReportError(f"{type(err).__name__}: {err}")
    return err


class Measurer(Protocol):
    """What measures recordings one by one (the report's
    :class:`~pipeline.stages.report.Measured`)."""

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
    _die_with_parent(parent_pid)
    # Ctrl-C reaches the whole process group, SIGTERM may too: the parent decides.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    measured = make()  # one per worker: its caches serve every recording it measures
    while True:
        try:
            source = conn.recv()
        except (EOFError, OSError):
            return
        if source is None:
            return
        outcome: Outcome
        try:
            outcome = measured.measure(Path(source), options)
        except Exception as err:
            outcome = ("raise", _sendable(err))
        conn.send(outcome)


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
    ctx = mp.get_context("spawn")
    queued = list(enumerate(sources))
    workers: dict[Connection, tuple[Any, int | None]] = {}  # conn -> (process, task index)
    done: dict[int, Outcome] = {}
    finished = 0
    next_out = 0

    def feed(conn: Connection) -> None:
        proc, _ = workers[conn]
        if queued:
            k, source = queued.pop(0)
            conn.send(str(source))
            workers[conn] = (proc, k)
        else:
            with contextlib.suppress(OSError):
                conn.send(None)
            workers[conn] = (proc, None)

    try:
        for _ in range(min(jobs, len(queued))):
            here, there = ctx.Pipe()
            proc = ctx.Process(
                target=_worker_main,
                args=(there, os.getpid(), options, make),
                name="pipeline-report-worker",
                daemon=True,
            )
            with _born_ignoring_interrupts():
                proc.start()
            there.close()
            workers[here] = (proc, None)
            feed(here)
        while next_out < len(sources):
            while next_out in done:
                yield sources[next_out], done.pop(next_out)
                next_out += 1
            if next_out >= len(sources):
                break
            busy = [c for c, (_, k) in workers.items() if k is not None]
            for item in mp_connection.wait(busy):
                conn = cast(Connection, item)
                proc, k = workers[conn]
                assert k is not None
                try:
                    outcome = conn.recv()
                except (EOFError, OSError):
                    proc.join(timeout=5)
                    raise ReportError(
                        f"{sources[k]}: the report worker measuring it died "
                        f"(exit code {proc.exitcode}; out of memory?); try fewer --jobs"
                    ) from None
                done[k] = outcome
                finished += 1
                progress(finished)
                feed(conn)
    finally:
        _kill_all(workers)


def _kill_all(workers: dict[Connection, tuple[Any, int | None]]) -> None:
    for conn, (proc, _) in list(workers.items()):
        if proc.is_alive():
            proc.kill()
        proc.join(timeout=5)
        conn.close()
    workers.clear()


__all__ = [
    "MAX_DEFAULT_JOBS",
    "RECORDINGS_PER_WORKER",
    "Measurer",
    "Outcome",
    "available_cpus",
    "default_jobs",
    "measure_in_workers",
]
