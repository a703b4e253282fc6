"""Long lists of paths in one error line: the count, the first few, and a file with them all.

An error naming 2,000 recordings one by one is a 70 KB line nobody reads; the summary keeps
the line short and says where the full list went.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Sequence

SHOWN = 3
"""Paths shown in the line before the list is cut."""


def summarise_paths(paths: Sequence[str], *, what: str = "path") -> str:
    """``paths`` joined by ", " when there are at most :data:`SHOWN`; else ``"N <what>s (a,
    b, c, ...; all listed in FILE)"``, FILE a new text file in the temp folder holding one
    path a line (left out of the text if it cannot be written)."""
    if len(paths) <= SHOWN:
        return ", ".join(paths)
    where = ""
    with contextlib.suppress(OSError):
        fd, name = tempfile.mkstemp(prefix=f"pipeline-{what}s-", suffix=".txt")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write("\n".join(paths) + "\n")
        where = f"; all listed in {name}"
    return f"{len(paths)} {what}s ({', '.join(paths[:SHOWN])}, ...{where})"
