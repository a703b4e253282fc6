"""The report's "Physical checks" section: the findings of
:func:`pipeline.analysis.findings.physical_checks`, in words."""

from __future__ import annotations

from pipeline.analysis.catalog import SETTLING_TOLERANCE_RAD
from pipeline.analysis.findings import (
    CONTACTS,
    DEAD_BAND,
    GOAL,
    GOAL_MISS_RAD,
    SATURATION_WARN_FRACTION,
    UNSETTLED,
    CheckAlert,
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


BANNER_MAX = 8
"""Alerts listed on the first screen; the rest are in the Physical checks table."""

_WHAT = {
    DEAD_BAND: lambda a: f"friction dead band {a.worst:.2g} rad (friction / position stiffness)",
    GOAL: lambda a: f"goal missed by {a.worst:.2g} rad",
    "saturation": lambda a: f"effort at its limit {a.worst * 100:.0f} % of the time",
    CONTACTS: lambda a: f"contact during execution, {a.worst * 1e3:.2f} mm deep",
    UNSETTLED: lambda a: f"start not settled within the {a.worst:g} s pre-roll",
}
_MEANS = {
    DEAD_BAND: "the joint may stop anywhere within that band, so its error and settling "
    "numbers measure the friction, not the control law",
    GOAL: "its error at the target is an offset the law leaves, not tracking noise",
    "saturation": "the law asked for more torque than the joint has: its numbers measure the "
    "effort limit as much as the law",
    CONTACTS: "the arm touched something: its errors include the collision",
    UNSETTLED: "its motion started from a state still moving, so its errors include the "
    "start's transient",
}
_EVERY = (
    "every controller shows it: on {where} the comparison measures the setup (friction, "
    "limits, obstacles), not the controllers"
)


def _joints(names: tuple[str, ...], order: list[str]) -> str:
    """``joint 7 `j7``` for one joint, ``joints 1, 3 and 7`` for several (by number)."""
    if not names:
        return "the whole arm"
    nums = [str(order.index(j) + 1) if j in order else f"`{j}`" for j in names]
    if len(names) == 1:
        return f"joint {nums[0]} `{names[0]}`" if names[0] in order else f"joint {nums[0]}"
    return f"joints {', '.join(nums[:-1])} and {nums[-1]}"


def check_banner(alerts: tuple[CheckAlert, ...], joints: list[str]) -> list[str]:
    """The first screen's banner: each failed physical check, which controller, which
    joint, and what it means for the comparison (empty when every check passes)."""
    if not alerts:
        return []
    lines = ["> **Physical checks failed**: read the comparison below with these in mind.", ">"]
    for a in alerts[:BANNER_MAX]:
        who = (
            ("every controller (" if a.every_controller else "")
            + ", ".join(f"**{c}**" for c in a.controllers)
            + (")" if a.every_controller else "")
        )
        where = _joints(a.joints, joints)
        share = f" in {a.episodes}/{a.of} episodes" if a.of > 1 else ""
        means = _EVERY.format(where=where) if a.every_controller else _MEANS[a.check]
        lines.append(f"> - {who}, {where}: {_WHAT[a.check](a)}{share}; {means}.")
    if len(alerts) > BANNER_MAX:
        lines.append(f"> - … {len(alerts) - BANNER_MAX} more: see *Physical checks* below.")
    return [*lines, ""]
