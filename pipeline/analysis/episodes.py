"""Per-episode facts from recordings: the episode table, effort limits, the robot spec.

Everything is read from the recording's typed settings, its metadata and its robot facts
(:mod:`pipeline.log.robot_facts`): without settings (a bag we did not write, or settings
breaking the contract) what they would give is null / "n/a", never a crash.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import polars as pl

from pipeline.analysis.protocol import ProtocolView
from pipeline.log.reader import Recording
from pipeline.log.robot_facts import robot_facts
from pipeline.robots import RobotSpec

EPISODE_COLUMNS = (
    "episode",
    "controller",
    "scenario",
    "robot",
    "seed",
    "status",
    "reason",
    "salvaged",
    "salvage_lost_pct",
    "motion_end_s",
    "end_s",
    "samples",
    "source",
    "sha256",
    "motion_completed",
    "controller_samples",
    "error_source",
    "motion_start_s",
    "start_abs_error_rad",
    "start_abs_effort_nm",
    "campaign",
    "condition",
    "group",
)


def group_key(scenario: str, campaign: str | None, condition: str | None) -> str:
    """What episodes are compared within: the scenario of a hand-listed episode, else
    ``<campaign>/<condition>`` (``<campaign>`` when only controller and seed vary)."""
    if campaign is None:
        return scenario
    return f"{campaign}/{condition}" if condition else campaign


def _period_s(rec: Recording) -> float:
    """Median ``/controller_state`` period [s] (0 when there is one message): the
    recording's where the reader gives it (decimated frames), else the frames'."""
    if rec.control_period_s is not None:
        return rec.control_period_s
    n = max(len(rec.joint_names), 1)
    t = rec.controller_states.get_column("time_s").to_numpy()[::n]
    return float(np.median(np.diff(t))) if t.size > 1 else 0.0


def motion_completed(rec: Recording, end_s: float | None) -> bool:
    """Whether the episode ran through its motion: status "ok" and the recording does not
    end before the motion end (half a control period of slack for the sample grid).
    True when the motion end is unknown and the status is ok (nothing says otherwise),
    unless the recording was salvaged: its end is where the damage was, not the episode's."""
    if rec.status != "ok":
        return False
    motion_end = rec.trajectory_duration_s
    if motion_end is None:
        return not rec.salvaged
    return end_s is not None and end_s >= motion_end - _period_s(rec) / 2


def episode_table(
    recordings: Sequence[Recording], views: Mapping[str, ProtocolView] | None = None
) -> pl.DataFrame:
    """One row per episode: identity, status, timing and provenance.

    ``motion_end_s`` is when the reference stops (null if unknown); ``end_s``
    the last sample's time [s] (either control-rate topic), both from the recording's
    start; ``motion_completed`` see :func:`motion_completed`; ``samples`` and
    ``controller_samples`` count ``/joint_states`` and ``/controller_state`` messages
    (the recording's ``end_s``, ``sample_count`` and ``controller_sample_count`` where the
    reader gives them: a long recording's frames are decimated);
    ``error_source``, ``motion_start_s`` (the pre-roll cut), ``start_abs_error_rad`` and
    ``start_abs_effort_nm`` (the worst joint at the motion start) come from ``views``
    (the protocol applied to each recording; null without one); ``campaign`` and
    ``condition`` from the typed settings (null for a hand-listed episode) and ``group``
    is :func:`group_key`.
    """
    rows: list[dict[str, Any]] = []
    for rec in recordings:
        times = rec.samples.get_column("time_s")
        cs_times = rec.controller_states.get_column("time_s")
        ends = [float(x.max()) for x in (times, cs_times) if x.len()]  # type: ignore[arg-type]
        end_s = max(ends) if ends else None
        n_joints = max(len(rec.joint_names), 1)
        samples = times.len() // n_joints
        controller_samples = cs_times.len() // n_joints
        if rec.end_s is not None:
            end_s = rec.end_s
        if rec.sample_count is not None:
            samples = rec.sample_count
        if rec.controller_sample_count is not None:
            controller_samples = rec.controller_sample_count
        rows.append(
            {
                "episode": rec.episode,
                "controller": rec.controller,
                "scenario": rec.scenario,
                "robot": rec.robot,
                "seed": rec.meta("seed"),
                "status": rec.status,
                "reason": rec.reason,
                "salvaged": rec.salvaged,
                "salvage_lost_pct": rec.salvage_lost_pct,
                "motion_end_s": rec.trajectory_duration_s,
                "end_s": end_s,
                "samples": samples,
                "source": str(rec.source),
                "sha256": rec.sha256,
                "motion_completed": motion_completed(rec, end_s),
                "controller_samples": controller_samples,
                **_protocol_columns((views or {}).get(rec.episode)),
            }
        )
        info = _campaign((views or {}).get(rec.episode))
        rows[-1]["campaign"] = info[0]
        rows[-1]["condition"] = info[1]
        rows[-1]["group"] = group_key(rec.scenario, *info)
    schema = {
        "episode": pl.String,
        "controller": pl.String,
        "scenario": pl.String,
        "robot": pl.String,
        "seed": pl.String,
        "status": pl.String,
        "reason": pl.String,
        "salvaged": pl.Boolean,
        "salvage_lost_pct": pl.Float64,
        "motion_end_s": pl.Float64,
        "end_s": pl.Float64,
        "samples": pl.Int64,
        "source": pl.String,
        "sha256": pl.String,
        "motion_completed": pl.Boolean,
        "controller_samples": pl.Int64,
        "error_source": pl.String,
        "motion_start_s": pl.Float64,
        "start_abs_error_rad": pl.Float64,
        "start_abs_effort_nm": pl.Float64,
        "campaign": pl.String,
        "condition": pl.String,
        "group": pl.String,
    }
    return pl.DataFrame(rows, schema=schema, orient="row").sort("episode")


