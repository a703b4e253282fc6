"""rosbag2 directories: ``metadata.yaml`` (written per ROS distro, read for any), finding
bags and their storage files, and publishing a new bag atomically.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import shutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from pipeline.errors import RecordingError
from pipeline.fsutil import RENAME_EXCHANGE, RENAME_NOREPLACE, remove_stale
from pipeline.fsutil import renameat2 as _renameat2
from pipeline.log.mcap import not_regular
from pipeline.log.schemas import MESSAGE_ENCODING, RosDistro

METADATA_FILE = "metadata.yaml"
# The metadata version each distro's rosbag2 writes (Humble 0.15: 5; we write 8 for Jazzy,
# see metadata_yaml).
METADATA_VERSION: dict[RosDistro, int] = {"jazzy": 8, "humble": 5}


# --- writing metadata.yaml ------------------------------------------------------------------------


class _QuotedStr(str):
    """A string YAML writes double-quoted (like yaml-cpp does for the QoS string)."""


class _Dumper(yaml.SafeDumper):
    """Block style with indented sequences, as yaml-cpp writes rosbag2's metadata."""

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        super().increase_indent(flow, False)

    def ignore_aliases(self, data: Any) -> bool:
        return True  # repeat equal mappings instead of writing YAML anchors


_Dumper.add_representer(
    _QuotedStr,
    lambda dumper, data: dumper.represent_scalar("tag:yaml.org,2002:str", str(data), style='"'),
)


@dataclass(frozen=True)
class TopicInfo:
    """A topic as ``metadata.yaml`` lists it."""

    name: str
    type: str
    qos_yaml: str
    type_hash: str
    message_count: int


def metadata_yaml(
    file_name: str,
    *,
    topics: Sequence[TopicInfo],
    start_ns: int,
    end_ns: int,
    custom_data: Mapping[str, str],
    ros_distro: RosDistro,
) -> str:
    """rosbag2 ``metadata.yaml`` text for one MCAP file, as ``ros_distro`` writes it.

    Jazzy: version 8 (Iron's layout: QoS profiles as a YAML string with enum numbers,
    ``type_description_hash``, ``custom_data``, ``ros_distro``), which every reader since Iron
    accepts (Jazzy reads it alongside its own version 9, where QoS became a YAML list). Humble:
    version 5, the layout Humble's rosbag2 writes and reads (no hashes, custom data or distro;
    our settings stay in the MCAP metadata record).
    """
    duration = {"nanoseconds": end_ns - start_ns}
    starting = {"nanoseconds_since_epoch": start_ns}
    total = sum(t.message_count for t in topics)
    humble = ros_distro == "humble"

    def topic_metadata(t: TopicInfo) -> dict[str, Any]:
        meta: dict[str, Any] = {
            "name": t.name,
            "type": t.type,
            "serialization_format": MESSAGE_ENCODING,
            "offered_qos_profiles": _QuotedStr(t.qos_yaml),
        }
        if not humble:
            meta["type_description_hash"] = t.type_hash
        return meta

    info: dict[str, Any] = {
        "version": METADATA_VERSION[ros_distro],
        "storage_identifier": "mcap",
        "duration": duration,
        "starting_time": starting,
        "message_count": total,
        "topics_with_message_count": [
            {"topic_metadata": topic_metadata(t), "message_count": t.message_count} for t in topics
        ],
        "compression_format": _QuotedStr(""),
        "compression_mode": _QuotedStr(""),
        "relative_file_paths": [file_name],
        "files": [
            {
                "path": file_name,
                "starting_time": starting,
                "duration": duration,
                "message_count": total,
            }
        ],
    }
    fast = not humble and _json_quotable(custom_data)
    if not humble and not fast:
        info["custom_data"] = dict(custom_data)
    if not humble:
        info["ros_distro"] = ros_distro
    text: str = yaml.dump(
        {"rosbag2_bagfile_information": info},
        Dumper=_Dumper,
        sort_keys=False,
        default_flow_style=False,
        allow_unicode=True,
        width=1 << 30,
    )
    if fast:
        # PyYAML's pure-Python emitter walks a scalar character by character (~30 ms
        # for an episode's settings JSON, as much as its control loop): printable
        # ASCII strings go in as JSON strings instead, which are valid YAML
        # double-quoted scalars (only \" and \\ are escaped in them)
        tail = f"  ros_distro: {ros_distro}\n"
        assert text.endswith(tail)
        block = "".join(f"    {json.dumps(k)}: {json.dumps(v)}\n" for k, v in custom_data.items())
        text = text[: -len(tail)] + "  custom_data:\n" + block + tail
    return text


