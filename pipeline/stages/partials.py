"""A campaign episode kept without its bag: its metric partials and settings.

A campaign with ``keep_bags: {every: k}`` keeps the full bag of every k-th episode. Each
episode it records is also measured by the report's own code
(:func:`pipeline.stages.partials.measure_recording`) from the recording its bag reads back
as, made in memory from the episode's arrays (:mod:`pipeline.log.direct`: no encoding,
compression, file or read), and kept as ``<campaign>/.partials/<key>.arrow``: what the
report keeps of an episode once its frames are let go (the recording's facts and
settings, the protocol view, the episode row, the metric frame and the thinned error
series). The report reads these instead of the missing bags, so the campaign table is
the same, exactly; re-running the episode by its key reproduces the bag byte for byte (a
recording depends on its params and seed alone).

The format (no pickle: nothing in it runs code when read):

- ``<key>.arrow``: an Arrow IPC stream of one row: ``header`` (JSON: the format, the
  measuring code, the TCP, the recording's scalar facts, its metadata, the settings
  sections of its own, and the episode row's and metric rows' strings, integers and
  booleans), ``floats`` (their float64 columns, one after the other, bit for bit),
  ``errors_t`` / ``errors`` (the thinned error series, errors flattened joint-fastest).
- ``shared/<sha256>.json`` / ``.arrow``: what a campaign's episodes repeat, stored once
  and named by its content: the URDF, the planned trajectory, the settings sections
  :data:`SHARED_SECTIONS`, and the schemas of the frames (the recording's emptied
  frames, the row, the metrics). Workers write them independently (same content, same
  name: a race writes the same bytes).

A partial carries the last commit of the code that measures (:data:`MEASURE_CODE`); the
report refuses a partial measured by other code (the campaign's completion marks fold it
in too, so a resumed campaign re-measures such episodes). Every file is written to a
temporary name and renamed. The bag's own identity (SHA-256, size) is not known without
the bag: a partial's recording has ``sha256 = ""`` and ``size_bytes = 0``.
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline.analysis.measure import Measured, Measurement
from pipeline.analysis.task_space import FLANGE_TOOL
from pipeline.errors import ReportError
from pipeline.fsutil import atomic_write_bytes
from pipeline.log.reader import read_recording

if TYPE_CHECKING:
    import polars as pl

    from pipeline.analysis.task_space import ToolOffset
    from pipeline.log.reader import Recording
    from pipeline.report.campaign_section import CampaignSection

PARTIAL_DIR = ".partials"
PARTIAL_SUFFIX = ".arrow"
LEGACY_SUFFIX = ".pkl"  # format 1 (pickles): refused, rewritten by a re-run
SHARED_DIR = "shared"
PARTIAL_FORMAT = 2  # bump when Partial or what it holds changes shape
# settings sections a campaign's episodes share (per robot, scenario or condition,
# controller, plan): stored once; the drawn plant, safety and protocol stay per episode
SHARED_SECTIONS = ("robot", "scenario", "controller", "planner", "loop")
# The code a partial's numbers depend on beyond the recording (relative to pipeline/):
# the reader, the analysis and the report's measuring.
MEASURE_CODE = ("analysis", "log", "report", "stages/report.py", "stages/partials.py")
# Recording fields the header holds as JSON (the others: file location, metadata,
# settings, frames, URDF and plan, stored apart)
_APART = frozenset(
    ("source", "mcap_path", "metadata", "settings", "samples", "controller_states", "planned",
     "robot_description")
)  # fmt: skip
_TUPLES = ("joint_names", "notes")
_COLUMNS = ("header", "floats", "errors_t", "errors")


def measure_commit() -> str:
    """Last commit that changed :data:`MEASURE_CODE` ("" outside git)."""
    from pipeline.stages.provenance import git_commit

    return git_commit(MEASURE_CODE)


def partial_fingerprint(fingerprint: str, measure_code: str) -> str:
    """The completion mark of an episode kept as its partial: its recording's
    ``fingerprint`` with the measuring code's commit folded in."""
    return hashlib.sha256(f"{fingerprint}:{measure_code}".encode()).hexdigest()


@dataclass(frozen=True)
class Partial(Measurement):
    """What the report keeps of one campaign episode, measured from its recording: its
    :class:`Measurement` and what it was measured by.

    Attributes:
        format: :data:`PARTIAL_FORMAT` of the writer.
        measure_code: :func:`measure_commit` of the writer.
        bag: the bag's folder name (the episode key) it was measured as.
        tool: the TCP the task-space metrics were measured with.
    """

    format: int
    measure_code: str
    bag: str
    tool: ToolOffset

    @classmethod
    def of(cls, m: Measurement, *, measure_code: str, bag: str, tool: ToolOffset) -> Partial:
        """``m`` as the partial of bag ``bag`` in this writer's format."""
        kept = {f.name: getattr(m, f.name) for f in fields(Measurement)}
        return cls(**kept, format=PARTIAL_FORMAT, measure_code=measure_code, bag=bag, tool=tool)


