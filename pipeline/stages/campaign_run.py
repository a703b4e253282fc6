"""Running a campaign: which episodes are already done, the run, and completion marks.

A campaign records into ``<out>/<campaign>/<episode key>/``. After an episode's bag is
published (atomically, by the bag writer), the parent writes a completion mark
``<out>/<campaign>/.done/<key>`` holding the episode's fingerprint: the hash of its full
settings and the recording code's version, then the SHA-256 of the bag's files. A
re-run skips an episode only when its mark matches its fingerprint today, its bag is
whole (metadata present, the MCAP file ends with the MCAP magic) and its bytes hash to
what the mark holds; anything else (no mark, a changed setting or code, a bag a killed
run left behind, a bag replaced or altered since: with a warning) runs again and
replaces what is there.

With ``keep_bags: {every: k}`` in the campaign, only every k-th episode keeps its bag.
Every episode is measured by the report's code from the recording its bag reads back as,
made in memory from its streams (:func:`pipeline.log.whole.episode_recording`), and kept
as its metric partial (:mod:`pipeline.stages.partials`); the others write no bag at all
and are marked done once their partial is written. Such an episode is done when its mark
matches and its partial (or a whole bag) is there. ``--episode KEY`` re-runs chosen
episodes into full bags.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import shutil
import stat
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import polars as pl

from pipeline.errors import ParamsError, PipelineError
from pipeline.fsutil import atomic_write_bytes, file_kind
from pipeline.params import (
    CampaignParams,
    Episode,
    Params,
    RandomAxis,
    RandomGoals,
    SimParams,
)
from pipeline.stages.campaign_expand import episode_fingerprint, expand
from pipeline.stages.provenance import git_commit

if TYPE_CHECKING:
    from pipeline.log.recording import Recording

DONE_DIR = ".done"
MCAP_MAGIC = b"\x89MCAP0\r\n"
MAX_MARK_BYTES = 4096  # a mark is a fingerprint and a hash: ~150 bytes
# Bag bytes per logged control step and joint (paper episode: 1.7 MB for ~4,300 steps x 6
# joints with /tf, ground truth, reference and effort), rounded up: a disk upper bound.
BAG_BYTES_PER_JOINT_STEP = 100
PARTIAL_BYTES = 32 << 10  # a metric partial and its mark, rounded up (measured ~20 KB)
DISK_SHARE = 0.9  # of the free space on --out a campaign may fill
MAX_CAMPAIGN_WALL_S = 7 * 24 * 3600.0  # longer is a typo (seeds: 1e6), not a study


@dataclass(frozen=True)
class CampaignRun:
    """What a campaign run will do.

    Attributes:
        name: the campaign.
        out_dir: ``<out>/<campaign>``.
        episodes: every episode of the campaign.
        pending: the episodes to run (all, with ``force``).
        skipped: keys of episodes already recorded with today's settings and code.
        stray: recordings in ``out_dir`` that are not episodes of the campaign (kept).
        commit: the recording code's version the fingerprints use.
        kept: keys of the episodes that keep their full bag (all without ``keep_bags``).
        sampled: the campaign keeps bags for a sample (``keep_bags``): every episode it
            records also writes its partial, and the others' bags are removed.
        changed: keys of pending episodes whose mark matched their settings but whose bag
            (or partial) is not the content the mark was written for: re-recorded, with
            a warning.
    """

    name: str
    out_dir: Path
    episodes: tuple[Episode, ...]
    pending: tuple[Episode, ...]
    skipped: tuple[str, ...]
    stray: tuple[str, ...]
    commit: str
    kept: frozenset[str] = frozenset()
    sampled: bool = False
    measure_code: str = ""
    changed: tuple[str, ...] = ()


def bag_is_whole(bag_dir: Path) -> bool:
    """A published rosbag2 folder: ``metadata.yaml`` and one MCAP file that ends with
    the MCAP magic (a file cut short does not). Reads 8 bytes, not the file."""
    if not (bag_dir / "metadata.yaml").is_file():
        return False
    mcaps = [p for p in bag_dir.iterdir() if p.suffix == ".mcap"]
    if len(mcaps) != 1:
        return False
    try:
        with open(mcaps[0], "rb") as f:
            size = f.seek(0, os.SEEK_END)
            if size < 2 * len(MCAP_MAGIC):
                return False
            f.seek(-len(MCAP_MAGIC), os.SEEK_END)
            return f.read() == MCAP_MAGIC
    except OSError:
        return False


class MarkError(PipelineError):
    """A completion mark (or the ``.done`` folder) is not the kind of file it must be."""


def _regular_text(path: Path, *, what: str) -> str | None:
    """The text of regular file ``path``; None when it does not exist. Never blocks: a
    FIFO or device is refused from ``lstat``/``fstat`` before (or without) reading.

    Raises:
        MarkError: it is a directory, a FIFO, a device or a socket.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
    except FileNotFoundError:
        return None
    except IsADirectoryError:
        raise MarkError(
            f"{path}: {what} is a directory, expected a file; remove it to re-run the episode"
        ) from None
    except OSError as err:  # ENXIO: a FIFO with no writer; EACCES, ...
        raise MarkError(f"{path}: cannot read the {what} ({err.strerror or err})") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = file_kind(mode)
            raise MarkError(
                f"{path}: {what} is {kind}, expected a regular file; remove it to re-run "
                "the episode"
            )
        with os.fdopen(fd, "rb", closefd=False) as fh:
            data = fh.read(MAX_MARK_BYTES + 1)
    finally:
        os.close(fd)
    if len(data) > MAX_MARK_BYTES:
        return ""  # not a mark we wrote: it matches nothing, the episode runs again
    return data.decode("ascii", "replace")


