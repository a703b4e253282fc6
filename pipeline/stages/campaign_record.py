"""``pipeline record --campaign NAME`` without its terminal: the checks before any work, the
run under the campaign folder's lock, and the re-run that keeps the sampled episodes' bags.

What the user sees (progress bar, messages, the summary table) is the caller's: it passes
a :class:`CampaignView` (:mod:`pipeline.cli.record_cmd` draws it with Rich).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol

if TYPE_CHECKING:
    from pipeline.params import Params
    from pipeline.stages.campaign_run import CampaignRun
    from pipeline.stages.episode import EpisodeOutcome

# on_event(kind, episode, value): what record() reports as the campaign runs
OnEvent = Callable[[str, str, float], None]
# status: a progress note; warning: a warning shown as plain text; line: one raw stderr
# line (a warning before any work); stdout: the run's result line
MessageKind = Literal["status", "warning", "line", "stdout"]


class CampaignView(Protocol):
    """How a campaign run is shown."""

    def say(self, text: str, *, kind: MessageKind = "status") -> None:
        """One message (:data:`MessageKind`)."""

    def progress(self, run: CampaignRun) -> contextlib.AbstractContextManager[OnEvent]:
        """A progress display over ``run.pending`` while it is open; its callback takes the
        run's events."""


@dataclass(frozen=True)
class CampaignRecorded:
    """What ``record_campaign`` did.

    Attributes:
        run: the run as planned under the lock (episodes, skipped, out_dir).
        outcomes: one per episode run (failures included); None when all were recorded.
    """

    run: CampaignRun
    outcomes: list[EpisodeOutcome] | None


def record_campaign(
    loaded: Params,
    name: str,
    *,
    out: Path | None,
    jobs: int,
    force: bool,
    executor: str,
    address: str | None,
    only: Sequence[str] | None,
    view: CampaignView,
) -> CampaignRecorded:
    """Record campaign ``name`` of ``loaded`` into ``out/<name>/`` (default: recordings,
    or the extra recordings folder for an extra campaign), skipping what is recorded.

    Raises:
        PipelineError: a refused campaign (count, size, settings, a busy or unsafe folder),
            before anything is created.
    """
    from pipeline.fsutil import OutputLock, ensure_dir
    from pipeline.params import EXTRA_RECORDINGS_DIR
    from pipeline.stages.campaign_run import (
        check_campaign_count,
        check_campaign_size,
        distinct_settings,
        plan_run,
    )
    from pipeline.stages.record import check_outputs_free, missing_fact_lines, validate_episodes

    # an extra campaign stays out of the DVC report's recordings/
    default = EXTRA_RECORDINGS_DIR if name in loaded.extra_campaigns else "recordings"
    out_dir = Path(default) if out is None else out
    check_campaign_count(loaded, name, out=out_dir, jobs=jobs)  # before expanding: counted
    episodes = list(only) if only else None
    run = plan_run(loaded, name, out=out_dir, force=force, only=episodes)
    # every input error first: a refused run creates nothing
    validate_episodes(loaded, distinct_settings(run.pending))
    for line in missing_fact_lines(run.pending):
        view.say(f"warning: {line}", kind="line")
    check_campaign_size(loaded, run, motion_s=0.0, jobs=jobs)
    ensure_dir(run.out_dir)
    # one run per campaign folder at a time (two would write the same episodes)
    with OutputLock(run.out_dir, command=f"`pipeline record --campaign {name}`"):
        # what is done now that we own it
        run = plan_run(loaded, name, out=out_dir, force=force, only=episodes)
        check_outputs_free(run.pending, run.out_dir, force=True)  # sweeps dead runs' work
        outcomes = run_planned(loaded, run, jobs=jobs, executor=executor, address=address,
                               view=view)  # fmt: skip
        if run.sampled and not episodes:
            keep_sample_bags(loaded, run, jobs=jobs, executor=executor, address=address,
                             view=view)  # fmt: skip
    return CampaignRecorded(run=run, outcomes=outcomes)


def run_planned(
    loaded: Params, run: CampaignRun, *, jobs: int, executor: str, address: str | None,
    view: CampaignView,
) -> list[EpisodeOutcome] | None:  # fmt: skip
    """Run a planned campaign's pending episodes, each marked done as it finishes (None:
    nothing to run)."""
    from pipeline.stages.campaign_run import completion_marker
    from pipeline.stages.record import record

    name = run.name
    if run.skipped:
        view.say(f"{name}: {len(run.skipped)} of {len(run.episodes)} episode(s) already "
                 f"recorded with these settings and code; running {len(run.pending)}")  # fmt: skip
    if run.changed:
        more = f" (and {len(run.changed) - 1} more)" if len(run.changed) > 1 else ""
        view.say(f"warning: {run.out_dir}: {run.changed[0]}{more}: the recording does not "
                 "match its completion mark (replaced or altered); recording it again",
                 kind="warning")  # fmt: skip
    if run.stray:
        more = f" (and {len(run.stray) - 1} more)" if len(run.stray) > 1 else ""
        view.say(f"warning: {run.out_dir}: {run.stray[0]}{more} is not an episode of "
                 f"campaign {name} (left in place; the report will read it)",
                 kind="warning")  # fmt: skip
    if not run.pending:
        view.say(f"campaign {name}: all {len(run.episodes)} episode(s) recorded in "
                 f"{run.out_dir}/", kind="stdout")  # fmt: skip
        return None
    with view.progress(run) as on_event:
        return record(
            loaded, run.pending, out_dir=run.out_dir, jobs=jobs, force=True,
            on_event=completion_marker(run, on_event), executor=executor, address=address,
            commit=run.commit,
        )  # fmt: skip


def keep_sample_bags(
    loaded: Params, run: CampaignRun, *, jobs: int, executor: str, address: str | None,
    view: CampaignView,
) -> None:  # fmt: skip
    """After a ``keep_bags`` campaign: re-run by key the episodes the report shows one by
    one (median and worst per condition and controller) whose bags were not kept."""
    from pipeline.stages.campaign_run import plan_run, sample_without_bags

    keys = sample_without_bags(run)
    if not keys:
        return
    view.say(
        f"{run.name}: keeping the bags of {len(keys)} sampled episode(s) (median and worst "
        "per condition): re-running them by key"
    )
    rerun = plan_run(loaded, run.name, out=run.out_dir.parent, only=keys)
    run_planned(loaded, rerun, jobs=jobs, executor=executor, address=address, view=view)
