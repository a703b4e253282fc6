"""File-system guards shared by the stages: output folders, locks, leftovers of killed runs.

- :func:`ensure_dir` turns "--out is a file" or "cannot create it" into one line.
- :class:`OutputLock` lets one ``pipeline record`` / ``pipeline report`` at a time write
  into a folder; a second one refuses at once, naming the holder (``flock``: the kernel
  releases it when the holder dies, however it dies).
- :func:`remove_stale` deletes the hidden work folders (``.<name>.partial-<pid>``,
  ``.reports.tmp-<pid>-...``) that a killed process left behind, once their process is gone.
- :func:`check_out_dir` refuses an ``--out`` the pipeline cannot own (``""``, the current
  working folder or one holding it).
- :func:`exchange` swaps two folders in one atomic step (a commit that is whole or absent).
- :func:`atomic_write_bytes` writes a file so that a killed run never leaves it half-written
  under its final name. Every user-named output file (``identify fit --out``, ``identify
  excite --csv``, the layouts, the ik-check summary and figure, ...), the campaign partials
  and the mesh cache go through it:

  - a directory, a FIFO, a device or a socket at the path is refused in one line (the
    temp-file-and-rename would otherwise replace ``/dev/full`` or a FIFO by a file);
  - a symlink is written *through*: its target gets the new content (atomically, by a
    rename beside the target) and the link stays a link (see docs/robustness.md);
  - an existing file keeps its mode (0600 stays 0600) and, where allowed, its owner.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path
from types import TracebackType

from pipeline.errors import PipelineError

try:  # POSIX; elsewhere the lock is a no-op (documented in docs/robustness.md)
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]


def pid_alive(pid: int) -> bool:
    """Whether a process with this id exists (a zombie counts as gone)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            return f.read().rsplit(")", 1)[-1].split()[0] != "Z"
    except OSError:
        return True  # no /proc: trust kill()


def remove_stale(
    folder: Path, pattern: re.Pattern[str], *, also_pids: frozenset[int] = frozenset()
) -> list[Path]:
    """Delete entries of ``folder`` whose name fully matches ``pattern`` and whose owner is gone.

    Args:
        folder: where to look (missing folder: nothing to do).
        pattern: a regex with a named group ``pid`` (the owner's process id); an entry
            matching without a ``pid`` group value counts as ownerless, hence stale.
        also_pids: owners to treat as gone although alive (the caller's own leftovers).

    Returns:
        The entries removed.
    """
    removed: list[Path] = []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return removed
    for entry in entries:
        match = pattern.fullmatch(entry.name)
        if match is None:
            continue
        pid_text = match.groupdict().get("pid")
        pid = int(pid_text) if pid_text else 0
        if pid in also_pids or not pid_alive(pid):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    entry.unlink()
            removed.append(entry)
    return removed


def check_out_dir(text: str | Path, *, option: str = "--out") -> Path:
    """The resolved ``--out`` folder, refusing one the pipeline cannot own.

    An empty string is the current working folder to :class:`~pathlib.Path`; a stage that
    sweeps or swaps its output folder must never do that to the user's working folder (or
    a folder holding it, whose swap would leave the shell in a deleted directory).

    Raises:
        PipelineError: empty, the current working folder, or an ancestor of it.
    """
    if not str(text).strip():
        raise PipelineError(
            f"{option}: empty; name a folder for the outputs (e.g. {option} reports)"
        )
    resolved = Path(os.path.realpath(text))
    cwd = Path(os.path.realpath(os.getcwd()))
    if resolved == cwd or resolved in cwd.parents:
        what = (
            "the current working folder"
            if resolved == cwd
            else "a folder holding the current working folder"
        )
        raise PipelineError(
            f"{text}: {option} is {what} ({resolved}); name a folder of its own "
            f"(e.g. {option} reports), whose contents the pipeline manages"
        )
    return resolved


