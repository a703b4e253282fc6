"""The report's "Physical checks" section: the findings of
:func:`pipeline.analysis.findings.physical_checks`, in words."""

from __future__ import annotations

from pipeline.analysis.catalog import SETTLING_TOLERANCE_RAD
from pipeline.analysis.findings import (
    GOAL_MISS_RAD,
    SATURATION_WARN_FRACTION,
    ContactFinding,
    DeadBandFinding,
    Finding,
    GoalMissFinding,
    PhysicalChecks,
    SaturationFinding,
)
from pipeline.report.md import MAX_ROWS


def finding_text(f: Finding) -> str:
    """One finding as the report says it (without the episode)."""
    if isinstance(f, ContactFinding):
        return (
            f"{f.kind} contact {f.bodies[0]} – {f.bodies[1]}, "
            f"{f.max_depth_m * 1e3:.2f} mm deep, t = {f.first_s:.3f} to "
            f"{f.last_s:.3f} s from the motion start ({f.samples} samples)"
        )
    if isinstance(f, SaturationFinding):
        return (
            f"{f.joint} saturated {f.fraction * 100:.1f} % of the time (above "
            f"{SATURATION_WARN_FRACTION * 100:.0f} %): its gains ask for more torque "
            "than the motor has"
        )
    if isinstance(f, GoalMissFinding):
        return (
            f"{f.joint} never reaches its goal (error at the target {f.final_error_rad:.3g} "
            f"rad > {GOAL_MISS_RAD:g} rad)"
        )
    assert isinstance(f, DeadBandFinding)
    return (
        f"`{f.controller_type}` on {f.joint}: proportional stiffness "
        f"{f.stiffness_nm_per_rad:.3g} N m/rad against {f.friction_nm:.3g} N m of friction, "
        f"a dead band of {f.width_rad:.3g} rad (> the "
        f"{SETTLING_TOLERANCE_RAD:g} rad settling band): without integral action "
        "the joint may stop anywhere in it; with it, only after the integral "
        "breaks the friction away"
    )


def physical_checks_section(checks: PhysicalChecks) -> list[str]:
    """Physically broken setups, per episode: never hidden, never fatal; a finding that
    reads the same for several episodes (same gains and friction over seeds) is listed
    once."""
    found: dict[str, list[str]] = {}
    for f in checks.findings:
        found.setdefault(finding_text(f), []).append(f.episode)
    lines = ["", "## Physical checks", ""]
    if not found:
        return [
            *lines,
            f"No contact during execution, no joint saturated more than "
            f"{SATURATION_WARN_FRACTION * 100:.0f} % of the time, every completed episode "
            f"reached its goal within {GOAL_MISS_RAD:g} rad, no gain below the configured "
            f"friction's dead band; {checks.stable} of {checks.episodes} episodes stable "
            "(not diverged).",
        ]
    for text, episodes in list(found.items())[:MAX_ROWS]:
        who = (
            ", ".join(episodes)
            if len(episodes) <= 3
            else (f"{episodes[0]} … {episodes[-1]} ({len(episodes)} episodes)")
        )
        lines.append(f"- **{who}**: {text}")
    if len(found) > MAX_ROWS:
        lines.append(
            f"- … {len(found) - MAX_ROWS} more findings (per episode: `saturation_fraction` "
            "and `final_error` in metrics.json, contacts in each bag's settings)"
        )
    return lines