def check_done_dir(out_dir: Path) -> None:
    """Refuse a ``.done`` that exists and is not a folder (one line, nothing read).

    Raises:
        MarkError: ``<out>/<campaign>/.done`` is a file, a FIFO, a device, ...
    """
    folder = out_dir / DONE_DIR
    try:
        mode = os.stat(folder).st_mode
    except FileNotFoundError:
        return
    except OSError as err:
        raise MarkError(f"{folder}: cannot read the marks folder ({err.strerror or err})") from None
    if not stat.S_ISDIR(mode):
        kind = "a file" if stat.S_ISREG(mode) else file_kind(mode)
        raise MarkError(
            f"{folder}: the campaign's marks folder is {kind}, expected a directory; "
            "remove it (every episode then runs again)"
        )


def content_hash(path: Path) -> str | None:
    """``sha256:<hex>`` over what a mark vouches for: a bag folder's files (their names,
    sizes and bytes, in name order) or one file (a partial). None when it is missing.

    SHA-256 of the whole bag, not a hash of its MCAP chunk CRCs: measured 20 ms for a
    12.7 MB bag (3 ms for the paper's 1.7 MB episode), small beside recording it, and it
    also covers metadata.yaml, the summary and chunks whose CRC the writer left at 0.
    """
    h = hashlib.sha256()
    try:
        files = sorted(p for p in path.iterdir() if p.is_file()) if path.is_dir() else [path]
        for f in files:
            data = f.read_bytes()
            h.update(f"{f.name}\0{len(data)}\0".encode())
            h.update(data)
    except OSError:
        return None
    return f"sha256:{h.hexdigest()}"


def mark_state(
    out_dir: Path, episode: Episode, fingerprint: str, *, partial: str | None = None
) -> str:
    """What the episode's mark says: ``"done"`` (it matches ``fingerprint``, or ``partial``
    for an episode that keeps no bag, and the content it hashed is there unchanged),
    ``"changed"`` (it matches, but the bag or partial is not the one it was written for:
    replaced, bit-flipped, or a mark from before marks held a hash), or ``"run"``.

    Raises:
        MarkError: the mark or ``.done`` is of the wrong file type.
    """
    check_done_dir(out_dir)
    text = _regular_text(out_dir / DONE_DIR / episode.name, what="completion mark")
    if text is None:
        return "run"
    lines = text.split()
    mark = lines[0] if lines else ""
    held = lines[1] if len(lines) > 1 else ""
    if mark == fingerprint:
        target = out_dir / episode.name
        if not bag_is_whole(target):
            return "run"
    elif partial is not None and mark == partial:
        from pipeline.stages.partials import partial_path  # sampled campaigns only

        target = partial_path(out_dir, episode.name)
        if not target.is_file():
            return "run"
    else:
        return "run"
    return "done" if held and content_hash(target) == held else "changed"


def is_done(
    out_dir: Path, episode: Episode, fingerprint: str, *, partial: str | None = None
) -> bool:
    """The episode's mark matches ``fingerprint`` and its bag is whole and unchanged, or
    (when it need not keep its bag) the mark matches ``partial`` (its
    :func:`~pipeline.stages.partials.partial_fingerprint`) and its partial is there,
    unchanged."""
    return mark_state(out_dir, episode, fingerprint, partial=partial) == "done"


