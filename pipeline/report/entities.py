"""Rerun entity paths and timeline: the one place the .rrd writer and blueprint agree on."""

from __future__ import annotations

import re

from pipeline.analysis.protocol import ERROR_SOURCE_MEASURED, ERROR_SOURCE_TRUE

TIMELINE = "sim_time"
SERIES_ROOT = "joints"
WORLD_ROOT = "world"
QUANTITIES = ("position", "error", "velocity", "effort")
# A view's title: ``{state}`` is the state the metrics use (:func:`state_words`).
QUANTITY_LABELS = {
    "position": "position, {state} [rad]",
    "error": "error = reference − {state} [mrad]",
    "velocity": "velocity, {state} [rad/s]",
    "effort": "applied effort [N m]",
}
# Factor from the recorded unit to the plotted one (the error in mrad: a few ticks, not "0").
QUANTITY_SCALES = {"error": 1e3}

_UNSAFE = re.compile(r"[^A-Za-z0-9_\-.]+")


def part(name: str) -> str:
    """A name made safe as one entity-path part."""
    return _UNSAFE.sub("_", name) or "_"


def quantity_path(joint: str, quantity: str) -> str:
    """Parent of every series of one quantity of one joint (a time-series view's origin)."""
    return f"{SERIES_ROOT}/{part(joint)}/{quantity}"


def series_path(joint: str, quantity: str, episode: str) -> str:
    """One episode's series of one quantity of one joint."""
    return f"{quantity_path(joint, quantity)}/{part(episode)}"


LEGEND = "legend"


def band_path(joint: str, group: str, controller: str, level: str) -> str:
    """A percentile (``p05``, ``p50``, ``p95``) of the error over a group's episodes."""
    return f"{quantity_path(joint, 'error')}/band_{part(group)}_{part(controller)}_{level}"


def episode_root(episode: str) -> str:
    """An episode's place in the 3D scene (its base offset lives here)."""
    return f"{WORLD_ROOT}/{part(episode)}"


def label_path(episode: str) -> str:
    """The episode's name and role, written at its base."""
    return f"{episode_root(episode)}/label"


def reference_path(joint: str, scenario: str) -> str:
    """The reference position of one joint in one scenario."""
    return f"{quantity_path(joint, 'position')}/reference_{part(scenario)}"


def arm_path(episode: str) -> str:
    """The arm's link geometry over time for one episode."""
    return f"{WORLD_ROOT}/{part(episode)}/arm"


def arm_link_path(episode: str, link: str) -> str:
    """A URDF robot's link frame (posed over time) for one episode: its meshes hang on it."""
    return f"{arm_path(episode)}/{part(link)}"


TCP_ROOT = "tcp"
TCP_QUANTITIES = {
    "position_error_mm": "TCP position error [mm] (FK of reference vs {state})",
    "orientation_error_mrad": "TCP orientation error [mrad] (FK of reference vs {state})",
}


def state_words(sources: set[str]) -> str:
    """What the plotted state is, from the episodes' error sources (``error_source`` of
    :class:`pipeline.analysis.protocol.ProtocolView`)."""
    true, measured = ERROR_SOURCE_TRUE in sources, ERROR_SOURCE_MEASURED in sources
    if true and measured:
        return "true state (measured where the bag has none)"
    return "measured state" if measured else "true state"


def tcp_quantity_path(quantity: str) -> str:
    """Parent of every episode's series of one TCP error (a time-series view's origin)."""
    return f"{TCP_ROOT}/{part(quantity)}"


def tcp_series_path(quantity: str, episode: str) -> str:
    """One episode's series of one TCP error."""
    return f"{tcp_quantity_path(quantity)}/{part(episode)}"


def tcp_path_path(episode: str) -> str:
    """The TCP's path (static, FK with the tool offset) of one episode."""
    return f"{WORLD_ROOT}/{part(episode)}/tcp_path"


def ee_path_path(episode: str) -> str:
    """The end-effector path (static) of one episode."""
    return f"{WORLD_ROOT}/{part(episode)}/ee_path"
