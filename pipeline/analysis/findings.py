"""Physical checks of the recorded episodes, as typed findings the report only words.

A physically broken setup is never hidden and never fatal: contact during execution, a
joint in torque saturation, a completed episode that never reached its goal, a
proportional gain too small against the configured friction. :func:`physical_checks`
finds them per episode (this is where the nominal model is evaluated, with Pinocchio);
the report words them and lists a finding shared by several episodes once.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import polars as pl

from pipeline.analysis.catalog import SETTLING_TOLERANCE_RAD, not_settled
from pipeline.analysis.protocol import ProtocolView
from pipeline.control.info import stiffness_gains
from pipeline.log.reader import Recording
from pipeline.log.robot_facts import robot_facts
from pipeline.robots.spec import RobotSpec
from pipeline.settings import EpisodeSettings

SATURATION_WARN_FRACTION = 0.05
"""Warn when a joint's effort sits at its limit for more than this share of the samples."""
GOAL_MISS_RAD = 1e-2
"""A completed episode whose error at the target exceeds this never reached its goal."""


@dataclass(frozen=True)
class ContactFinding:
    """A contact during execution (from the episode's recorded safety settings).

    Attributes:
        episode: the episode.
        kind: ``obstacle``, ``self`` or ``floor``.
        bodies: the two bodies in contact.
        max_depth_m: deepest penetration [m].
        first_s, last_s: first and last sample in penetration, from the motion start [s].
        samples: checked samples in penetration.
    """

    episode: str
    kind: str
    bodies: tuple[str, str]
    max_depth_m: float
    first_s: float
    last_s: float
    samples: int


@dataclass(frozen=True)
class SaturationFinding:
    """A joint whose effort sat at its limit for more than :data:`SATURATION_WARN_FRACTION`
    of the samples (``fraction``: the share)."""

    episode: str
    joint: str
    fraction: float


@dataclass(frozen=True)
class GoalMissFinding:
    """A joint whose error at the target exceeds :data:`GOAL_MISS_RAD` [rad]."""

    episode: str
    joint: str
    final_error_rad: float


@dataclass(frozen=True)
class DeadBandFinding:
    """A joint whose proportional stiffness leaves a friction dead band wider than the
    settling band (:data:`pipeline.analysis.catalog.SETTLING_TOLERANCE_RAD`).

    Attributes:
        episode: the episode.
        joint: the joint.
        controller_type: the controller's type (``pid``, ``ctc``, ...).
        stiffness_nm_per_rad: the proportional term's position stiffness [N m/rad].
        friction_nm: the plant's Coulomb friction on the joint [N m].
    """

    episode: str
    joint: str
    controller_type: str
    stiffness_nm_per_rad: float
    friction_nm: float

    @property
    def width_rad(self) -> float:
        """The dead band: friction / stiffness [rad]."""
        return self.friction_nm / self.stiffness_nm_per_rad


@dataclass(frozen=True)
class UnsettledStartFinding:
    """An episode whose pre-roll reached its cap (``preroll_s``) without settling
    (``pipeline.sim.settling``): its metrics start from an unsettled state.

    Attributes:
        episode: the episode.
        preroll_s: the pre-roll it ran, the cap [s].
    """

    episode: str
    preroll_s: float


Finding = (
    ContactFinding | SaturationFinding | GoalMissFinding | DeadBandFinding | UnsettledStartFinding
)


@dataclass(frozen=True)
class PhysicalChecks:
    """Every finding of the episodes, in episode order (per episode: contacts, then per
    joint saturation, goal miss, dead band), and how many episodes stayed stable."""

    findings: tuple[Finding, ...]
    stable: int
    episodes: int


