"""Verdicts that flip within a swept assumption's range (a campaign report's section).

A verdict (the report's one rule: wins / loses / n.s. / equivalent; the sign where too few
pairs for a test) that changes as one swept value changes, the others held, hangs on that
assumption: the report names it.
"""

from __future__ import annotations

from pathlib import Path

import polars as pl

from pipeline.analysis import catalog
from pipeline.analysis.campaign_tables import TABLE_DIR, condition_values, verdict_flips

# Flipping verdicts listed per assumption (all are in the CSV file).
MAX_FLIPS_SHOWN = 30


def flip_lines(
    wl: pl.DataFrame, conditions: list[str], *, out_dir: Path, stem: str, files: list[str]
) -> list[str]:
    """``### Verdicts that flip with <axis>``: per swept axis (an assumption such as
    ``armature_scale``), the verdicts whose answer changes within its swept range."""
    swept: dict[str, set[str]] = {}
    for cond in conditions:
        for label, value in condition_values(cond).items():
            swept.setdefault(label, set()).add(value)
    labels = [k for k, v in swept.items() if len(v) > 1]
    if not labels:
        return []
    flips = verdict_flips(wl)
    rel = f"{TABLE_DIR}/{stem}_flips.csv"
    flips.write_csv(out_dir / rel)
    files.append(rel)
    lines: list[str] = []
    for label in sorted(labels):
        values = sorted(swept[label], key=lambda t: (number_key(t), t))
        sub = flips.filter(pl.col("assumption") == label)
        lines += [f"### Verdicts that flip with `{label}`", ""]
        if not sub.height:
            lines += [
                "None: every verdict (wins / loses / n.s. / equivalent; the sign where "
                f"untested) is the same for {label} = {', '.join(values)}, the other swept "
                "values held.",
                "",
            ]
            continue
        lines += [
            f"{sub.height} verdict(s) change within {label} = {', '.join(values)} (the other "
            f"swept values held): they hang on this assumption. All: [`{rel}`]({rel}).",
            "",
        ]
        for r in sub.head(MAX_FLIPS_SHOWN).iter_rows(named=True):
            title = catalog.BY_NAME[r["metric"]].title if r["metric"] in catalog.BY_NAME else ""
            where = f" ({r['others']})" if r["others"] else ""
            lines.append(
                f"- `{r['candidate']}` vs `{r['baseline']}`, {title or r['metric']}, "
                f"{r['joint']}{where}: {r['answers']}."
            )
        if sub.height > MAX_FLIPS_SHOWN:
            lines.append(f"- ({sub.height - MAX_FLIPS_SHOWN} more in the CSV file.)")
        lines.append("")
    return lines


def number_key(text: str) -> float:
    """A swept value's number, for sorting (inf when it is not one)."""
    try:
        return float(text)
    except ValueError:
        return float("inf")
