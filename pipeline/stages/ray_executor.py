"""Episodes on Ray (``pipeline record --executor ray``): the same tasks, the same bytes.

Each episode is one Ray task running :func:`pipeline.stages.record.run_one`, which
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
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from pipeline.errors import PipelineError
from pipeline.params import Episode
from pipeline.stages.record import EpisodeOutcome, ScenarioPlan, failed_outcome, run_one


def _episode_task(
    episode: Episode, plan: ScenarioPlan, out_dir: str, force: bool, commit: str
) -> EpisodeOutcome:
    return run_one(episode, plan, out_dir=Path(out_dir), force=force, commit=commit)


def run_on_ray(
    episodes: Sequence[Episode],
    plans: Mapping[str, ScenarioPlan],
    plan_of: Mapping[str, str],
    *,
    out_dir: Path,
    force: bool,
    commit: str,
    address: str | None,
    emit: Callable[[str, str, float], None],
) -> dict[str, EpisodeOutcome]:
    """Run ``episodes`` as Ray tasks; one outcome per episode (a lost task fails its own).

    Uses the Ray instance this process already joined (``ray.init`` before the call),
    else joins ``address`` (``auto``, ``ray://host:10001``) or, without one, starts a
    local instance for the run and stops it after.

    Args:
        plans: plan per plan key. plan_of: episode name -> its plan key.

    Raises:
        PipelineError: Ray is not installed or the cluster cannot be reached.
    """
    try:
        import ray
    except ImportError as err:
        raise PipelineError(
            "--executor ray needs Ray: pip install 'armlab-pipeline[ray]' (or ray[default])"
        ) from err
    started_here = not ray.is_initialized()
    if started_here:
        # ray.init replaces the SIGTERM handler with sys.exit (no cleanup of ours would
        # run, and the exit code would be 15); keep ours, which takes Ctrl-C's path
        on_sigterm = signal.getsignal(signal.SIGTERM)
        try:
            ray.init(
                address=address, include_dashboard=False, log_to_driver=False,
                configure_logging=False,
            )  # fmt: skip
        except (ConnectionError, RuntimeError, ValueError) as err:
            where = address or "a local instance"
            raise PipelineError(f"--executor ray: cannot start or join {where} ({err})") from err
        finally:
            if threading.current_thread() is threading.main_thread() and on_sigterm is not None:
                signal.signal(signal.SIGTERM, on_sigterm)
    outcomes: dict[str, EpisodeOutcome] = {}
    pending: dict[Any, str] = {}
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(_episode_task)
        plan_refs = {key: ray.put(plan) for key, plan in plans.items()}
        for e in episodes:
            ref = task.remote(e, plan_refs[plan_of[e.name]], str(out_dir), force, commit)
            pending[ref] = e.name
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1, timeout=0.5)
            for ref in done:
                name = pending.pop(ref)
                try:
                    outcomes[name] = ray.get(ref)
                except ray.exceptions.RayError as err:
                    first = str(err).strip().splitlines()[0] if str(err).strip() else repr(err)
                    outcomes[name] = failed_outcome(name, f"Ray task failed: {first}")
                emit("done", name, 1.0)
    except KeyboardInterrupt:
        for ref in pending:
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        raise
    finally:
        if started_here:
            ray.shutdown()
    return outcomes