def physical_checks(
    recordings: Sequence[Recording],
    views: Mapping[str, ProtocolView],
    metrics: pl.DataFrame,
) -> PhysicalChecks:
    """The physical checks of every recording.

    Args:
        recordings: the episodes.
        views: per episode, its protocol view (typed settings, motion start).
        metrics: :func:`pipeline.analysis.metrics.joint_metrics` of the episodes.
    """
    found: list[Finding] = []
    rows: dict[tuple[str, str], dict[str, Any]] = {
        (r["episode"], r["joint"]): r for r in metrics.iter_rows(named=True)
    }
    for rec in recordings:
        view = views.get(rec.episode)
        st = view.settings if view is not None else None
        start = view.motion_start_s if view is not None else 0.0
        if st is not None:
            found += [
                ContactFinding(
                    rec.episode,
                    c.kind,
                    c.bodies,
                    c.max_depth_m,
                    c.first_ns * 1e-9 - start,
                    c.last_ns * 1e-9 - start,
                    c.samples,
                )
                for c in st.safety.contacts
            ]
            if not st.protocol.preroll_settled:
                found.append(UnsettledStartFinding(rec.episode, start))
        stiffness = stiffness_nm_per_rad(st, robot_facts(rec).spec) if st is not None else None
        for j, joint in enumerate(rec.joint_names):
            m = rows.get((rec.episode, joint), {})
            sat = m.get("saturation_fraction")
            if sat is not None and sat > SATURATION_WARN_FRACTION:
                found.append(SaturationFinding(rec.episode, joint, sat))
            final = m.get("final_error")
            if final is not None and final > GOAL_MISS_RAD:
                found.append(GoalMissFinding(rec.episode, joint, final))
            friction = st.plant.frictionloss if st is not None else ()
            if stiffness is None or j >= len(friction) or j >= len(stiffness):
                continue
            if stiffness[j] > 0 and friction[j] / stiffness[j] > SETTLING_TOLERANCE_RAD:
                assert st is not None
                found.append(
                    DeadBandFinding(
                        rec.episode, joint, st.controller.type, stiffness[j], friction[j]
                    )
                )
    stable = sum(1 for r in recordings if r.status == "ok")
    return PhysicalChecks(tuple(found), stable, len(recordings))


def worst_saturation(metrics: pl.DataFrame) -> dict[str, float | None]:
    """Per episode, the largest ``saturation_fraction`` over its joints (None: not recorded)."""
    return {
        r["episode"]: r["saturation_fraction"]
        for r in metrics.group_by("episode")
        .agg(pl.col("saturation_fraction").max())
        .iter_rows(named=True)
    }


def nominal_plant(
    recordings: Sequence[Recording], views: Mapping[str, ProtocolView]
) -> bool | None:
    """Whether the recordings' plant is the nominal model (None: unknown or mixed)."""
    flags = {
        view.settings.plant.exact
        for rec in recordings
        if (view := views.get(rec.episode)) is not None and view.settings is not None
    }
    return flags.pop() if len(flags) == 1 else None


def stiffness_nm_per_rad(st: EpisodeSettings, spec: RobotSpec | None) -> list[float] | None:
    """Per-joint position stiffness [N m/rad] of the controller's proportional term:
    ``kp`` itself for the decentralized laws, ``M_n(goal)_jj * kp`` for the model-based
    ones (their kp is an acceleration gain [1/s^2])."""
    kp = st.controller.gains.get("kp")
    if not (isinstance(kp, list) and all(isinstance(k, int | float) for k in kp)):
        return None
    stiff = stiffness_gains(st.controller.type)  # the entry declares which are [N m/rad]
    if stiff is None:
        return None  # a plug-in not importable here: the unit of its kp is unknown
    if "kp" in stiff:
        return [float(k) for k in kp]
    if spec is None or not spec.has_dynamics or len(st.planner.goal) != spec.dof:
        return None
    mass = _mass_diagonal(spec, tuple(float(g) for g in st.planner.goal))
    return [float(k) * mass[j] for j, k in enumerate(kp)]