def partial_path(campaign_dir: Path, key: str) -> Path:
    """Where episode ``key``'s partial lives."""
    return campaign_dir / PARTIAL_DIR / f"{key}{PARTIAL_SUFFIX}"


def _dumps(value: Any) -> str:
    """Compact, key-sorted JSON: the bag metadata's settings form (floats round-trip)."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def _share(folder: Path, data: bytes, suffix: str) -> str:
    """Store ``data`` once under its content's name in ``folder``; returns the name."""
    name = f"{hashlib.sha256(data).hexdigest()[:32]}{suffix}"
    path = folder / name
    if not path.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, data)
    return name


def _ipc(frame: pl.DataFrame) -> bytes:
    buf = io.BytesIO()
    frame.write_ipc_stream(buf, compression="zstd")  # ~16 KB a partial, not 21
    return buf.getvalue()


def write_partial(partial: Partial, path: Path) -> None:
    """Write ``partial`` (see the module doc) atomically, the shared parts first; a
    format-1 pickle of the same episode is removed."""
    import numpy as np
    import polars as pl

    shared = path.parent / SHARED_DIR
    rec = partial.recording

    def share_json(value: Any) -> str:
        return _share(shared, _dumps(value).encode(), ".json")

    meta = dict(rec.metadata)
    text = meta.pop("settings", None)
    settings: dict[str, Any] | None = None
    if text is not None:
        parsed = json.loads(text)
        settings = {"text": text}
        if isinstance(parsed, dict) and _dumps(parsed) == text:  # rebuilt exactly
            settings = {
                "own": {k: v for k, v in parsed.items() if k not in SHARED_SECTIONS},
                "shared": {k: share_json(parsed[k]) for k in SHARED_SECTIONS if k in parsed},
            }
    planned = rec.planned
    # the frames' schemas (the recording's emptied frames, the row's, the metrics'): shared
    schemas = pl.DataFrame(
        [
            pl.Series(k, [], dtype=pl.List(pl.Struct(frame.schema)))
            for k, frame in (
                ("samples", rec.samples),
                ("controller_states", rec.controller_states),
                ("row", partial.row),
                ("metrics", partial.metrics),
            )
        ]
    )
    row, row_floats = _split(partial.row)
    metrics, metric_floats = _split(partial.metrics)
    header = {
        "format": partial.format,
        "measure_code": partial.measure_code,
        "bag": partial.bag,
        "tool": {"xyz_m": list(partial.tool.xyz_m), "rpy_rad": list(partial.tool.rpy_rad)},
        "recording": {f.name: getattr(rec, f.name) for f in fields(rec) if f.name not in _APART},
        "metadata": meta,
        "settings": settings,
        "urdf": None if rec.robot_description is None else share_json(rec.robot_description),
        "planned": None
        if planned is None
        else share_json(
            {
                "joint_names": planned.joint_names,
                "times_s": planned.times_s.tolist(),
                "positions": planned.positions.tolist(),
                "velocities": planned.velocities.tolist(),
            }
        ),
        "schemas": _share(shared, _ipc(schemas), ".arrow"),
        "view": {
            "error_source": partial.view.error_source,
            "motion_start_s": partial.view.motion_start_s,
            "start_abs_error_rad": partial.view.start_abs_error_rad,
            "start_abs_effort_nm": partial.view.start_abs_effort_nm,
        },
        "row": row,
        "metrics": metrics,
    }
    t, e = partial.errors if partial.errors is not None else (None, None)
    floats = pl.concat([*row_floats, *metric_floats]) if row_floats or metric_floats else None
    table = pl.DataFrame(
        [
            pl.Series("header", [json.dumps(header)], dtype=pl.String),
            pl.Series("floats", [floats], dtype=pl.List(pl.Float64)),
            pl.Series("errors_t", [None if t is None else t], dtype=pl.List(pl.Float64)),
            pl.Series(
                "errors",
                [None if e is None else np.ascontiguousarray(e).reshape(-1)],
                dtype=pl.List(pl.Float64),
            ),
        ]
    )
    path.parent.mkdir(exist_ok=True)
    atomic_write_bytes(path, _ipc(table))
    path.with_suffix(LEGACY_SUFFIX).unlink(missing_ok=True)