def kept_bags(campaign: CampaignParams, episodes: Sequence[Episode]) -> frozenset[str]:
    """Keys of the episodes that keep their full bag: all, or every k-th one (in the
    campaign's order, the first included) with ``keep_bags: {every: k}``."""
    every = campaign.keep_bags.every if campaign.keep_bags is not None else 1
    return frozenset(e.name for k, e in enumerate(episodes) if k % every == 0)


def mark_done(out_dir: Path, name: str, fingerprint: str, *, target: Path | None = None) -> None:
    """Write the completion mark atomically (a temporary name, then a rename): the
    fingerprint, then the :func:`content_hash` of ``target`` (the bag folder
    ``out_dir/name`` unless given: the partial of an episode that keeps no bag)."""
    check_done_dir(out_dir)
    folder = out_dir / DONE_DIR
    folder.mkdir(exist_ok=True)
    held = content_hash(out_dir / name if target is None else target) or ""
    atomic_write_bytes(folder / name, f"{fingerprint}\n{held}\n".encode("ascii"))


def unmark(out_dir: Path, name: str) -> None:
    """Remove episode ``name``'s mark (none is fine).

    Raises:
        MarkError: ``.done`` or the mark is of the wrong file type (a directory is never
            removed for the user).
    """
    check_done_dir(out_dir)
    path = out_dir / DONE_DIR / name
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    if stat.S_ISDIR(mode):
        raise MarkError(
            f"{path}: completion mark is a directory, expected a file; remove it to re-run "
            "the episode"
        )
    with contextlib.suppress(FileNotFoundError):
        path.unlink()


def plan_run(
    params: Params,
    name: str,
    *,
    out: Path,
    force: bool = False,
    only: Sequence[str] | None = None,
) -> CampaignRun:
    """Expand campaign ``name`` and find what ``<out>/<name>`` already holds.

    ``only``: run just these episode keys, each into its full bag (``--episode``: the
    bag of an episode kept as its partial, byte for byte as a full-bag run writes it).

    Raises:
        ParamsError: unknown campaign or a bad sweep or key (names the field).
    """
    episodes = expand(params, name)
    out_dir = out / name
    commit = git_commit()
    keys = {e.name for e in episodes}
    kept = kept_bags(params.campaigns[name], episodes)
    selected = episodes
    if only:
        unknown = [k for k in only if k not in keys]
        if unknown:
            raise ParamsError(
                f"--episode {unknown[0]}: no such episode in campaign {name} "
                "(`pipeline campaigns` lists its size; keys look like payload_kg-0.5.ctc.s3)"
            )
        wanted = set(only)
        selected = tuple(e for e in episodes if e.name in wanted)
        kept = kept | wanted
    keep = params.campaigns[name].keep_bags
    sampled = keep is not None and keep.every > 1
    measure_code = ""
    if sampled:  # a full-bag campaign loads no measuring code (dvc.yaml's campaign deps)
        from pipeline.stages.partials import measure_commit, partial_fingerprint

        measure_code = measure_commit()
    check_done_dir(out_dir)
    skipped: list[str] = []
    changed: list[str] = []
    pending: list[Episode] = []
    for e in selected:
        fingerprint = episode_fingerprint(e, commit=commit)
        partial = (
            partial_fingerprint(fingerprint, measure_code)
            if sampled and e.name not in kept
            else None
        )
        state = "run" if force else mark_state(out_dir, e, fingerprint, partial=partial)
        if state == "done":
            skipped.append(e.name)
            continue
        if state == "changed":
            changed.append(e.name)
        if sampled and not only:
            # the worker measures its bag into the partial (and drops the bag). A re-run by
            # key writes the bag only: its partial stays, and its parent may have used
            # polars already, whose thread pool a forked worker must not touch (it hangs).
            pending.append(
                dataclasses.replace(e, partial_code=measure_code, drop_bag=e.name not in kept)
            )
        else:
            pending.append(e)
    stray = (
        sorted(
            p.name
            for p in out_dir.iterdir()
            if p.is_dir() and not p.name.startswith(".") and p.name not in keys
        )
        if out_dir.is_dir()
        else []
    )
    return CampaignRun(
        name, out_dir, episodes, tuple(pending), tuple(skipped), tuple(stray), commit, kept,
        sampled=sampled, measure_code=measure_code, changed=tuple(changed),
    )  # fmt: skip


