"""Markdown helpers every report section shares: tables, number formats, the words for a
missing value, and the row limits that keep report.md bounded."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from pipeline.analysis.aggregate import MeanCI
from pipeline.analysis.metrics import ERROR_FLOOR_RAD
from pipeline.constants import ERROR_FORMAT

# Lists (episodes, warnings, findings, recordings) show at most this many rows; the rest are
# in episodes.csv / recordings.csv / metrics.json, so report.md stays bounded whatever N is.
MAX_ROWS = 40
# A scenario with more episodes than this gets no per-episode tables (only the summaries).
MAX_EPISODE_COLUMNS = 8
NA = "n/a"
NOT_RECORDED = "n/a (not recorded)"
NOT_IN_BAG = "n/a (not in the bag)"
ENDED_EARLY = "n/a (episode ended before the motion did)"
SALVAGE_CUT = "n/a (recording salvaged: cut at the damage, motion end unknown)"
FLOOR = f"{ERROR_FLOOR_RAD:.0e}".replace("e-0", "e-")  # "1e-9"
# A reduction below this (the candidate more than twice the baseline) reads better as a
# ratio: "-3600 %" says less than "37x the baseline's".
RATIO_BELOW_PCT = -100.0

Format = Callable[[float], str]
"""Formats one number for a cell."""


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured Markdown table (``|`` in a cell escaped)."""

    def esc(cell: str) -> str:
        return cell.replace("|", "\\|")

    lines = ["| " + " | ".join(esc(h) for h in header) + " |"]
    lines.append("|" + "|".join(" --- " for _ in header) + "|")
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def sci(x: Any, digits: int | None = None) -> str:
    """``1.234e-03`` (:data:`pipeline.constants.ERROR_FORMAT`, or ``digits`` decimals);
    n/a for None."""
    return NA if x is None else format(float(x), ERROR_FORMAT if digits is None else f".{digits}e")


def num(x: Any, fmt: str = ".3g") -> str:
    """A number in ``fmt``, a bool as ``true``/``false``, anything else as text."""
    if x is None or x == NA:
        return NA
    if isinstance(x, bool):
        return str(x).lower()
    if isinstance(x, int | float):
        return format(float(x), fmt)
    return str(x)


def pct(x: Any) -> str:
    """A reduction [%]; a ratio when the candidate is more than twice the baseline."""
    if x is None:
        return "— (divisor ≈ 0)"
    if float(x) < RATIO_BELOW_PCT:
        return f"{1.0 - float(x) / 100.0:.3g}× the baseline's"
    return f"{float(x):.1f} %"


def signed(x: float, digits: int) -> str:
    """``+1.234`` / ``-1.234``; a value that rounds to zero is ``0.000`` (never ``-0.000``)."""
    text = f"{x:+.{digits}f}"
    return text[1:] if float(text) == 0.0 else text


def mean_ci(ci: MeanCI, fmt: Format, hw_fmt: Format | None = None) -> str:
    """``mean ± half width (n = k)``; ``fmt`` formats the mean (and, unless ``hw_fmt`` is
    given, the half width)."""
    if ci.mean is None:
        return NA
    if ci.half_width is None:
        return f"{fmt(ci.mean)} (n = {ci.n})"
    return f"{fmt(ci.mean)} ± {(hw_fmt or fmt)(ci.half_width)} (n = {ci.n})"


def mean_ci_pct(ci: MeanCI) -> str:
    """A reduction's mean ± half width [%] (n = k), or the mean ratio."""
    if ci.mean is None:
        return "— (divisor ≈ 0)"
    if ci.mean < RATIO_BELOW_PCT:
        return f"{1.0 - ci.mean / 100.0:.3g}× the baseline's on average (n = {ci.n})"
    if ci.half_width is None:
        return f"{ci.mean:.1f} % (n = {ci.n})"
    return f"{ci.mean:.1f} ± {ci.half_width:.1f} % (n = {ci.n})"


def value(x: Any) -> str:
    """A setting of any shape, shown compactly."""
    if x is None or x == NA:
        return NA
    if isinstance(x, list | tuple):
        if len(x) > 1 and all(v == x[0] for v in x):
            return f"{value(x[0])} (all joints)"
        return "[" + ", ".join(value(v) for v in x) + "]"
    if isinstance(x, dict):
        return ", ".join(f"{k} = {value(v)}" for k, v in x.items()) or NA
    if isinstance(x, float):
        return format(x + 0.0, ".4g")  # + 0.0: no "-0"
    return str(x)


def seed_span(seeds: Sequence[str]) -> str:
    """``0–49`` for the seeds 0..49 (sorted numerically where they are numbers)."""
    ordered = sorted(set(seeds), key=lambda x: (len(x), x))
    return ordered[0] if len(ordered) == 1 else f"{ordered[0]}–{ordered[-1]} ({len(ordered)})"


def count(values: Sequence[str]) -> dict[str, int]:
    """How often each value occurs, in first-seen order."""
    out: dict[str, int] = {}
    for v in values:
        out[v] = out.get(v, 0) + 1
    return out