def _split(frame: pl.DataFrame) -> tuple[dict[str, Any], list[pl.Series]]:
    """A frame's height and non-float columns as JSON lists (strings, integers, booleans:
    exact in JSON), and its float64 columns (kept as binary, bit for bit).

    Raises:
        ReportError: a column of another type.
    """
    import polars as pl

    others: dict[str, list[Any]] = {}
    floats: list[pl.Series] = []
    for col in frame.iter_columns():
        if col.dtype == pl.Float64:
            floats.append(col)
        elif col.dtype in (pl.String, pl.Int64, pl.Boolean, pl.Null):
            others[col.name] = col.to_list()
        else:
            raise ReportError(f"metric partial: column {col.name} is {col.dtype}, not kept")
    return {"height": frame.height, "columns": others}, floats


def _joined(
    schema: pl.Schema, split: dict[str, Any], floats: pl.Series, at: int
) -> tuple[pl.DataFrame, int]:
    """The frame :func:`_split` split (its float64 columns from ``floats[at:]``), and
    where the next frame's floats start."""
    import polars as pl

    columns = []
    n, others = int(split["height"]), split["columns"]
    for name, dtype in schema.items():
        if dtype == pl.Float64:
            columns.append(floats.slice(at, n).alias(name))
            at += n
        else:
            columns.append(pl.Series(name, others[name], dtype=dtype))
    return pl.DataFrame(columns), at


class _Shared:
    """The shared parts read so far (a report reads each once, unless it changed)."""

    def __init__(self) -> None:
        self.cache: dict[tuple[Path, int, int], Any] = {}

    def get(self, partial: Path, name: Any) -> Any:
        import polars as pl

        if not isinstance(name, str) or "/" in name:
            raise ValueError(f"shared part {name!r} is not a name")
        path = partial.parent / SHARED_DIR / name
        try:
            st = path.stat()
            key = (path, st.st_mtime_ns, st.st_size)
            if key in self.cache:
                return self.cache[key]
            data = path.read_bytes()
        except OSError as err:
            raise ReportError(
                f"{partial}: its shared part {path} is unreadable ({err.strerror or err}); "
                "re-run the campaign to rewrite it"
            ) from err
        if hashlib.sha256(data).hexdigest()[:32] != path.stem:
            raise ReportError(
                f"{partial}: its shared part {path} does not match its name (changed or cut "
                "short); re-run the campaign to rewrite it"
            )
        value = (
            pl.read_ipc_stream(io.BytesIO(data)) if path.suffix == ".arrow" else json.loads(data)
        )
        self.cache[key] = value
        return value


_SHARED = _Shared()
# (schemas part name, frame name) -> that frame, empty: see ``_parse``
_EMPTY_FRAMES: dict[tuple[str, str], pl.DataFrame] = {}


def read_partial(path: Path) -> Partial:
    """Read a partial written by :func:`write_partial`.

    Raises:
        ReportError: unreadable, not a partial, written by another format of this code,
            or its shared parts missing or changed (one line naming the file).
    """
    if path.suffix == LEGACY_SUFFIX:
        raise ReportError(
            f"{path}: metric partial format 1 (a pickle), expected {PARTIAL_FORMAT}; re-run "
            "the campaign with this code to rewrite it"
        )
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ReportError(
            f"{path}: unreadable metric partial ({err.strerror or err}); re-run the campaign "
            "to rewrite it"
        ) from err
    try:
        return _parse(path, data)
    except ReportError:
        raise
    except Exception as err:  # the boundary: a damaged or foreign file, in one line
        raise ReportError(
            f"{path}: unreadable metric partial ({type(err).__name__}: {err}); re-run the "
            "campaign to rewrite it"
        ) from err


