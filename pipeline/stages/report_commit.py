"""The report's atomic commit: a finished staging folder becomes ``--out`` in one step.

The report stage writes everything into a fresh staging folder beside ``out``
(:func:`staging_folder`); when all of it succeeded, :func:`commit` links the files of
``out`` that the previous report did not write (``plots/.gitignore``, notes) into it,
lists the report's own files in a manifest (:data:`MANIFEST`) and swaps the two folders'
names in one atomic step, so a failed or killed run never leaves a half-written file under
a final name, a mix of two reports, or a damaged earlier report. Only files a previous
report listed in its manifest are ever removed. :func:`recover` puts back an earlier
report a killed commit left renamed aside.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
from pathlib import Path

from pipeline.errors import ReportError
from pipeline.fsutil import exchange, pid_alive, remove_stale

# The files the last report wrote into --out, one relative path a line: the only files a
# later report removes (when it does not write them again). Everything else is the user's.
MANIFEST = ".pipeline-outputs"
# The commit's steps, in order; PIPELINE_FAULT_COMMIT=<step> dies there (tests only).
COMMIT_STEPS = ("staged", "carried", "listed", "half-swapped", "swapped")


def _fault(step: str) -> None:
    """Test hook: end the process as SIGKILL would, right at commit ``step``."""
    if os.environ.get("PIPELINE_FAULT_COMMIT") == step:
        os._exit(137)


def _manifest(out_dir: Path) -> set[str]:
    """The files the previous report wrote into ``out_dir`` (none without a manifest: a
    report from before manifests, or a folder the pipeline never wrote, is left alone)."""
    try:
        text = (out_dir / MANIFEST).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return set()
    return {line for line in text.splitlines() if line and not line.startswith("#")}


def _tree_files(root: Path) -> list[str]:
    """Files (and symlinks) under ``root``, relative, sorted."""
    out = []
    for folder, dirs, names in os.walk(root):
        rel = Path(folder).relative_to(root)
        out += [(rel / n).as_posix() for n in names]
        out += [(rel / d).as_posix() for d in dirs if (Path(folder) / d).is_symlink()]
    return sorted(out)


def _carry(out_dir: Path, staging: Path, *, ours: set[str]) -> None:
    """Copy into ``staging`` what ``out_dir`` holds that is not ours to replace or remove:
    the user's files (hard links, so nothing is duplicated on disk), symlinks and folders."""
    for folder, dirs, names in os.walk(out_dir):
        src_dir = Path(folder)
        rel_dir = src_dir.relative_to(out_dir)
        for name in [*dirs, *names]:
            src = src_dir / name
            rel = (rel_dir / name).as_posix()
            dst = staging / rel
            if rel in ours or dst.exists() or dst.is_symlink():
                continue
            if src.is_symlink():
                os.symlink(os.readlink(src), dst)
            elif src.is_dir():
                dst.mkdir()
                shutil.copystat(src, dst)
            else:
                try:
                    os.link(src, dst)
                except OSError:  # no hard links here (a FUSE mount, a link limit)
                    shutil.copy2(src, dst)
        dirs[:] = [d for d in dirs if not (src_dir / d).is_symlink()]


def commit(staging: Path, out_dir: Path) -> None:
    """Make the finished ``staging`` folder the report ``out_dir``, in one atomic step.

    ``staging`` gains what ``out_dir`` holds besides the previous report's own files (the
    user's notes, ``.gitignore`` files), then a manifest of the report's files; then the
    two folders swap names at once (:func:`exchange`), so ``out_dir`` holds either the
    whole earlier report or the whole new one at every instant, whatever kills the run.
    Afterwards ``staging`` holds the earlier folder, which the caller removes. Only files
    the previous report listed in its manifest disappear (stale figures, tables).

    Where the file system cannot swap, ``out_dir`` is renamed aside to
    ``.<out>.old-<pid>-<random>`` and the staging folder renamed in: a kill between the two
    leaves ``out_dir`` missing and the old report whole beside it, which the next run puts
    back (:func:`recover`) before anything else.

    Raises:
        OSError: a step failed; ``out_dir`` is as it was.
    """
    _fault("staged")
    written = _tree_files(staging)
    if out_dir.is_dir():
        _carry(out_dir, staging, ours=_manifest(out_dir) | set(written) | {MANIFEST})
        shutil.copystat(out_dir, staging)
    _fault("carried")
    (staging / MANIFEST).write_text(
        "# written by `pipeline report`; a later report removes these files only\n"
        + "".join(f"{rel}\n" for rel in written),
        encoding="utf-8",
    )
    _fault("listed")
    if not out_dir.exists():
        os.rename(staging, out_dir)
    elif not exchange(staging, out_dir):
        old = out_dir.parent / f".{out_dir.name}.old-{os.getpid()}-{secrets.token_hex(4)}"
        os.rename(out_dir, old)
        _fault("half-swapped")
        os.rename(staging, out_dir)
        os.rename(old, staging)  # the caller removes the earlier report with the staging
    _fault("swapped")


def _old_pattern(out_dir: Path) -> re.Pattern[str]:
    return re.compile(rf"\.{re.escape(out_dir.name)}\.old-(?P<pid>\d+)-[a-f0-9]+")


def recover(out_dir: Path) -> None:
    """Put back an earlier report a killed commit left renamed aside (``out_dir`` missing),
    then remove such folders of dead runs that are no longer needed."""
    pattern = _old_pattern(out_dir)
    if not out_dir.exists():
        try:
            aside = sorted(
                (p for p in out_dir.parent.iterdir() if pattern.fullmatch(p.name)),
                key=lambda p: p.stat().st_mtime,
            )
        except OSError:
            aside = []
        for path in reversed(aside):
            match = pattern.fullmatch(path.name)
            if match is not None and not pid_alive(int(match["pid"])):
                try:
                    os.rename(path, out_dir)
                except OSError as err:
                    raise ReportError(
                        f"{out_dir}: missing, and the earlier report a killed run left at "
                        f"{path} cannot be put back ({err.strerror}); rename it yourself"
                    ) from err
                break
    remove_stale(out_dir.parent, pattern)


def remove_tree(path: Path) -> None:
    """Remove the staging folder even if Ctrl-C lands while it is being removed (then
    finish removing it and let the interrupt go on)."""
    interrupt: KeyboardInterrupt | None = None
    for _ in range(5):
        try:
            shutil.rmtree(path, ignore_errors=True)
            break
        except KeyboardInterrupt as err:
            interrupt = err
    if interrupt is not None:
        raise interrupt


def staging_pattern(out_dir: Path) -> re.Pattern[str]:
    """The names of staging folders beside ``out_dir`` (a killed run's are stale)."""
    # ``.<out>.tmp-<pid>-<random>``; older runs wrote ``.<out>.tmp-<random>`` (no pid: stale
    # whenever we hold the lock)
    return re.compile(rf"\.{re.escape(out_dir.name)}\.tmp-(?:(?P<pid>\d+)-)?[A-Za-z0-9_]+")


def staging_folder(out_dir: Path) -> Path:
    """A fresh staging folder's path beside ``out_dir`` (not created):
    ``.<out>.tmp-<pid>-<random>``."""
    return out_dir.parent / f".{out_dir.name}.tmp-{os.getpid()}-{secrets.token_hex(4)}"
