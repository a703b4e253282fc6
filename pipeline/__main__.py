"""``python -m pipeline`` and the ``pipeline`` console script.

The entry point imports the CLI inside a guard: Ctrl-C (or SIGTERM) while the heavy
libraries load (~1 s) ends with "interrupted" and exit 130 ("terminated", 143), not a
KeyboardInterrupt traceback.
"""

from __future__ import annotations

import sys

from pipeline.errors import handle_sigterm, interrupt_exit


def entry() -> None:
    """Console-script entry point: import the CLI, then run it."""
    handle_sigterm()
    try:
        from pipeline.cli import main
    except KeyboardInterrupt as err:
        word, code = interrupt_exit(err)
        sys.stderr.write(f"{word}\n")
        sys.exit(code)
    main()


if __name__ == "__main__":
    entry()
