"""How an error is printed, by every printer: report.md, the report's and the record's
console tables (so the record console and the report agree to the printed digit).

Light on purpose: ``pipeline record`` imports it without the analysis stack.
"""

from __future__ import annotations

from typing import Any

NA = "n/a"


def sci(x: Any, digits: int = 3) -> str:
    """``1.234e-03``; n/a for None."""
    return NA if x is None else f"{float(x):.{digits}e}"
