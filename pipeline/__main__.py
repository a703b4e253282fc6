"""``python -m pipeline`` and the ``pipeline`` console script.

The entry point imports the CLI inside a guard: Ctrl-C (or SIGTERM) while the heavy
libraries load (~1 s) ends with "interrupted" and exit 130 ("terminated", 143), not a
KeyboardInterrupt traceback. ``record --executor ray`` runs supervised
(:mod:`pipeline.supervise`): Ray can end its driver process without a word.
"""

from __future__ import annotations

import os
import re
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from pipeline import supervise
from pipeline.argv import command_name
from pipeline.errors import handle_sigterm, interrupt_exit
from pipeline.memory import OUT_OF_MEMORY_HINT, address_limit_below_need


def entry() -> None:
    """Console-script entry point: import the CLI, then run it."""
    handle_sigterm()
    # nothing here renders with MuJoCo: skip its OpenGL probe (glfw, ~0.1-0.3 s per start);
    # MUJOCO_GL set by the caller wins
    os.environ.setdefault("MUJOCO_GL", "disable")
    if supervise.drives_ray(sys.argv[1:]) and supervise.MARK_ENV not in os.environ:
        args = sys.argv[1:]  # Ray may end its driver abruptly
        sys.exit(supervise.run_supervised(args, after_abrupt_end=lambda: _sweep_partials(args)))
    supervise.mark_exit_when_python_exits()
    short = address_limit_below_need(command_name(sys.argv[1:]))
    if short is not None and "--debug" not in sys.argv[1:]:
        sys.stderr.write(f"error: {short}: {OUT_OF_MEMORY_HINT}\n")
        sys.exit(1)
    try:
        from pipeline.cli import main
    except KeyboardInterrupt as err:
        word, code = interrupt_exit(err)
        sys.stderr.write(f"{word}\n")
        sys.exit(code)
    except (MemoryError, ImportError) as err:
        from pipeline.memory import out_of_memory

        if "--debug" in sys.argv[1:] or not out_of_memory(err):
            raise
        sys.stderr.write(f"error: {out_of_memory(err)}: {OUT_OF_MEMORY_HINT}\n")
        sys.exit(1)
    main()


# a bag writer's work folder (pipeline/log/rosbag2.py): ``.<name>.partial-<pid>``
_PARTIAL = re.compile(r"\..+\.partial-(?P<pid>\d+)")
_SWEEP_WAIT_S = 30.0  # Ray ends a dead driver's workers within seconds


def _sweep_partials(args: Sequence[str]) -> None:
    """After a Ray run ended abruptly: remove the half-written bags of its workers (under
    ``--out``, its campaign folders included) once their writers are gone; a writer still
    alive after ``_SWEEP_WAIT_S`` finishes or leaves its folder to the next run's sweep."""
    from pipeline.fsutil import pid_alive, remove_stale

    out = Path(_option(args, "--out", "-o") or "recordings")
    folders = [out, *(p for p in out.glob("*") if p.is_dir() and not p.name.startswith("."))]
    deadline = time.monotonic() + _SWEEP_WAIT_S
    while True:
        for folder in folders:
            remove_stale(folder, _PARTIAL)
        left = [
            p for f in folders for p in f.glob(".*.partial-*") if (m := _PARTIAL.fullmatch(p.name))
            and pid_alive(int(m["pid"]))
        ]  # fmt: skip
        if not left or time.monotonic() > deadline:
            return
        time.sleep(0.2)


def _option(args: Sequence[str], *names: str) -> str | None:
    """The value of an option given as ``--out X``, ``--out=X`` or ``-o X`` (None: absent)."""
    for i, arg in enumerate(args):
        for name in names:
            if arg == name and i + 1 < len(args):
                return args[i + 1]
            if arg.startswith(f"{name}="):
                return arg.split("=", 1)[1]
    return None


if __name__ == "__main__":
    entry()
