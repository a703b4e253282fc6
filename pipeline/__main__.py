"""``python -m pipeline`` and the ``pipeline`` console script.

The entry point imports the CLI inside a guard: Ctrl-C (or SIGTERM) while the heavy
libraries load (~1 s) ends with "interrupted" and exit 130 ("terminated", 143), not a
KeyboardInterrupt traceback. ``record --executor ray`` runs supervised
(:mod:`pipeline.supervise`): Ray can end its driver process without a word.
"""

from __future__ import annotations

import os
import sys

from pipeline import supervise
from pipeline.errors import handle_sigterm, interrupt_exit


def entry() -> None:
    """Console-script entry point: import the CLI, then run it."""
    handle_sigterm()
    # nothing here renders with MuJoCo: skip its OpenGL probe (glfw, ~0.1-0.3 s per start);
    # MUJOCO_GL set by the caller wins
    os.environ.setdefault("MUJOCO_GL", "disable")
    if supervise.drives_ray(sys.argv[1:]) and supervise.MARK_ENV not in os.environ:
        sys.exit(supervise.run_supervised(sys.argv[1:]))  # Ray may end its driver abruptly
    supervise.mark_exit_when_python_exits()
    try:
        from pipeline.cli import main
    except KeyboardInterrupt as err:
        word, code = interrupt_exit(err)
        sys.stderr.write(f"{word}\n")
        sys.exit(code)
    except (MemoryError, ImportError) as err:
        from pipeline.memory import OUT_OF_MEMORY_HINT, out_of_memory

        if "--debug" in sys.argv[1:] or not out_of_memory(err):
            raise
        sys.stderr.write(f"error: {out_of_memory(err)}: {OUT_OF_MEMORY_HINT}\n")
        sys.exit(1)
    main()


if __name__ == "__main__":
    entry()
