"""A Ray-driven ``record`` runs in a child process this one supervises.

When one of Ray's own processes dies (the dashboard agent, the raylet), Ray's C++ core
worker ends the driver process at once (``QuickExit``): no Python ``finally``, no
``atexit``, so the driver cannot say what happened. The run is therefore started as a
child of a small parent that only waits: the child marks a Python-level exit in a file;
a child that ends without the mark was ended by Ray (or by a signal), and the parent
prints the one ``error:`` line the user is owed and exits non-zero.

The parent forwards SIGINT and SIGTERM to the child (the child runs in its own process
group, so a terminal's Ctrl-C reaches it once, through the parent), and the child gets
SIGTERM if the parent dies (``PR_SET_PDEATHSIG``): nothing is left running. Standard
library only: the parent never imports the pipeline's heavy libraries.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from types import FrameType

MARK_ENV = "ARMLAB_SUPERVISED_EXIT_MARK"
"""Environment variable naming the file the supervised child writes when Python exits it."""

_PR_SET_PDEATHSIG = 1


def drives_ray(args: Sequence[str]) -> bool:
    """True for ``record ... --executor ray`` (either spelling of the option)."""
    if "record" not in args:
        return False
    for i, arg in enumerate(args):
        if arg == "--executor=ray" or (arg == "--executor" and args[i + 1 : i + 2] == ["ray"]):
            return True
    return False


def mark_exit_when_python_exits() -> None:
    """In the supervised child: write the exit mark from ``atexit`` (skipped by QuickExit)."""
    mark = os.environ.get(MARK_ENV)
    if mark:
        atexit.register(Path(mark).write_text, "python exit\n")


def write_exit_mark() -> None:
    """In the supervised child: write the exit mark now (before an ``os._exit``)."""
    mark = os.environ.get(MARK_ENV)
    if mark:
        with contextlib.suppress(OSError):
            Path(mark).write_text("python exit\n")


def _die_with_parent() -> None:  # runs in the child between fork and exec
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


def run_supervised(
    args: Sequence[str], *, after_abrupt_end: Callable[[], None] | None = None
) -> int:
    """Run ``python -m pipeline ARGS`` as a child, forward signals, and return its exit code.

    A child that ended without Python's exit (Ray's QuickExit, a signal) gets one
    ``error:`` line here, and a non-zero code; ``after_abrupt_end`` runs first (the
    caller's clean-up of what the child's workers left).
    """
    fd, mark_name = tempfile.mkstemp(prefix="armlab-exit-", suffix=".mark")
    os.close(fd)
    mark = Path(mark_name)
    mark.unlink()
    env = {**os.environ, MARK_ENV: str(mark)}
    child = subprocess.Popen(  # our own interpreter and module
        [sys.executable, "-m", "pipeline", *args],
        env=env,
        process_group=0,
        preexec_fn=_die_with_parent,  # prctl only: no locks taken
    )

    def forward(signum: int, _frame: FrameType | None) -> None:
        with contextlib.suppress(ProcessLookupError):
            child.send_signal(signum)

    previous = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        code = child.wait()
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        exited_in_python = mark.exists()
        mark.unlink(missing_ok=True)
    if exited_in_python:
        return code
    if after_abrupt_end is not None:
        after_abrupt_end()
    how = f"signal {signal.Signals(-code).name}" if code < 0 else f"exit {code}"
    sys.stderr.write(
        f"error: record: the Ray run ended abruptly ({how}): one of Ray's processes died "
        "(Ray's own line above names it); bags already written are complete: re-run to "
        "record the rest (a campaign skips what it has; listed episodes: --only the rest)\n"
    )
    return code if code > 0 else 1
