"""A recording's labels: our ``armlab.episode`` metadata (else labels from the options or
the bag's name), its settings under the recording contract, its URDF and the notes about them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np
from numpy.typing import NDArray

from pipeline.constants import METADATA_EPISODE, TOPIC_ROBOT_DESCRIPTION
from pipeline.log.collect import Collector, robot_description
from pipeline.log.recording import PlannedTrajectory, ReadOptions
from pipeline.model.urdf_xml import urdf_effort_limits, urdf_robot_name
from pipeline.settings import EpisodeSettings, SettingsError

__all__ = [
    "URDF_MAX_CHARS",
    "URDF_MAX_DEPTH",
    "DurationCheck",
    "Labels",
    "check_trajectory_duration",
    "labels_of",
    "read_labels",
    "reference_end_s",
    "typed_settings",
    "urdf_problem",
]

# A bag's robot description beyond these is not a URDF we read (the largest robots' URDFs,
# meshes referenced by file, are a few MB and a dozen levels deep).
URDF_MAX_CHARS = 16 * 1024 * 1024
URDF_MAX_DEPTH = 64


@dataclass(frozen=True)
class Labels:
    """What a recording says about itself.

    Attributes:
        metadata: our metadata record (string key/values), else labels from the options
            or the bag's name (and the robot name its URDF declares).
        settings: the settings under the recording contract; None when absent (a bag we
            did not write), unparseable or breaking the contract (``settings_notes`` says).
        urdf: the URDF on the robot description topic, if recorded.
        notes: what the labels, the URDF and the settings JSON gave rise to.
        settings_notes: why settings that are there do not follow the contract (the
            recording's last notes).
        ours: the bag carries our ``armlab.episode`` metadata record.
    """

    metadata: dict[str, str]
    settings: EpisodeSettings | None
    urdf: str | None
    notes: tuple[str, ...]
    settings_notes: tuple[str, ...]
    ours: bool


def typed_settings(data: dict[str, Any]) -> tuple[EpisodeSettings | None, str]:
    """Parsed settings JSON under the contract, or None and why (a note; "" if empty)."""
    if not data:
        return None, ""
    try:
        return EpisodeSettings.from_dict(data), ""
    except SettingsError as err:
        return None, f"settings do not follow the recording contract ({err}): settings are n/a"


def read_labels(
    collector: Collector,
    source: Path,
    options: ReadOptions,
    chosen: dict[str, str | None],
    names: Sequence[str],
) -> Labels:
    """Metadata (ours, else labels), typed settings, the URDF, the notes about them and
    whether the bag carries our metadata."""
    return labels_of(
        collector.metadata.get(METADATA_EPISODE),
        robot_description(collector, chosen["robot_description"]),
        source=source,
        options=options,
        urdf_topic=chosen["robot_description"],
        names=names,
    )


def labels_of(
    ours_meta: Mapping[str, str] | None,
    urdf: str | None,
    *,
    source: Path,
    options: ReadOptions,
    urdf_topic: str | None,
    names: Sequence[str],
) -> Labels:
    """:func:`read_labels` of our ``armlab.episode`` record ``ours_meta`` (None: the bag
    has none) and the recorded URDF ``urdf``."""
    notes: list[str] = []
    raw_meta = dict(ours_meta or {})
    ours = ours_meta is not None
    bag = source.name.removesuffix(".mcap")
    labels = {
        "controller": options.labels.get(bag) or options.controller,
        "scenario": options.scenario,
    }
    if not ours:
        raw_meta = {
            "episode": bag,
            "controller": bag,
            "scenario": "external",
        }
    raw_meta |= {k: v for k, v in labels.items() if v}
    problem = urdf_problem(urdf) if urdf is not None else None
    if problem is not None:
        # dropped, so nothing downstream (names, limits, a 3D model) parses it again
        urdf = None
        notes.append(
            f"{urdf_topic or TOPIC_ROBOT_DESCRIPTION}: malformed URDF "
            f"({problem}): ignored; the robot's name, effort limits and saturation at the "
            "limit are n/a"
        )
    if urdf is not None:
        sliding = _prismatic(urdf, names)
        if sliding:
            notes.append(
                f"{', '.join(sliding)}: prismatic: its position, errors and effort are in m, "
                "m/s and N where this report's labels say rad, rad/s and N m"
            )
    if not ours and urdf is not None:
        robot = urdf_robot_name(urdf)
        if robot:
            raw_meta["robot"] = robot
    if not ours and problem is None:
        notes.append(_limits_note(urdf, names, urdf_topic))
    settings: dict[str, Any] = {}
    if "settings" in raw_meta:
        try:
            parsed = json.loads(raw_meta["settings"])
            if isinstance(parsed, dict):
                settings = parsed
            else:
                notes.append(
                    f"'{METADATA_EPISODE}' settings is not a JSON object: settings are n/a"
                )
        except json.JSONDecodeError as err:
            notes.append(
                f"'{METADATA_EPISODE}' settings is not valid JSON ({err.msg} at char {err.pos}): "
                "settings are n/a"
            )
    elif not ours:
        notes.append(
            f"no '{METADATA_EPISODE}' metadata record (not recorded by armlab): episode "
            f"'{raw_meta['episode']}', controller '{raw_meta['controller']}' and scenario "
            f"'{raw_meta['scenario']}' from "
            + ("the command line" if any(labels.values()) else "the bag's name")
            + "; settings (gains, plant, planner, motion start) are n/a"
        )
    typed, why = typed_settings(settings)
    return Labels(raw_meta, typed, urdf, tuple(notes), (why,) if why else (), ours)


def _short(text: str, most: int = 60) -> str:
    return text if len(text) <= most else text[:most] + "..."


def urdf_problem(urdf: str) -> str | None:
    """Why a bag's robot description is not a URDF to read (None: it is one): too large,
    entity declarations (a URDF needs none; entity bombs use them), not XML, not a
    ``<robot>``, nested too deep, or a joint limit or mass that is not a number or not
    physical (NaN, infinite, a negative effort, velocity or mass, lower above upper)."""
    if len(urdf) > URDF_MAX_CHARS:
        return f"{len(urdf):,} characters, more than the {URDF_MAX_CHARS:,} read"
    if "<!ENTITY" in urdf:
        return "it declares XML entities (<!ENTITY>), which a URDF never needs"
    try:
        root = ElementTree.fromstring(urdf)
    except ElementTree.ParseError as err:
        return f"not XML: {_short(str(err), 120)}"
    if root.tag != "robot":
        return f"its root element is <{_short(root.tag)}>, expected <robot>"
    stack = [(root, 1)]
    while stack:
        element, depth = stack.pop()
        if depth > URDF_MAX_DEPTH:
            return f"elements nested more than {URDF_MAX_DEPTH} levels deep"
        stack.extend((child, depth + 1) for child in element)
    limit_keys: tuple[str, ...] = ("effort", "velocity", "lower", "upper")
    checks: list[tuple[str, ElementTree.Element | None, tuple[str, ...]]] = [
        (f"joint {_short(j.get('name', '?'))}: limit", j.find("limit"), limit_keys)
        for j in root.iter("joint")
    ]
    checks += [
        (f"link {_short(link.get('name', '?'))}: mass", link.find("inertial/mass"), ("value",))
        for link in root.iter("link")
    ]
    for where, found, keys in checks:
        if found is None:
            continue
        values: dict[str, float] = {}
        for key in keys:
            text = found.get(key)
            if text is None:
                continue
            try:
                values[key] = float(text)
            except ValueError:
                return f"{where} {key}={_short(text)!r} is not a number"
            if not math.isfinite(values[key]) or (
                key in ("effort", "velocity", "value") and values[key] < 0
            ):
                return f"{where} {key}={_short(text)!r} is not physical"
        if values.get("lower", -math.inf) > values.get("upper", math.inf):
            return f"{where} lower={values['lower']:g} is above upper={values['upper']:g}"
    return None


def _prismatic(urdf: str, joints: Sequence[str]) -> list[str]:
    """The recorded ``joints`` the (well-formed) URDF declares prismatic, in their order."""
    kinds = {j.get("name"): j.get("type") for j in ElementTree.fromstring(urdf).iter("joint")}
    return [name for name in joints if kinds.get(name) == "prismatic"]


def _limits_note(urdf: str | None, joints: Sequence[str], topic: str | None) -> str:
    """Where a bag without our metadata gets its effort limits (saturation) from."""
    topic = topic or TOPIC_ROBOT_DESCRIPTION
    if urdf is None:
        return (
            f"no robot description ({topic}): effort limits unknown, saturation at the limit is "
            "n/a (built-in robots of the same name are not assumed)"
        )
    limits = urdf_effort_limits(urdf)
    shown = ", ".join(f"{j} {limits[j]:g}" for j in joints if j in limits)
    missing = [j for j in joints if j not in limits]
    return (
        f"effort limits from the bag's {topic} URDF"
        + (f" [N m]: {shown}" if shown else ": none declared")
        + (f"; none for {', '.join(missing)} (saturation at the limit n/a)" if missing else "")
    )


@dataclass(frozen=True)
class DurationCheck:
    """A recorded ``planner.trajectory_duration_s`` that the recording's data contradict.

    Attributes:
        duration_s: the trajectory's duration the data give [s] (the planned trajectory
            topic's last point, else when the reference stops moving); None when they give
            none: the motion end is then unknown.
        note: what was contradicted, by what, and what is used instead.
    """

    duration_s: float | None
    note: str


def reference_end_s(
    stamps_ns: NDArray[np.int64], reference: NDArray[np.float64], t0_ns: int
) -> float | None:
    """When the reference position last changes, from ``t0_ns`` [s] (None: no rows)."""
    if stamps_ns.size < 2:
        return None
    moved = np.flatnonzero(np.any(np.abs(np.diff(reference, axis=0)) > 1e-12, axis=1))
    last = int(stamps_ns[moved[-1] + 1]) if moved.size else int(stamps_ns[0])
    return (last - t0_ns) * 1e-9


def check_trajectory_duration(
    settings: EpisodeSettings | None,
    planned: PlannedTrajectory | None,
    *,
    end_s: float | None,
    salvaged: bool,
    control_period_s: float,
    reference_end: float | None = None,
    planned_topic: str = "the planned trajectory",
) -> DurationCheck | None:
    """Check the recorded trajectory duration against the data (None: not contradicted).

    In order: the planned trajectory topic's last ``time_from_start`` (recorded with the
    motion) must be the end or the first sample after it (within its last sample step,
    plus 1 ms or 0.1 %: the recorder samples the plan on a grid); without that topic the
    reference must stop moving by the motion end it implies (within two control periods
    and 1 %); and an ``ok``, unsalvaged recording must not end before that motion end (the
    recorder records past it).
    """
    if settings is None:
        return None
    duration = settings.planner.trajectory_duration_s
    start = settings.protocol.motion_start_s
    said = f"settings planner.trajectory_duration_s = {duration:g} s"
    if planned is not None and planned.times_s.size:
        planned_s = float(planned.times_s[-1])
        # the recorder samples the plan on a grid up to the first instant >= its end
        step_s = float(planned.times_s[-1] - planned.times_s[-2]) if planned.times_s.size > 1 else 0
        tol_s = max(1e-3, 1e-3 * planned_s)
        if duration - tol_s <= planned_s <= duration + step_s + tol_s:
            return None
        return DurationCheck(
            planned_s,
            f"{said} is contradicted by {planned_topic}, whose last point is at "
            f"{planned_s:.3f} s: the motion end is taken from {planned_topic}",
        )
    slack = 2 * control_period_s + 0.01 * duration
    if reference_end is not None and reference_end - start > duration + slack:
        moving = reference_end - start
        return DurationCheck(
            moving,
            f"{said} is contradicted by the reference, which moves until {moving:.3f} s "
            "after the motion start: the motion end is taken from the reference's stamps",
        )
    ok = settings.status == "ok" and not salvaged
    if ok and end_s is not None and end_s < start + duration - slack:
        return DurationCheck(
            None,
            f"{said} is contradicted by the stamps: the recording ends at {end_s:.3f} s, "
            f"before the motion end it implies ({start + duration:.6g} s): the motion end is "
            "unknown (final error, overshoot and settling time n/a)",
        )
    return None
