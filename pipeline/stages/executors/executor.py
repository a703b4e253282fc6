"""What every executor is: a way to run episodes that hands back one outcome each."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Protocol

from pipeline.errors import EXIT_INTERRUPTED, PipelineError, interrupt_exit
from pipeline.params import Episode
from pipeline.stages.episode import EpisodeOutcome
from pipeline.stages.plans import ScenarioPlan

Emit = Callable[[str, str, float], None]
"""``emit(kind, name, value)``: "episode" (fraction done) or "done" (value 1)."""


class Executor(Protocol):
    """Runs episodes with :func:`pipeline.stages.episode.run_one`; the bytes do not depend on it."""

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
        """Run ``episodes``; one outcome per episode, failures included.

        Args:
            plans: each episode's plan, by episode name (episodes may share one).
            out_dir: each episode writes ``out_dir/<episode name>``.
            force: replace existing recordings.
            commit: the recording code's version to record.
            emit: progress reports.

        Raises:
            Interrupted: Ctrl-C or SIGTERM; what finished and what did not.
        """
        ...


class Interrupted(PipelineError):
    """Ctrl-C (SIGINT) or SIGTERM during a record run: what finished and what did not.

    Attributes:
        finished: outcomes of the episodes that ended (ok, diverged or failed).
        unfinished: names of the episodes that were cancelled (running or queued).
        exit_code: 130 for Ctrl-C, 143 for SIGTERM (what shells report).
    """

    exit_code = EXIT_INTERRUPTED

    def __init__(
        self,
        finished: Sequence[EpisodeOutcome],
        unfinished: Sequence[str],
        *,
        cause: BaseException | None = None,
    ) -> None:
        self.finished = tuple(finished)
        self.unfinished = tuple(unfinished)
        word, self.exit_code = interrupt_exit(cause or KeyboardInterrupt())
        done = ", ".join(f"{o.name} ({o.status})" for o in self.finished) or "none"
        super().__init__(
            f"{word}: finished {len(self.finished)} episode(s): {done}; not recorded: "
            f"{', '.join(self.unfinished) or 'none'}"
        )


def interrupted(
    episodes: Sequence[Episode],
    outcomes: Mapping[str, EpisodeOutcome],
    out_dir: Path,
    *,
    started_s: float,
    cause: BaseException,
) -> Interrupted:
    """What finished: the outcomes received, plus any recording this run published whose
    summary the interrupt cut off (its folder is newer than the run, ``started_s``)."""
    finished = [outcomes[e.name] for e in episodes if e.name in outcomes]
    unfinished = []
    for e in episodes:
        if e.name in outcomes:
            continue
        try:
            # file times may lag time.time() by a clock tick
            published = (out_dir / e.name).stat().st_mtime >= started_s - 0.05
        except OSError:
            published = False
        if published:
            finished.append(
                EpisodeOutcome(e.name, "recorded", "summary lost to the interrupt", "",
                               float("nan"), float("nan"), 0.0, 0.0)
            )  # fmt: skip
        else:
            unfinished.append(e.name)
    return Interrupted(finished, unfinished, cause=cause)