def distinct_settings(episodes: Sequence[Episode]) -> list[Episode]:
    """One episode per distinct (scenario, controller) pair: what input checks need to see."""
    seen: dict[str, Episode] = {}
    for e in episodes:
        key = json.dumps(
            [e.scenario.model_dump(), e.controller.model_dump()], sort_keys=True, default=str
        )
        seen.setdefault(key, e)
    return list(seen.values())


# per physics step and joint, measured 4-6 us (rounded up)
_PER_STEP_WALL_S = 1e-5


def _episode_cost(*, dof: int, duration_s: float, sim: SimParams) -> tuple[int, float]:
    """(bag bytes, wall seconds) of one episode of ``duration_s`` [s]."""
    control_s = sim.physics_dt_s * sim.control_period_steps
    steps = int(duration_s / control_s) + 1
    n_bytes = steps * dof * BAG_BYTES_PER_JOINT_STEP // sim.joint_state_decimation
    return n_bytes, steps * sim.control_period_steps * dof * _PER_STEP_WALL_S


def _refuse_too_big(
    params: Params, name: str, out_dir: Path, *, count: int, n_bytes: int, wall_s: float,
    jobs: int,
) -> None:  # fmt: skip
    probe = out_dir if out_dir.exists() else out_dir.parent
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    free = shutil.disk_usage(probe).free
    where = f"{params.source}: {params.where(name)}"
    if n_bytes > DISK_SHARE * free:
        raise ParamsError(
            f"{where}: {count:,} episodes would write about {n_bytes / 1e9:.3g} GB, "
            f"more than the {DISK_SHARE * free / 1e9:.3g} GB free on {probe}; sweep fewer "
            "values or seeds, or raise sim.joint_state_decimation"
        )
    if wall_s > MAX_CAMPAIGN_WALL_S:
        raise ParamsError(
            f"{where}: {count:,} episodes would run for about "
            f"{wall_s / 86400:.3g} days on {jobs} job(s); split the campaign or add jobs"
        )


def campaign_count(campaign: CampaignParams) -> int:
    """How many episodes a campaign has, counted from its params (nothing drawn or built)."""
    n = len(campaign.controllers) * len(campaign.seed_list)
    for spec in campaign.sweep.values():
        n *= spec.n if isinstance(spec, RandomAxis) else len(spec)
    if isinstance(campaign.goals, RandomGoals):
        n *= campaign.goals.random
    elif campaign.goals is not None:
        n *= len(campaign.goals)
    return n


def check_campaign_count(params: Params, name: str, *, out: Path, jobs: int) -> int:
    """Refuse a campaign too big for the disk or a week *before* it is expanded: its
    episodes counted from the params, each costed at its cheapest (the scenario's robot,
    the smallest swept ``hold_s`` / ``preroll_s``, no motion). Expanding 300,000 episodes
    takes a minute and 400 MB; counting them takes nothing. Returns the count.

    Raises:
        ParamsError: unknown campaign, or a lower bound already too big.
    """
    from pipeline.robots.loaders import load_spec

    if name not in params.campaigns:
        return 0  # expand() names the known ones
    campaign = params.campaigns[name]
    scenario = params.scenarios.get(campaign.scenario)
    if scenario is None:
        return 0  # expand() says what is wrong
    least = {"hold_s": scenario.hold_s, "preroll_s": scenario.preroll_s}
    for path, spec in campaign.sweep.items():
        if path in least:
            low = spec.uniform[0] if isinstance(spec, RandomAxis) else min(spec)
            least[path] = min(least[path], max(low, 0.0))
    count = campaign_count(campaign)
    n_bytes, wall_s = _episode_cost(
        dof=load_spec(scenario.robot).dof,
        duration_s=least["hold_s"] + least["preroll_s"],
        sim=params.sim,
    )
    _refuse_too_big(
        params, name, out / name, count=count, n_bytes=n_bytes * count,
        wall_s=wall_s * count / max(1, jobs), jobs=jobs,
    )  # fmt: skip
    return count


def check_campaign_size(
    params: Params, run: CampaignRun, *, motion_s: float, jobs: int
) -> tuple[int, float]:
    """Refuse a campaign whose bags would not fit on the disk of ``--out`` or that would
    run for longer than a week; returns the estimate (bytes, wall seconds).

    Args:
        motion_s: the reference's duration [s] (0 before planning: a lower bound).
    """
    from pipeline.robots.loaders import load_spec

    n_bytes = 0
    wall_s = 0.0
    dofs: dict[str, int] = {}
    for e in run.pending:
        dof = dofs.get(e.scenario.robot)
        if dof is None:
            dof = dofs[e.scenario.robot] = load_spec(e.scenario.robot).dof
        hold_s = max(e.scenario.hold_s, e.scenario.hold_max_s or 0.0)  # the longest
        duration_s = e.scenario.preroll_s + motion_s + hold_s
        b, w = _episode_cost(dof=dof, duration_s=duration_s, sim=e.sim)
        n_bytes += PARTIAL_BYTES if e.drop_bag else b
        wall_s += w
    wall_s /= max(1, jobs)
    _refuse_too_big(
        params, run.name, run.out_dir, count=len(run.pending), n_bytes=n_bytes,
        wall_s=wall_s, jobs=jobs,
    )  # fmt: skip
    return n_bytes, wall_s