_PRINTABLE_ASCII = re.compile(r"[ -~]*")


def _json_quotable(custom_data: Mapping[str, str]) -> bool:
    """Every key and value a printable-ASCII string (so ``json.dumps`` gives a YAML
    double-quoted scalar with the same value), and at least one entry."""
    return bool(custom_data) and all(
        isinstance(x, str) and _PRINTABLE_ASCII.fullmatch(x) is not None
        for item in custom_data.items()
        for x in item
    )


# --- atomic publish ----------------------------------------------------------------


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _publish(tmp: Path, final: Path, *, force: bool) -> None:
    """Move the finished ``tmp`` directory to ``final`` (replacing it only with ``force``)."""
    if not os.path.lexists(final):
        if _renameat2(tmp, final, RENAME_NOREPLACE):
            return
        if os.path.lexists(final):  # pragma: no cover - lost a race without renameat2
            raise FileExistsError(errno.EEXIST, "exists", str(final))
        os.rename(tmp, final)
        return
    if not force:
        raise RecordingError(f"{final}: recording already exists; use --force to overwrite it")
    if _renameat2(tmp, final, RENAME_EXCHANGE):
        shutil.rmtree(tmp)  # now holds the old recording
        return
    old = final.with_name(f".{final.name}.old-{os.getpid()}")
    os.rename(final, old)
    os.rename(tmp, final)
    shutil.rmtree(old)


def write_bag_dir(bag_dir: Path, write: Callable[[Path], None], *, force: bool) -> int:
    """Build a rosbag2 directory with ``write(tmp_dir)`` and publish it atomically.

    The directory is built under ``.<name>.partial-<pid>`` next to the final name, fsynced,
    then renamed into place, so a killed run never leaves a partial bag under a final name
    (readers skip dot-directories, and the next write of that name removes stale partial
    directories of dead processes). With ``force`` the old bag is swapped out atomically
    (``renameat2(RENAME_EXCHANGE)`` where the kernel and file system support it), then
    deleted.

    Returns:
        Bytes written (sum of the file sizes).
    """
    parent = bag_dir.parent
    parent.mkdir(parents=True, exist_ok=True)
    # ``.<name>.partial-<pid>`` directories of killed writers
    remove_stale(parent, re.compile(rf"\.{re.escape(bag_dir.name)}\.partial-(?P<pid>\d+)"))
    tmp = parent / f".{bag_dir.name}.partial-{os.getpid()}"
    if os.path.lexists(tmp):
        shutil.rmtree(tmp)
    tmp.mkdir()
    try:
        write(tmp)
        for p in tmp.iterdir():
            with open(p, "rb+") as f:
                os.fsync(f.fileno())
        _fsync_dir(tmp)
        size = sum(p.stat().st_size for p in tmp.iterdir())
        _publish(tmp, bag_dir, force=force)
        _fsync_dir(parent)
    except BaseException:
        with contextlib.suppress(OSError):
            shutil.rmtree(tmp)
        raise
    return size


# --- finding bags -------------------------------------------------------------------------

STORAGE_SUFFIXES = (".mcap", ".db3")


