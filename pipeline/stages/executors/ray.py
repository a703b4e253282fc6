"""Episodes on Ray (``pipeline record --executor ray``): the same tasks, the same bytes.

Each episode is one Ray task running :func:`pipeline.stages.episode.run_one`, which
writes its bag atomically under ``--out``; on a multi-node cluster ``--out`` must be a
filesystem every node mounts at the same path. Plans are put in the object store once
and shared by reference. Ray's worker processes live across tasks, so what a worker
loaded for one episode (robot spec, imported libraries) serves the next.

Ray is an optional extra: ``pip install 'armlab-pipeline[ray]'``.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.errors import PipelineError
from pipeline.params import Episode
from pipeline.stages.episode import EpisodeOutcome, failed_outcome, run_one
from pipeline.stages.executors.executor import Emit, interrupted
from pipeline.stages.plans import ScenarioPlan


def _episode_task(
    episode: Episode, plan: ScenarioPlan, out_dir: str, force: bool, commit: str
) -> EpisodeOutcome:
    return run_one(episode, plan, out_dir=Path(out_dir), force=force, commit=commit)


#: Attempts at starting a local Ray instance. Ray gives its raylet a fixed 30 s to register
#: (``ray/_private/node.py``); on a loaded machine (load 8+ on 2 cores) it may not, and a
#: second attempt after a clean shutdown usually does. A remote ``address`` gets one try.
LOCAL_START_ATTEMPTS = 3


def start_ray(*, address: str | None, num_cpus: int | None = None) -> None:
    """Join ``address`` or start a local Ray instance, waiting for it to be ready.

    A local start that times out is shut down and retried, up to
    :data:`LOCAL_START_ATTEMPTS` times in all.

    Raises:
        PipelineError: Ray cannot be started or joined (one line, Ray's first line kept).
    """
    import ray

    attempts = 1 if address else LOCAL_START_ATTEMPTS
    for attempt in range(1, attempts + 1):
        try:
            ray.init(
                address=address, num_cpus=num_cpus, include_dashboard=False,
                log_to_driver=False, configure_logging=False,
            )  # fmt: skip
            return
        except Exception as err:  # Ray raises a bare Exception on a
            # start-up timeout (a loaded machine, a support process that died)
            with contextlib.suppress(Exception):
                ray.shutdown()
            if attempt < attempts:
                continue
            where = address or "a local instance"
            lines = str(err).strip().splitlines()
            tried = f" after {attempts} attempts" if attempts > 1 else ""
            raise PipelineError(
                f"--executor ray: cannot start or join {where}{tried} "
                f"({lines[0] if lines else type(err).__name__})"
            ) from err


@dataclass(frozen=True)
class RayExecutor:
    """Episodes as Ray tasks, on the Ray instance this process joined or at ``address``.

    Uses the Ray instance this process already joined (``ray.init`` before the call),
    else joins ``address`` (``auto``, ``ray://host:10001``) or, without one, starts a
    local instance for the run and stops it after.
    """

    address: str | None = None

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
        """See :meth:`pipeline.stages.executors.executor.Executor.run`; a lost task fails its own.

        Raises:
            PipelineError: Ray is not installed or the cluster cannot be reached.
        """
        try:
            import ray
        except ImportError as err:
            raise PipelineError(
                "--executor ray needs Ray: pip install 'armlab-pipeline[ray]' (or ray[default])"
            ) from err
        started_s = time.time()
        started_here = not ray.is_initialized()
        if started_here:
            # ray.init replaces the SIGTERM handler with sys.exit (no cleanup of ours would
            # run, and the exit code would be 15); keep ours, which takes Ctrl-C's path
            on_sigterm = signal.getsignal(signal.SIGTERM)
            try:
                start_ray(address=self.address)
            finally:
                if threading.current_thread() is threading.main_thread() and on_sigterm is not None:
                    signal.signal(signal.SIGTERM, on_sigterm)
        outcomes: dict[str, EpisodeOutcome] = {}
        pending: dict[Any, str] = {}
        try:
            task = ray.remote(num_cpus=1, max_retries=0)(_episode_task)
            # one object per distinct plan, shared by the episodes that track it
            plan_refs = {id(plan): ray.put(plan) for plan in plans.values()}
            for e in episodes:
                ref = task.remote(e, plan_refs[id(plans[e.name])], str(out_dir), force, commit)
                pending[ref] = e.name
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1, timeout=0.5)
                for ref in done:
                    name = pending.pop(ref)
                    try:
                        outcomes[name] = ray.get(ref)
                    except ray.exceptions.RayError as err:
                        text = str(err).strip()
                        first = text.splitlines()[0] if text else repr(err)
                        outcomes[name] = failed_outcome(name, f"Ray task failed: {first}")
                    emit("done", name, 1.0)
        except KeyboardInterrupt as err:
            for ref in pending:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)
            raise interrupted(episodes, outcomes, out_dir, started_s=started_s, cause=err) from None
        finally:
            if started_here:
                ray.shutdown()
        return outcomes