@functools.lru_cache(maxsize=256)
def _mass_diagonal(spec: RobotSpec, q: tuple[float, ...]) -> tuple[float, ...]:
    """diag M_n(q) of the nominal model (a campaign shares robot and goal: computed once)."""
    import pinocchio as pin

    from pipeline.robots.urdf import build_pinocchio_model

    model = build_pinocchio_model(spec)
    mass = pin.crba(model, model.createData(), np.asarray(q, dtype=float))
    return tuple(float(mass[j, j]) for j in range(len(q)))


def unsettled_joints(
    metrics: pl.DataFrame, views: Mapping[str, ProtocolView] | None = None
) -> dict[str, str]:
    """Per episode, "settled" or "not settled ...": by the hold's recorded settling
    (``protocol.hold_settled``, ``pipeline.sim.settling``) where the bag has it, else the
    joints whose error at the target still moves in its last windows
    (``catalog.not_settled``); none where unknown."""
    recorded: dict[str, str] = {}
    for episode, view in (views or {}).items():
        flag = view.settings.protocol.hold_settled if view.settings is not None else None
        if flag is not None:
            recorded[episode] = "settled" if flag else "not settled (hold capped)"
    if not {"final_error", "final_drift"} <= set(metrics.columns):
        return recorded
    flagged = metrics.with_columns(
        flag=not_settled(pl.col("final_error"), pl.col("final_drift"))
    ).filter(pl.col("flag").is_not_null())
    out: dict[str, str] = {}
    for row in (
        flagged.group_by("episode", maintain_order=True)
        .agg(pl.col("joint").filter(pl.col("flag")))
        .iter_rows(named=True)
    ):
        joints = row["joint"]
        out[row["episode"]] = "settled" if not joints else "not settled: " + ", ".join(joints)
    return out | recorded


# The checks a cell of :func:`check_grid` reports on.
CONTACTS, SATURATION, GOAL, DEAD_BAND = "contacts", "saturation", "goal", "dead band"
UNSETTLED = "start not settled"


@dataclass(frozen=True)
class CheckCell:
    """The physical checks of one controller on one joint (or, for contacts, on the whole
    arm: ``joint`` ""), over its episodes.

    Attributes:
        controller: the controller.
        joint: the joint ("" for the per-episode contact check).
        findings: what the checks found.
        not_in_bag: checks some episode's bag holds no data for (n/a, never a pass):
            contacts without our safety settings, saturation without effort limits, the
            goal without a planned goal, the dead band without gains and friction.
        episodes: how many episodes the cell covers.
    """

    controller: str
    joint: str
    findings: tuple[Finding, ...]
    not_in_bag: tuple[str, ...]
    episodes: int


def check_grid(
    recordings: Sequence[Recording],
    views: Mapping[str, ProtocolView],
    metrics: pl.DataFrame,
    checks: PhysicalChecks,
) -> tuple[CheckCell, ...]:
    """The physical checks as a controller × joint grid (plus one contacts cell per
    controller, ``joint`` ""), controllers in first-seen order, joints in recorded order."""
    rows: dict[tuple[str, str], dict[str, Any]] = {
        (r["episode"], r["joint"]): r for r in metrics.iter_rows(named=True)
    }
    found: dict[tuple[str, str], list[Finding]] = {}
    for f in checks.findings:
        found.setdefault((f.episode, getattr(f, "joint", "")), []).append(f)
    cells: dict[tuple[str, str], tuple[list[Finding], set[str], int]] = {}
    for rec in recordings:
        view = views.get(rec.episode)
        st = view.settings if view is not None else None
        stiffness = stiffness_nm_per_rad(st, robot_facts(rec).spec) if st is not None else None
        for joint in ("", *rec.joint_names):
            cell = cells.setdefault((rec.controller, joint), ([], set(), 0))
            missing = cell[1]
            if joint == "":
                if st is None:
                    missing.add(CONTACTS)
            else:
                m = rows.get((rec.episode, joint), {})
                if m.get("saturation_fraction") is None:
                    missing.add(SATURATION)
                if st is None or m.get("final_error") is None:
                    missing.add(GOAL)
                k = rec.joint_names.index(joint)
                friction = st.plant.frictionloss if st is not None else ()
                if stiffness is None or k >= len(friction) or k >= len(stiffness):
                    missing.add(DEAD_BAND)
            cells[(rec.controller, joint)] = (
                cell[0] + found.get((rec.episode, joint), []),
                missing,
                cell[2] + 1,
            )
    return tuple(
        CheckCell(c, j, tuple(fs), tuple(sorted(missing)), n)
        for (c, j), (fs, missing, n) in cells.items()
    )


