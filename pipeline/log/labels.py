"""A recording's labels: our ``armlab.episode`` metadata (else labels from the options or
the bag's name), its settings under the recording contract, its URDF and the notes about them.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.constants import METADATA_EPISODE, TOPIC_ROBOT_DESCRIPTION
from pipeline.log.collect import Collector, robot_description
from pipeline.log.recording import ReadOptions
from pipeline.model.urdf_xml import urdf_effort_limits, urdf_robot_name
from pipeline.settings import EpisodeSettings, SettingsError

__all__ = ["Labels", "read_labels", "typed_settings"]


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
    notes: list[str] = []
    raw_meta = dict(collector.metadata.get(METADATA_EPISODE, {}))
    ours = METADATA_EPISODE in collector.metadata
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
    urdf = robot_description(collector, chosen["robot_description"])
    if not ours and urdf is not None:
        robot = urdf_robot_name(urdf)
        if robot:
            raw_meta["robot"] = robot
    if not ours:
        notes.append(_limits_note(urdf, names, chosen["robot_description"]))
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
