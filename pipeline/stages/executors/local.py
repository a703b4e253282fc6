"""Episodes on this machine: in this process, or on a pool of forked worker processes.

The pool has one pipe per worker and no manager process (:mod:`pipeline.stages.workers`,
shared with the report's pool). Each worker dies with the parent (``PR_SET_PDEATHSIG`` on
Linux, a watcher thread elsewhere), ignores Ctrl-C and SIGTERM (the parent decides what it
cancels), and never publishes a recording for a run that is gone.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from pipeline.control.contain import is_builtin
from pipeline.params import Episode
from pipeline.stages.episode import EpisodeOutcome, remove_work_folders, run_one
from pipeline.stages.executors.executor import Emit, interrupted
from pipeline.stages.plans import ScenarioPlan
from pipeline.stages.workers import WorkerPool, become_worker, ready, tasks

CANCEL_GRACE_S = 3.0  # a worker writing its bag when Ctrl-C (SIGTERM) comes may finish it


@dataclass(frozen=True)
class LocalExecutor:
    """Episodes in this process (``jobs`` 1, or one episode), else on ``jobs`` workers."""

    jobs: int = 1

    def run(
        self,
        episodes: Sequence[Episode],
        plans: Mapping[str, ScenarioPlan],
        *,
        out_dir: Path,
        force: bool,
        commit: str,
        emit: Emit,
    ) -> dict[str, EpisodeOutcome]:
        """See :meth:`pipeline.stages.executors.executor.Executor.run`."""
        started_s = time.time()
        # plug-in code runs in a worker even at jobs 1: an os._exit, a crash or a C loop
        # in it fails its episode instead of ending (or hanging) this process
        plugins = any(not is_builtin(e.controller.type) for e in episodes)
        if (self.jobs > 1 and len(episodes) > 1) or plugins:
            return _run_pool(episodes, plans, out_dir=out_dir, force=force, commit=commit,
                             jobs=self.jobs, emit=emit, started_s=started_s)  # fmt: skip
        outcomes: dict[str, EpisodeOutcome] = {}
        try:
            for e in episodes:
                outcomes[e.name] = run_one(
                    e,
                    plans[e.name],
                    out_dir=out_dir,
                    force=force,
                    commit=commit,
                    progress=_episode_progress(emit, e.name),
                )
                emit("done", e.name, 1.0)
        except KeyboardInterrupt as err:
            remove_work_folders(out_dir)
            raise interrupted(episodes, outcomes, out_dir, started_s=started_s, cause=err) from None
        return outcomes


def _mp_context() -> mp.context.BaseContext:
    # fork where available: workers inherit the imported libraries (a spawned worker spends
    # ~2 s importing MuJoCo, Pinocchio and OMPL). No library here runs threads before the
    # fork, and the plan is computed before it, so nothing random is inherited mid-use.
    return mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")


def _episode_progress(emit: Emit, name: str) -> Callable[[float], None]:
    return lambda fraction: emit("episode", name, fraction)


class _Cancelled(BaseException):
    """Raised inside a worker's episode once the parent cancelled the run (not an error)."""


def _worker_main(
    conn: Connection, parent_pid: int, cancel: Any, out_dir: str, force: bool, commit: str
) -> None:
    """A pool worker: run the episodes the parent sends until it sends None."""
    become_worker(parent_pid)

    def before_write() -> None:
        if os.getppid() != parent_pid:
            os._exit(1)  # never publish a recording for a run that is gone
        if cancel.is_set():
            raise _Cancelled

    for episode, plan in tasks(conn):

        def progress(fraction: float, name: str = episode.name) -> None:
            if cancel.is_set():
                raise _Cancelled
            conn.send(("progress", name, fraction))

        try:
            outcome = run_one(
                episode, plan, out_dir=Path(out_dir), force=force, commit=commit,
                progress=progress, before_write=before_write,
            )  # fmt: skip
        except _Cancelled:
            conn.send(("cancelled", episode.name, None))
            continue
        conn.send(("done", episode.name, outcome))


