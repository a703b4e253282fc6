"""Worker processes on pipes: what the record executor's pool and the report's share.

One pipe per worker and no manager process. The parent starts the workers
(:class:`WorkerPool`), gives each one task at a time (:meth:`WorkerPool.feed`) and kills
every worker when it stops, however it stops (:meth:`WorkerPool.kill_all`: an error,
Ctrl-C or SIGTERM in the parent). A worker (:func:`become_worker`) asks the kernel to
kill it when its parent dies (``prctl(PR_SET_PDEATHSIG)`` on Linux, a watcher thread
elsewhere) and ignores Ctrl-C and SIGTERM: they reach the whole process group, and the
parent decides what it cancels. It takes tasks (:func:`tasks`) until the parent sends
None or goes away.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from multiprocessing import connection as mp_connection
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any, Generic, TypeVar, cast

if TYPE_CHECKING:
    from multiprocessing.context import BaseContext
    from multiprocessing.process import BaseProcess

K = TypeVar("K")  # what names a task (an episode's name, a recording's index)

_PR_SET_PDEATHSIG = 1


def die_with_parent(parent_pid: int) -> None:
    """Make this (worker) process end when ``parent_pid`` does, however it ends.

    Linux: the kernel sends SIGKILL at the parent's death (``PR_SET_PDEATHSIG``). Elsewhere
    a daemon thread polls ``getppid``. Either way a worker never outlives its parent.
    """
    armed = False
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)
    if not armed:

        def watch() -> None:
            while os.getppid() == parent_pid:
                time.sleep(0.2)
            os._exit(1)

        threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def become_worker(parent_pid: int) -> None:
    """A worker's first step: die with ``parent_pid``, ignore Ctrl-C and SIGTERM."""
    die_with_parent(parent_pid)
    # Ctrl-C reaches the whole process group, and so does SIGTERM from `timeout`, systemd
    # or a CI runner; the parent decides what it cancels (and kills the workers).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def tasks(conn: Connection) -> Iterator[Any]:
    """The tasks the parent sends on ``conn``, until it sends None or goes away."""
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        yield task


@contextlib.contextmanager
def born_ignoring_interrupts() -> Iterator[None]:
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


def ready(conns: list[Connection], timeout_s: float | None = None) -> list[Connection]:
    """Those of ``conns`` with something to read (or closed), within ``timeout_s`` (None:
    until one has)."""
    return [cast(Connection, c) for c in mp_connection.wait(conns, timeout=timeout_s)]


class WorkerPool(Generic[K]):
    """Worker processes, one pipe each, and the task each one is on.

    Each worker runs ``target(conn, parent_pid, *args)``, which should call
    :func:`become_worker` first and take its work from :func:`tasks`. Use it as a context
    manager: every worker is killed when the block ends, however it ends.

    Args:
        ctx: the multiprocessing context (fork or spawn).
        target: the worker's function (picklable for spawn: a module-level function).
        args: its arguments after the pipe and the parent's pid.
        name: the workers' process name.
    """

    def __init__(
        self, ctx: BaseContext, target: Callable[..., None], args: tuple[Any, ...], *, name: str
    ) -> None:
        self.ctx = ctx
        self.target = target
        self.args = args
        self.name = name
        self.workers: dict[Connection, tuple[BaseProcess, K | None]] = {}

    def __enter__(self) -> WorkerPool[K]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.kill_all()

    def start(self) -> Connection:
        """Start one more (idle) worker; its end of the pipe."""
        here, there = self.ctx.Pipe()
        proc = self.ctx.Process(  # type: ignore[attr-defined]
            target=self.target, args=(there, os.getpid(), *self.args), name=self.name,
            daemon=True,
        )  # fmt: skip
        # A spawned worker spends a second importing before it could ignore Ctrl-C, so it
        # is born ignoring it; a forked one ignores it at once (and would inherit the mask).
        hold = self.ctx.get_start_method() != "fork"
        with born_ignoring_interrupts() if hold else contextlib.nullcontext():
            proc.start()
        there.close()
        self.workers[here] = (proc, None)
        return here

    def feed(self, conn: Connection, queued: list[tuple[K, Any]]) -> None:
        """Send the worker on ``conn`` the first of ``queued`` (key, message), taken off
        the list; or, when none is left, None: it exits."""
        proc, _ = self.workers[conn]
        if queued:
            key, message = queued.pop(0)
            conn.send(message)
            self.workers[conn] = (proc, key)
        else:
            with contextlib.suppress(OSError):
                conn.send(None)
            self.workers[conn] = (proc, None)

    def task(self, conn: Connection) -> K | None:
        """The key of the task the worker on ``conn`` is on (None: idle)."""
        return self.workers[conn][1]

    def busy(self) -> list[Connection]:
        """The pipes of the workers on a task."""
        return [conn for conn, (_, key) in self.workers.items() if key is not None]

    def drop(self, conn: Connection) -> int | None:
        """Forget the worker on ``conn``, whose pipe broke (it died); its exit code."""
        proc, _ = self.workers.pop(conn)
        proc.join(timeout=5)
        conn.close()
        return proc.exitcode

    def kill_all(self) -> None:
        """Kill every worker and close its pipe."""
        for conn, (proc, _) in list(self.workers.items()):
            if proc.is_alive():
                proc.kill()
            proc.join(timeout=5)
            conn.close()
        self.workers.clear()


__all__ = [
    "WorkerPool",
    "become_worker",
    "born_ignoring_interrupts",
    "die_with_parent",
    "ready",
    "tasks",
]