# The campaign tables' status of a salvaged recording cut before its motion end.
SALVAGED_CUT = "salvaged, cut before the motion end"


def shown_status(row: Mapping[str, Any]) -> str:
    """An episode row's status as the report shows it: a salvaged recording says so, how
    much was lost and, when cut before its motion end, that it is not compared."""
    status = str(row["status"])
    if not row.get("salvaged"):
        return status
    pct = row.get("salvage_lost_pct")
    lost = "loss unknown" if pct is None else f"{pct:.1f} % lost"
    cut = "" if row.get("motion_completed") else "; cut before the motion end, not compared"
    return f"{status} (salvaged: {lost}{cut})"


def comparable(episodes: pl.DataFrame) -> pl.Expr:
    """Episodes that take part in comparisons: status "ok", and not salvaged recordings cut
    before their motion end (their max and RMS cover part of the motion only)."""
    ok = pl.col("status") == "ok"
    if "salvaged" in episodes.columns and "motion_completed" in episodes.columns:
        ok = ok & ~(pl.col("salvaged").fill_null(False) & ~pl.col("motion_completed"))
    return ok


def _campaign(view: ProtocolView | None) -> tuple[str | None, str | None]:
    info = view.settings.campaign if view is not None and view.settings is not None else None
    return (None, None) if info is None else (info.name, info.condition)


def _protocol_columns(view: ProtocolView | None) -> dict[str, Any]:
    if view is None:
        return dict.fromkeys(
            ("error_source", "motion_start_s", "start_abs_error_rad", "start_abs_effort_nm")
        )
    return {
        "error_source": view.error_source,
        "motion_start_s": view.motion_start_s,
        "start_abs_error_rad": view.start_abs_error_rad,
        "start_abs_effort_nm": view.start_abs_effort_nm,
    }


def robot_spec(rec: Recording) -> RobotSpec | None:
    """The recording's robot spec (:func:`pipeline.log.robot_facts.robot_facts`); None when
    it gives none (the report then skips what needs it)."""
    return robot_facts(rec).spec


def limits_table(recordings: Sequence[Recording]) -> pl.DataFrame:
    """Effort limit per episode and joint (null where unknown)."""
    rows = []
    for rec in recordings:
        for joint, limit in robot_facts(rec).effort_limits_nm.items():
            rows.append({"episode": rec.episode, "joint": joint, "effort_limit_nm": limit})
    return pl.DataFrame(
        rows,
        schema={"episode": pl.String, "joint": pl.String, "effort_limit_nm": pl.Float64},
        orient="row",
    )
