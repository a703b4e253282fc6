"""A campaign episode kept without its bag: its metric partials and settings.

A campaign with ``keep_bags: {every: k}`` keeps the full bag of every k-th episode; each
other episode's bag is written as usual, measured by the report's own code
(:meth:`pipeline.stages.report.Measured.add`, the same arrays a report of the full bag
reads), and replaced by ``<campaign>/.partials/<key>.pkl``: what the report keeps of an
episode once its frames are let go (the protocol view with the settings, the episode
row, the metric frame, the thinned error series and the task-space model). The report
reads these instead of the missing bags, so the campaign table is the same, exactly;
re-running the episode by its key reproduces the bag byte for byte (a recording depends
on its params and seed alone).

The file is a pickle of :class:`Partial`: written by this code for this code's report
(its ``format`` and the recording code's commit are checked on reading). It is written
to a temporary name and renamed, before the bag is removed.
"""

from __future__ import annotations

import os
import pickle
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline.analysis.protocol import ProtocolView
from pipeline.analysis.task_space import FLANGE_TOOL, TaskSpace, ToolOffset
from pipeline.errors import ReportError
from pipeline.log.reader import Recording

PARTIAL_DIR = ".partials"
PARTIAL_SUFFIX = ".pkl"
PARTIAL_FORMAT = 1  # bump when Partial or what it holds changes shape


@dataclass(frozen=True)
class Partial:
    """What the report keeps of one campaign episode, measured from its full bag.

    Attributes:
        format: :data:`PARTIAL_FORMAT` of the writer.
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


def measure_bag(bag_dir: Path, *, tool: ToolOffset = FLANGE_TOOL) -> Partial:
    """Read a bag and measure it exactly as ``pipeline report`` does.

    Raises:
        RecordingError: the bag cannot be read.
    """
    from pipeline.log.reader import read_recording
    from pipeline.stages.report import Measured

    measured = Measured(tool)
    rec = measured.add(read_recording(bag_dir, None, sink=measured))
    episode = rec.episode
    return Partial(
        format=PARTIAL_FORMAT,
        bag=bag_dir.name,
        tool=tool,
        recording=rec,
        view=measured.views[episode],
        row=measured.rows[episode],
        metrics=measured.metrics[episode],
        errors=measured.errors.get(episode),
        task_space={k: v for k, v in measured.task_space.items() if k == episode},
    )


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