def completion_marker(
    run: CampaignRun, emit: Callable[[str, str, float], None]
) -> Callable[[str, str, float], None]:
    """An ``on_event`` for :func:`pipeline.stages.record.record` that marks each episode
    done once this run published its bag (a new folder, or a replaced one) or, for an
    episode of a ``keep_bags`` campaign that does not keep its bag, its partial (the
    worker wrote it and no bag: :func:`keep_partial`)."""
    fingerprints = {e.name: episode_fingerprint(e, commit=run.commit) for e in run.pending}
    partials = {e.name: e for e in run.pending if e.drop_bag}

    def mtime(path: Path) -> int | None:
        try:
            return path.stat().st_mtime_ns
        except OSError:
            return None

    def partial_file(name: str) -> Path:
        from pipeline.stages.partials import partial_path

        return partial_path(run.out_dir, name)

    before: dict[str, tuple[int | None, int | None]] = {}
    for e in run.pending:
        unmark(run.out_dir, e.name)  # a stale mark must not survive a failed re-run
        partial = mtime(partial_file(e.name)) if e.name in partials else None
        before[e.name] = (mtime(run.out_dir / e.name), partial)

    def on_event(kind: str, name: str, value: float) -> None:
        if kind == "done" and name in fingerprints:
            bag = run.out_dir / name
            published = mtime(bag)
            if published is not None and published != before[name][0] and bag_is_whole(bag):
                mark_done(run.out_dir, name, fingerprints[name])
            elif name in partials:
                written = mtime(partial_file(name))
                if written is not None and written != before[name][1]:
                    from pipeline.stages.partials import partial_fingerprint

                    code = partials[name].partial_code or ""
                    mark_done(
                        run.out_dir, name, partial_fingerprint(fingerprints[name], code),
                        target=partial_file(name),
                    )  # fmt: skip
        emit(kind, name, value)

    return on_event


def keep_partial(
    out_dir: Path, name: str, *, measure_code: str, recording: Recording | None = None
) -> None:
    """Measure episode ``name`` into its partial: from ``recording`` (made in memory as
    its bag reads back: :func:`pipeline.log.whole.episode_recording`) or, without one,
    from its published bag ``out_dir/name``.

    Raises:
        PipelineError: the bag cannot be read, or the recording not measured.
    """
    from pipeline.stages.partials import measure_bag, measure_recording, partial_path, write_partial

    if recording is not None:
        partial = measure_recording(recording, measure_code=measure_code)
    else:
        partial = measure_bag(out_dir / name, measure_code=measure_code)
    write_partial(partial, partial_path(out_dir, name))


def sample_without_bags(run: CampaignRun) -> list[str]:
    """Keys of the episodes the report will show one by one (the median and the worst per
    condition and controller, or all of a small group: :func:`pipeline.analysis.measure.
    sample_roles`, from the episodes' partials) whose bag was not kept: re-run them by
    key (:func:`plan_run` ``only``) to keep their bags. Episodes with neither a partial
    nor a bag (failed) are left out, as the report leaves them out.

    Raises:
        ReportError: a partial is unreadable.
    """
    from pipeline.analysis.measure import sample_roles
    from pipeline.stages.partials import measure_bag, partial_path, read_partial

    rows: list[pl.DataFrame] = []
    metrics: list[pl.DataFrame] = []
    for e in run.episodes:
        path = partial_path(run.out_dir, e.name)
        if path.is_file():
            p = read_partial(path)
        elif bag_is_whole(run.out_dir / e.name):
            p = measure_bag(run.out_dir / e.name)
        else:
            continue
        rows.append(p.row)
        metrics.append(p.metrics)
    if not rows:
        return []
    roles = sample_roles(
        pl.concat(metrics, how="vertical_relaxed"), pl.concat(rows, how="vertical_relaxed")
    )
    return sorted(k for k in roles if not bag_is_whole(run.out_dir / k))