@dataclass(frozen=True)
class CheckAlert:
    """A failed physical check that qualifies the comparison: for the report's first screen.

    One alert per check and set of joints; the controllers failing it with those joints.

    Attributes:
        check: :data:`CONTACTS`, :data:`SATURATION`, :data:`GOAL`, :data:`DEAD_BAND` or
            :data:`UNSETTLED`.
        controllers: the controllers that fail it (first-seen order).
        joints: the joints ((), for contacts: the whole arm).
        worst: the worst value: dead band width [rad], goal miss [rad], share of samples
            saturated [0-1], deepest contact [m], the pre-roll cap reached unsettled [s].
        episodes: in how many of those controllers' episodes it happened.
        of: how many episodes those controllers have.
        every_controller: every controller of the report fails it on these joints: there
            the comparison measures the setup (friction, limits, obstacles), not the laws.
    """

    check: str
    controllers: tuple[str, ...]
    joints: tuple[str, ...]
    worst: float
    episodes: int
    of: int
    every_controller: bool


def _worst(fs: Sequence[Finding]) -> float:
    values = [
        f.width_rad if isinstance(f, DeadBandFinding)
        else f.final_error_rad if isinstance(f, GoalMissFinding)
        else f.fraction if isinstance(f, SaturationFinding)
        else f.preroll_s if isinstance(f, UnsettledStartFinding)
        else f.max_depth_m
        for f in fs
    ]  # fmt: skip
    return max(values)


def check_alerts(grid: Sequence[CheckCell]) -> tuple[CheckAlert, ...]:
    """The failed checks of :func:`check_grid`, one alert per check and set of controllers
    failing it on the same joints (joints in recorded order): dead bands first (they make a
    joint's error meaningless), then goal misses, saturation, contacts; within a check,
    the alerts every controller shares first."""
    kinds = (
        (DEAD_BAND, DeadBandFinding), (GOAL, GoalMissFinding),
        (SATURATION, SaturationFinding), (CONTACTS, ContactFinding),
        (UNSETTLED, UnsettledStartFinding),
    )  # fmt: skip
    controllers = list(dict.fromkeys(c.controller for c in grid))
    runs = {c.controller: c.episodes for c in grid if c.joint == ""}
    out: list[CheckAlert] = []
    for check, kind in kinds:
        # joint -> the controllers failing the check there, and their findings
        by_joint: dict[str, dict[str, list[Finding]]] = {}
        for cell in grid:
            fs = [f for f in cell.findings if isinstance(f, kind)]
            if fs:
                by_joint.setdefault(cell.joint, {}).setdefault(cell.controller, []).extend(fs)
        groups: dict[tuple[str, ...], list[str]] = {}
        for joint, failing in by_joint.items():
            names = tuple(c for c in controllers if c in failing)
            groups.setdefault(names, []).append(joint)
        alerts = []
        for names, joints in groups.items():
            failed: list[Finding] = [f for j in joints for c in names for f in by_joint[j][c]]
            every = len(controllers) > 1 and len(names) == len(controllers)
            episodes = len({f.episode for f in failed})
            total = sum(runs.get(c, 0) for c in names)
            shown = tuple(j for j in joints if j)
            alerts.append(CheckAlert(check, names, shown, _worst(failed), episodes, total, every))
        out += sorted(alerts, key=lambda a: (not a.every_controller, -len(a.controllers)))
    return tuple(out)