def _run_pool(
    episodes: Sequence[Episode],
    plans: Mapping[str, ScenarioPlan],
    *,
    out_dir: Path,
    force: bool,
    commit: str,
    jobs: int,
    emit: Emit,
    started_s: float,
) -> dict[str, EpisodeOutcome]:
    """Run episodes on ``jobs`` worker processes, one pipe each (no manager process).

    A worker that dies (out-of-memory killer, a crash in a library) fails its episode
    and is replaced. Ctrl-C cancels the run: workers abandon their episodes at the next
    progress report (or just before writing), those already writing get
    :data:`CANCEL_GRACE_S` to finish, then every worker is killed and
    :class:`~pipeline.stages.executors.executor.Interrupted` raised.
    """
    ctx = _mp_context()
    cancel = ctx.Event()
    queued = [(e.name, (e, plans[e.name])) for e in episodes]
    by_name = {e.name: e.controller.type for e in episodes}
    outcomes: dict[str, EpisodeOutcome] = {}
    pool = WorkerPool[str](
        ctx, _worker_main, (cancel, str(out_dir), force, commit), name="pipeline-record-worker"
    )
    try:
        for _ in range(min(jobs, len(queued))):
            pool.start()
        for conn in list(pool.workers):
            pool.feed(conn, queued)
        while len(outcomes) < len(episodes):
            for conn in ready(list(pool.workers), timeout_s=0.5):
                current = pool.task(conn)
                try:
                    kind, name, value = conn.recv()
                except (EOFError, OSError):
                    exitcode = pool.drop(conn)
                    if current is not None and current not in outcomes:
                        outcomes[current] = _worker_died(current, exitcode, by_name[current])
                        emit("done", current, 1.0)
                    if queued:
                        pool.feed(pool.start(), queued)
                    continue
                if kind == "progress":
                    emit("episode", name, value)
                else:
                    outcomes[name] = value
                    emit("done", name, 1.0)
                    pool.feed(conn, queued)
            if not pool.workers and len(outcomes) < len(episodes):  # pragma: no cover - defensive
                for name, _ in queued:
                    outcomes[name] = _worker_died(name, None, by_name[name])
                queued.clear()
    except KeyboardInterrupt as err:
        cancel.set()
        _collect_until_idle(pool, outcomes, timeout_s=CANCEL_GRACE_S)
        pool.kill_all()
        remove_work_folders(out_dir)
        raise interrupted(episodes, outcomes, out_dir, started_s=started_s, cause=err) from None
    finally:
        pool.kill_all()
        remove_work_folders(out_dir, mine=False)  # what a worker that died mid-write left
    return outcomes


def _collect_until_idle(
    pool: WorkerPool[str], outcomes: dict[str, EpisodeOutcome], *, timeout_s: float
) -> None:
    """After a cancel: take the outcomes busy workers still send, until none is busy."""
    busy = pool.busy()
    deadline = time.monotonic() + timeout_s
    while busy and time.monotonic() < deadline:
        for conn in ready(busy, timeout_s=max(0.0, deadline - time.monotonic())):
            try:
                kind, name, value = conn.recv()
            except (EOFError, OSError):
                busy.remove(conn)
                continue
            if kind == "done":
                outcomes[name] = value
            if kind in ("done", "cancelled"):
                busy.remove(conn)


def _worker_died(name: str, exitcode: int | None, controller: str = "") -> EpisodeOutcome:
    how = f"killed by signal {-exitcode}" if exitcode is not None and exitcode < 0 else (
        f"exit code {exitcode}")  # fmt: skip
    hint = " (out of memory?)" if exitcode == -signal.SIGKILL else ""
    if controller and not is_builtin(controller):
        hint += f" while running plug-in controller '{controller}' (did it call os._exit?)"
    return EpisodeOutcome(
        name, "failed", f"its worker process died ({how}){hint}", "", float("nan"),
        float("nan"), 0.0, 0.0,
    )  # fmt: skip
