"""A campaign episode kept without its bag: its metric partials and settings.

A campaign with ``keep_bags: {every: k}`` keeps the full bag of every k-th episode; each
other episode's bag is written as usual, measured by the report's own code
(:func:`pipeline.stages.report.measure_bag`, the same arrays a report of the full bag
reads), and replaced by ``<campaign>/.partials/<key>.pkl``: what the report keeps of an
episode once its frames are let go (the protocol view with the settings, the episode
row, the metric frame, the thinned error series and the task-space model). The report
reads these instead of the missing bags, so the campaign table is the same, exactly;
re-running the episode by its key reproduces the bag byte for byte (a recording depends
on its params and seed alone).

The file is a pickle of :class:`Partial`: written by this code for this code's report.
It carries the last commit of the code that measures (:data:`MEASURE_CODE`); the report
refuses a partial measured by other code (the campaign's completion marks fold it in
too, so a resumed campaign re-measures such episodes). It is written to a temporary
name and renamed, before the bag is removed.
"""

from __future__ import annotations

import hashlib
import os
import pickle
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from pipeline.errors import ReportError

if TYPE_CHECKING:  # only this file's types: a full-bag campaign loads no report code
    import numpy as np
    import polars as pl
    from numpy.typing import NDArray

    from pipeline.analysis.protocol import ProtocolView
    from pipeline.analysis.task_space import TaskSpace, ToolOffset
    from pipeline.log.reader import Recording
    from pipeline.report.campaigns import CampaignSection

PARTIAL_DIR = ".partials"
PARTIAL_SUFFIX = ".pkl"
PARTIAL_FORMAT = 1  # bump when Partial or what it holds changes shape
# The code a partial's numbers depend on beyond the recording (relative to pipeline/):
# the reader, the analysis and the report's measuring.
MEASURE_CODE = ("analysis", "log", "report", "stages/report.py", "stages/partials.py")


def measure_commit() -> str:
    """Last commit that changed :data:`MEASURE_CODE` ("" outside git)."""
    from pipeline.stages.provenance import git_commit

    return git_commit(MEASURE_CODE)


def partial_fingerprint(fingerprint: str, measure_code: str) -> str:
    """The completion mark of an episode kept as its partial: its recording's
    ``fingerprint`` with the measuring code's commit folded in."""
    return hashlib.sha256(f"{fingerprint}:{measure_code}".encode()).hexdigest()


@dataclass(frozen=True)
class Partial:
    """What the report keeps of one campaign episode, measured from its full bag.

    Attributes:
        format: :data:`PARTIAL_FORMAT` of the writer.
        measure_code: :func:`measure_commit` of the writer.
        bag: the bag's folder name (the episode key) it was measured from.
        tool: the TCP the task-space metrics were measured with.
        recording: the recording with its frames let go (settings, notes, counts).
        view: its protocol view (``view.recording`` is ``recording``).
        row: its row of :func:`pipeline.analysis.episodes.episode_table`.
        metrics: its rows of :func:`pipeline.analysis.metrics.joint_metrics`.
        errors: the thinned error series (times [s], errors [rad]) for the .rrd's bands.
        task_space: episode -> its FK model (empty when the bag has no robot model).
    """

    format: int
    measure_code: str
    bag: str
    tool: ToolOffset
    recording: Recording
    view: ProtocolView
    row: pl.DataFrame
    metrics: pl.DataFrame
    errors: tuple[NDArray[np.float64], NDArray[np.float64]] | None
    task_space: dict[str, TaskSpace]


def partial_path(campaign_dir: Path, key: str) -> Path:
    """Where episode ``key``'s partial lives."""
    return campaign_dir / PARTIAL_DIR / f"{key}{PARTIAL_SUFFIX}"


def write_partial(partial: Partial, path: Path) -> None:
    """Write ``partial`` atomically (a temporary name, then a rename)."""
    path.parent.mkdir(exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}"
    with open(tmp, "wb") as f:
        pickle.dump(partial, f, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, path)


def read_partial(path: Path) -> Partial:
    """Read a partial written by :func:`write_partial`.

    Raises:
        ReportError: unreadable, or written by another format of this code.
    """
    try:
        with open(path, "rb") as f:
            partial = pickle.load(f)  # our own file, from our own writer
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError) as err:
        raise ReportError(
            f"{path}: unreadable metric partial ({err}); re-run the campaign to rewrite it"
        ) from err
    if not isinstance(partial, Partial) or partial.format != PARTIAL_FORMAT:
        found = getattr(partial, "format", type(partial).__name__)
        raise ReportError(
            f"{path}: metric partial format {found}, expected {PARTIAL_FORMAT}; re-run the "
            "campaign with this code to rewrite it"
        )
    return partial


def find_partials(recordings_dir: Path) -> list[Path]:
    """Every partial under ``recordings_dir`` (its own ``.partials`` or a campaign's)."""
    return sorted(recordings_dir.glob(f"**/{PARTIAL_DIR}/*{PARTIAL_SUFFIX}"))


def bags_listed(
    section: CampaignSection, staging: Path, stem: str, names: list[str], missing: set[str]
) -> CampaignSection:
    """``section`` with the list of which episodes have bags (``<stem>.bags.csv``, written
    into ``staging``) and one line saying so."""
    import polars as pl

    from pipeline.analysis.campaign import TABLE_DIR

    rel = f"{TABLE_DIR}/{stem}.bags.csv"
    pl.DataFrame(
        {"episode": names, "bag": [e not in missing for e in names]},
        schema={"episode": pl.String, "bag": pl.Boolean},
    ).write_csv(staging / rel)
    kept = len(names) - len(missing)
    line = (
        f"Bags: {kept} of {len(names)} episodes have their bag (campaign `keep_bags`); the "
        f"other {len(missing)} were measured from their metric partials, by the same code. "
        f"`{rel}` lists which; `pipeline record --campaign {section.name} --episode KEY` "
        "re-runs one into its bag, byte for byte."
    )
    return replace(section, lines=(*section.lines, "", line), files=(*section.files, rel))
