"""The report's "Physical checks" section: the findings of
:func:`pipeline.analysis.findings.physical_checks`, in words."""

from __future__ import annotations

from pipeline.analysis.catalog import SETTLING_TOLERANCE_RAD
from pipeline.analysis.findings import (
    GOAL_MISS_RAD,
    SATURATION_WARN_FRACTION,
    CheckCell,
    ContactFinding,
    DeadBandFinding,
    Finding,
    GoalMissFinding,
    PhysicalChecks,
    SaturationFinding,
    UnsettledStartFinding,
)
from pipeline.report.md import MAX_ROWS, NA, NOT_IN_BAG
from pipeline.report.md import table as md_table


def _short(fs: list[Finding], n: int) -> list[str]:
    """A cell's findings, one phrase per kind: the worst value and in how many episodes."""
    out: list[str] = []
    kinds: dict[type, list[Finding]] = {}
    for f in fs:
        kinds.setdefault(type(f), []).append(f)
    for kind, group in kinds.items():
        k = len({f.episode for f in group})
        share = f" ({k}/{n})" if n > 1 else ""
        if kind is SaturationFinding:
            worst = max(f.fraction for f in group if isinstance(f, SaturationFinding))
            out.append(f"saturated {worst * 100:.0f} %{share}")
        elif kind is GoalMissFinding:
            miss = max(f.final_error_rad for f in group if isinstance(f, GoalMissFinding))
            out.append(f"goal missed by {miss:.2g} rad{share}")
        elif kind is UnsettledStartFinding:
            cap = max(f.preroll_s for f in group if isinstance(f, UnsettledStartFinding))
            out.append(f"start not settled in {cap:g} s{share}")
        elif kind is DeadBandFinding:
            width = max(f.width_rad for f in group if isinstance(f, DeadBandFinding))
            out.append(f"dead band {width:.2g} rad{share}")
        else:
            contacts = [f for f in group if isinstance(f, ContactFinding)]
            deepest = max(contacts, key=lambda f: f.max_depth_m)
            pairs = sorted({f"{f.kind} contact {f.bodies[0]} – {f.bodies[1]}" for f in contacts})
            shown = ", ".join(pairs[:3]) + (f" (+{len(pairs) - 3} more)" if len(pairs) > 3 else "")
            out.append(f"{shown}, {deepest.max_depth_m * 1e3:.2f} mm deep{share}")
    return out


def _cell_text(cell: CheckCell | None, all_checks: int) -> str:
    if cell is None:
        return NA
    parts = _short(list(cell.findings), cell.episodes)
    if cell.not_in_bag and len(cell.not_in_bag) >= all_checks and not parts:
        return NOT_IN_BAG
    if not parts:
        parts = ["ok"]
    if cell.not_in_bag:
        parts.append(f"{', '.join(cell.not_in_bag)} {NOT_IN_BAG}")
    return "; ".join(parts)


def physical_checks_section(checks: PhysicalChecks, grid: tuple[CheckCell, ...] = ()) -> list[str]:
    """Physically broken setups as one controller × joint table (a contacts column for the
    whole arm): never hidden, never fatal; what a bag holds no data for is n/a, never "ok"."""
    lines = ["", "## Physical checks", ""]
    controllers = list(dict.fromkeys(c.controller for c in grid))
    joints = list(dict.fromkeys(c.joint for c in grid if c.joint))
    by = {(c.controller, c.joint): c for c in grid}
    header = ["controller", "contacts", *[f"{k + 1} {j}" for k, j in enumerate(joints)]]
    rows = [
        [c, _cell_text(by.get((c, "")), 1), *[_cell_text(by.get((c, j)), 3) for j in joints]]
        for c in controllers[:MAX_ROWS]
    ]
    lines += [
        md_table(header, rows),
        "",
        f"{checks.stable} of {checks.episodes} episodes stable (not diverged). A cell is *ok* "
        f"when, over the controller's episodes (k/n: in how many), no contact happened "
        f"during execution, every pre-roll settled before its cap (`preroll_s`; *start not "
        f"settled*: the metrics start from an unsettled state), no joint sat at its "
        f"effort limit more than "
        f"{SATURATION_WARN_FRACTION * 100:.0f} % of the time, every completed episode "
        f"reached its goal within {GOAL_MISS_RAD:g} rad and no proportional gain leaves a "
        f"friction dead band (friction / stiffness) wider than the "
        f"{SETTLING_TOLERANCE_RAD:g} rad settling band (without integral action the joint "
        "may stop anywhere in it; with it, only after the integral breaks the friction "
        f"away). *{NOT_IN_BAG}*: the recording holds no data for that check (no safety "
        "record, effort limit, planned goal, gains or friction), so it is not a pass.",
    ]
    return lines