def find_recordings(root: Path) -> list[Path]:
    """Every rosbag2 directory (has ``metadata.yaml``) and bare ``.mcap``/``.db3`` file
    under ``root``.

    Hidden files and folders (temporary names of a writer at work) are ignored.
    A ``root`` that is itself a recording is returned alone. Symlinked folders are
    followed (each real folder once, so a link to an ancestor ends).

    Raises:
        RecordingError: a folder that cannot be listed (permission denied): the
            recordings in it would be missing from the report without a word.
    """
    root = Path(root)
    if root.is_file():
        return [root]
    if (root / METADATA_FILE).is_file():
        return [root]

    def unlisted(err: OSError) -> None:
        raise RecordingError(
            f"{err.filename}: cannot list this folder ({err.strerror}); the recordings in it "
            "would be left out (fix its permissions or point --recordings elsewhere)"
        ) from err

    found: list[Path] = []
    seen: set[str] = set()
    for dirpath, dirnames, filenames in os.walk(root, onerror=unlisted, followlinks=True):
        real = os.path.realpath(dirpath)
        if real in seen:  # a symlink back to a folder already walked
            dirnames[:] = []
            continue
        seen.add(real)
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        here = Path(dirpath)
        if here != root and METADATA_FILE in filenames:
            found.append(here)
            dirnames[:] = []
            continue
        found.extend(
            here / f
            for f in sorted(filenames)
            if f.endswith(STORAGE_SUFFIXES) and not f.startswith(".")
        )
    return sorted(found)


def storage_files(source: Path) -> list[Path]:
    """The storage files of a recording, in order: a bare file, or the files a rosbag2
    directory's ``metadata.yaml`` lists (several for a split bag), else its ``*.mcap``.

    Raises:
        RecordingError: missing, unreadable metadata, no storage file, a listed file missing.
    """
    if not source.exists():
        raise RecordingError(f"{source}: no such file or directory")
    if source.is_file():
        return [source]
    if not source.is_dir():  # a FIFO or a device named .mcap
        raise RecordingError(f"{source}: {not_regular(source.stat().st_mode)}")
    meta = source / METADATA_FILE
    names: list[str] = []
    if meta.is_file():
        try:
            # the C loader when built: metadata.yaml carries the settings JSON (~10 ms in Python)
            loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
            info = yaml.load(meta.read_text(encoding="utf-8"), Loader=loader)
            rel = info["rosbag2_bagfile_information"]["relative_file_paths"]
            names = [str(r) for r in rel]
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError) as err:
            raise RecordingError(
                f"{meta}: not a rosbag2 metadata file (expected "
                "rosbag2_bagfile_information.relative_file_paths)"
            ) from err
    else:
        names = sorted(p.name for p in source.iterdir() if p.suffix in STORAGE_SUFFIXES)
    if not names:
        raise RecordingError(f"{source}: no .mcap or .db3 file in this rosbag2 directory")
    paths = [source / name for name in names]
    for path in paths:
        if not path.is_file():
            raise RecordingError(f"{path}: listed in metadata.yaml but missing")
        if path.suffix not in STORAGE_SUFFIXES:
            raise RecordingError(
                f"{path}: unknown storage file (expected {' or '.join(STORAGE_SUFFIXES)})"
            )
    return paths


def declared_counts(source: Path) -> dict[str, int] | None:
    """Messages per topic as a rosbag2 directory's ``metadata.yaml`` declares them
    (``topics_with_message_count``); None for a bare file, or a metadata file without
    counts (its other fields were checked by :func:`storage_files`)."""
    meta = source / METADATA_FILE
    if not meta.is_file():
        return None
    try:
        loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
        info = yaml.load(meta.read_text(encoding="utf-8"), Loader=loader)
        entries = info["rosbag2_bagfile_information"]["topics_with_message_count"]
        counts: dict[str, int] = {}
        for entry in entries:
            topic = str(entry["topic_metadata"]["name"])
            count = entry["message_count"]
            if not isinstance(count, int) or isinstance(count, bool) or count < 0:
                return None
            counts[topic] = counts.get(topic, 0) + count
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError):
        return None
    return counts or None
