"""Files written so that a killed run never leaves a half-written file under its final name.

Every user-named output file (``identify fit --out``, ``identify excite --csv``, the
layouts, the ik-check summary and figure, ...) goes through :func:`atomic_write_bytes`:

- a directory, a FIFO, a device or a socket at the path is refused in one line (the
  temp-file-and-rename would otherwise replace ``/dev/full`` or a FIFO by a file);
- a symlink is written *through*: its target gets the new content (atomically, by a
  rename beside the target) and the link stays a link (see docs/robustness.md);
- an existing file keeps its mode (0600 stays 0600) and, where allowed, its owner.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from pathlib import Path

from pipeline.errors import PipelineError
from pipeline.fsutil import file_kind


class OutputPathError(PipelineError):
    """An output path names something that is not (and may not become) a regular file."""


def output_target(path: Path) -> tuple[Path, os.stat_result | None]:
    """Where writing ``path`` puts the bytes (a symlink's final target) and that file's
    current status (None: it does not exist yet).

    Raises:
        OutputPathError: the path (or its target) is a directory, FIFO, device or socket.
    """
    target = Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)
    try:
        st = os.stat(target)
    except FileNotFoundError:
        return target, None
    except OSError as err:
        raise OutputPathError(f"{path}: cannot write ({err.strerror or err})") from None
    if not stat.S_ISREG(st.st_mode):
        via = f" (through the symlink to {target})" if target != Path(path) else ""
        raise OutputPathError(
            f"{path}: is {file_kind(st.st_mode)}{via}; name a regular file to write"
        )
    return target, st


def check_output_file(path: Path) -> None:
    """Refuse, before any work, an output path that is not and cannot become a regular
    file (see :func:`output_target`)."""
    output_target(path)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to a temp file beside ``path``'s target, then rename it over it.

    A killed run leaves at most a ``.<name>.*.tmp`` file, never a truncated ``path``.
    A new file gets ordinary permissions (0666 minus the umask), like ``open(path, "w")``;
    a file already there keeps its mode and owner.

    Raises:
        OutputPathError: ``path`` is a directory, a FIFO, a device or a socket.
        OSError: the write itself failed.
    """
    target, st = output_target(path)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        if st is None:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; outputs are ordinary files
        else:
            os.chmod(tmp, stat.S_IMODE(st.st_mode))
            if (st.st_uid, st.st_gid) != (os.getuid(), os.getgid()):
                with contextlib.suppress(OSError):  # only root may give a file away
                    os.chown(tmp, st.st_uid, st.st_gid)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