def _parse(path: Path, data: bytes) -> Partial:
    import numpy as np
    import polars as pl

    from pipeline.analysis.protocol import ProtocolView
    from pipeline.analysis.task_space import ToolOffset, task_space_of
    from pipeline.log.labels import typed_settings
    from pipeline.log.reader import PlannedTrajectory, Recording

    table = pl.read_ipc_stream(io.BytesIO(data))
    if table.columns[:1] != ["header"] or table.height != 1:
        raise ValueError("not a metric partial")
    header = json.loads(table.item(0, "header"))
    found = header.get("format") if isinstance(header, dict) else None
    if found != PARTIAL_FORMAT or tuple(table.columns) != _COLUMNS:
        raise ReportError(
            f"{path}: metric partial format {found}, expected {PARTIAL_FORMAT}; re-run the "
            "campaign with this code to rewrite it"
        )
    meta: dict[str, str] = dict(header["metadata"])
    settings = header["settings"]
    if settings is not None:
        if "text" in settings:
            meta["settings"] = settings["text"]
        else:
            parts = dict(settings["own"])
            parts |= {k: _SHARED.get(path, v) for k, v in settings["shared"].items()}
            meta["settings"] = _dumps(parts)
        meta = dict(sorted(meta.items()))  # as the writer stores them
    typed = typed_settings(json.loads(meta["settings"]))[0] if "settings" in meta else None
    planned = None
    if header["planned"] is not None:
        p = _SHARED.get(path, header["planned"])
        planned = PlannedTrajectory(
            joint_names=tuple(p["joint_names"]),
            times_s=np.asarray(p["times_s"], dtype=np.float64),
            positions=np.asarray(p["positions"], dtype=np.float64),
            velocities=np.asarray(p["velocities"], dtype=np.float64),
        )
    schemas = _SHARED.get(path, header["schemas"])

    def empty(name: str) -> pl.DataFrame:
        # the schemas' part is named by its content: its empty frames are built once per
        # process (a frame from a schema costs ~0.2 ms, clearing one ~2 us)
        key = (str(header["schemas"]), name)
        frame = _EMPTY_FRAMES.get(key)
        if frame is None:
            frame = pl.DataFrame(schema=schemas.get_column(name).dtype.inner.to_schema())
            _EMPTY_FRAMES[key] = frame
        return frame.clear()

    scalars = dict(header["recording"])
    for key in _TUPLES:
        scalars[key] = tuple(scalars[key])
    source = path.parent.parent / str(header["bag"])
    rec = Recording(
        source=source,
        mcap_path=source / f"{source.name}_0.mcap",
        metadata=meta,
        settings=typed,
        samples=empty("samples"),
        controller_states=empty("controller_states"),
        planned=planned,
        robot_description=None if header["urdf"] is None else _SHARED.get(path, header["urdf"]),
        **scalars,
    )
    view = ProtocolView(recording=rec, settings=typed, **header["view"])
    xyz, rpy = header["tool"]["xyz_m"], header["tool"]["rpy_rad"]
    tool = ToolOffset((xyz[0], xyz[1], xyz[2]), (rpy[0], rpy[1], rpy[2]))
    floats = table.get_column("floats")[0]
    floats = pl.Series("floats", [], dtype=pl.Float64) if floats is None else floats
    row, at = _joined(empty("row").schema, header["row"], floats, 0)
    metrics, at = _joined(empty("metrics").schema, header["metrics"], floats, at)
    if at != floats.len():
        raise ValueError(f"{floats.len()} float values, {at} expected")
    errors = None
    t = table.get_column("errors_t")[0]
    if t is not None:
        t_s = t.to_numpy()
        e = table.get_column("errors")[0].to_numpy()
        errors = (t_s, e.reshape(t_s.size, -1) if t_s.size else e.reshape(0, len(rec.joint_names)))
    return Partial(
        format=PARTIAL_FORMAT,
        measure_code=str(header["measure_code"]),
        bag=str(header["bag"]),
        tool=tool,
        recording=rec,
        view=view,
        row=row,
        metrics=metrics,
        errors=errors,
        task_space=task_space_of(rec, tool),
    )


def find_partials(recordings_dir: Path) -> list[Path]:
    """Every partial under ``recordings_dir`` (its own ``.partials`` or a campaign's),
    format-1 pickles included (:func:`read_partial` refuses them)."""
    return sorted(
        p
        for suffix in (PARTIAL_SUFFIX, LEGACY_SUFFIX)
        for p in recordings_dir.glob(f"**/{PARTIAL_DIR}/*{suffix}")
    )


def bags_listed(
    section: CampaignSection, staging: Path, stem: str, names: list[str], missing: set[str]
) -> CampaignSection:
    """``section`` with the list of which episodes have bags (``<stem>.bags.csv``, written
    into ``staging``) and one line saying so."""
    import polars as pl

    from pipeline.analysis.campaign_tables import TABLE_DIR

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


def measure_bag(
    bag_dir: Path, *, tool: ToolOffset = FLANGE_TOOL, measure_code: str | None = None
) -> Partial:
    """Read a bag and measure it exactly as ``pipeline report`` does: its partial
    (:class:`Partial`).

    Raises:
        RecordingError: the bag cannot be read.
    """
    measured = Measured(tool)
    rec = measured.add(read_recording(bag_dir, None, sink=measured))
    return _partial(measured, rec, bag_dir.name, tool, measure_code)


def measure_recording(
    rec: Recording, *, tool: ToolOffset = FLANGE_TOOL, measure_code: str | None = None
) -> Partial:
    """Measure a recording read whole (or made in memory as its bag would read back:
    :func:`pipeline.log.direct.episode_recording`) exactly as ``pipeline report`` does."""
    measured = Measured(tool)
    return _partial(measured, measured.add(rec), rec.source.name, tool, measure_code)


def _partial(
    measured: Measured, rec: Recording, bag: str, tool: ToolOffset, measure_code: str | None
) -> Partial:
    return Partial.of(
        measured.take(rec.episode),
        measure_code=measure_commit() if measure_code is None else measure_code,
        bag=bag,
        tool=tool,
    )