def ensure_dir(path: Path, *, option: str = "--out") -> Path:
    """Create ``path`` (and parents) as a writable folder.

    Raises:
        PipelineError: it is a file, or cannot be created or written.
    """
    if path.exists() and not path.is_dir():
        raise PipelineError(f"{path}: {option} is a file, expected a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise PipelineError(
            f"{path}: cannot create the {option} directory ({err.strerror or err})"
        ) from err
    if not os.access(path, os.W_OK | os.X_OK):
        raise PipelineError(f"{path}: {option} directory is not writable")
    return path


class OutputLock:
    """An exclusive lock on an output folder, held for one stage run.

    The lock file is ``.<folder name>.lock`` beside the folder (its parent must exist),
    where staging folders live too, and records the holder's pid for the message. It is
    removed on release; an acquirer that finds the file replaced while it waited for
    ``flock`` retries, so removal cannot let two holders in. A SIGKILLed holder leaves
    the file, unlocked: the next run takes it.

    Example::

        with OutputLock(out_dir, command="`pipeline record`"):
            ...
    """

    def __init__(self, folder: Path, *, command: str) -> None:
        # resolved: two runs through a symlink and its target take one lock
        self.folder = Path(os.path.realpath(folder))
        self.command = command
        self.path = self.folder.parent / f".{self.folder.name}.lock"
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock or raise at once.

        Raises:
            PipelineError: another process holds it (names its pid), or the lock file
                cannot be created.
        """
        if fcntl is None:  # pragma: no cover - Windows
            return
        for _ in range(10):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as err:
                raise PipelineError(
                    f"{self.path}: cannot create the lock file ({err.strerror or err})"
                ) from err
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as err:
                holder = _read_pid(fd)
                os.close(fd)
                if err.errno not in (errno.EWOULDBLOCK, errno.EACCES):
                    raise PipelineError(f"{self.path}: cannot lock ({err.strerror})") from err
                who = f" (pid {holder})" if holder else ""
                raise PipelineError(
                    f"{self.folder}: another {self.command}{who} is writing to this folder; "
                    "wait for it to finish or choose another --out"
                ) from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                try:
                    os.ftruncate(fd, 0)
                    os.write(fd, f"{os.getpid()}\n".encode())
                except OSError as err:  # a full disk: leave no empty lock file behind
                    with contextlib.suppress(OSError):
                        os.unlink(self.path)
                    os.close(fd)
                    raise PipelineError(
                        f"{self.path}: cannot write the lock file ({err.strerror or err})"
                    ) from err
                self._fd = fd
                return
            os.close(fd)  # the holder released and removed it meanwhile: take the new one
        raise PipelineError(f"{self.path}: lock file keeps changing; is another run looping?")

    def release(self) -> None:
        """Remove the lock file and drop the lock (idempotent)."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.path)
        os.close(self._fd)
        self._fd = None

    def __enter__(self) -> OutputLock:
        self.acquire()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()


def _read_pid(fd: int) -> int:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        return int(text) if text.isdigit() else 0
    except OSError:
        return 0


RENAME_NOREPLACE = 1  # linux/fs.h
RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def renameat2(src: Path, dst: Path, flags: int) -> bool:
    """Linux ``renameat2(2)``; False (nothing done) where the platform or file system does
    not support ``flags``.

    Raises:
        OSError: the rename itself failed (e.g. ``EEXIST``, ``EXDEV``, ``EBUSY``).
    """
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):  # pragma: no cover - not glibc >= 2.28
        return False
    rc = fn(_AT_FDCWD, os.fsencode(src), _AT_FDCWD, os.fsencode(dst), ctypes.c_uint(flags))
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(src), None, str(dst))


def exchange(a: Path, b: Path) -> bool:
    """Swap the two existing paths ``a`` and ``b`` in one atomic step
    (``RENAME_EXCHANGE``): every observer sees either both old names or both new.

    Returns:
        False where the system or file system cannot do it (then nothing changed and the
        caller falls back to two renames).

    Raises:
        OSError: the swap itself failed (e.g. ``EXDEV``, ``EBUSY`` for a mount point).
    """
    return renameat2(a, b, RENAME_EXCHANGE)


def file_kind(mode: int) -> str:
    """What a non-regular file is, in words for an error line ("a FIFO", "a device", ...)."""
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


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
