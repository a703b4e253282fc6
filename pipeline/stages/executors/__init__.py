"""Executors: where a record run's episodes run, chosen by name ("local", "ray").

Every executor runs :func:`pipeline.stages.episode.run_one` per episode and has one
method, :meth:`Executor.run`; the recordings' bytes do not depend on which one ran them.
"""

from __future__ import annotations

from collections.abc import Callable

from pipeline.errors import PipelineError
from pipeline.stages.executors.executor import Executor, Interrupted
from pipeline.stages.executors.local import LocalExecutor
from pipeline.stages.executors.ray import RayExecutor

# name -> factory(jobs, address); the CLI's --executor takes these names
EXECUTORS: dict[str, Callable[[int, str | None], Executor]] = {
    "local": lambda jobs, address: LocalExecutor(jobs=jobs),
    "ray": lambda jobs, address: RayExecutor(address=address),
}


def make_executor(name: str, *, jobs: int = 1, address: str | None = None) -> Executor:
    """The executor called ``name``.

    Args:
        jobs: episodes at once ("local": worker processes; "ray": its cluster decides).
        address: the Ray instance to join ("ray" only).

    Raises:
        PipelineError: unknown name (lists the known ones).
    """
    factory = EXECUTORS.get(name)
    if factory is None:
        raise PipelineError(f"unknown executor '{name}' (executors: {', '.join(EXECUTORS)})")
    return factory(jobs, address)


__all__ = ["EXECUTORS", "Executor", "Interrupted", "make_executor"]
