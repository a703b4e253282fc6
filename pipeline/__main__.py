"""``python -m pipeline`` and the ``pipeline`` console script.

The entry point imports the CLI inside a guard: Ctrl-C while the heavy libraries load
(~1 s) ends with "interrupted" and exit 130, not a KeyboardInterrupt traceback.
"""

from __future__ import annotations

import sys


def entry() -> None:
    """Console-script entry point: import the CLI, then run it."""
    try:
        from pipeline.cli import main
    except KeyboardInterrupt:
        sys.stderr.write("interrupted\n")
        sys.exit(130)
    main()


if __name__ == "__main__":
    entry()
