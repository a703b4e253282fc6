"""Rerun entity paths and timeline: the one place the .rrd writer and blueprint agree on."""

from __future__ import annotations

import re

TIMELINE = "sim_time"
SERIES_ROOT = "joints"
WORLD_ROOT = "world"
QUANTITIES = ("position", "error", "velocity", "effort")
QUANTITY_LABELS = {
    "position": "position [rad]",
    "error": "error = reference - measured [rad]",
    "velocity": "velocity [rad/s]",
    "effort": "applied effort [N m]",
}

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


def reference_path(joint: str, scenario: str) -> str:
    """The reference position of one joint in one scenario."""
    return f"{quantity_path(joint, 'position')}/reference_{part(scenario)}"


def arm_path(episode: str) -> str:
    """The arm's link geometry over time for one episode."""
    return f"{WORLD_ROOT}/{part(episode)}/arm"


def ee_path_path(episode: str) -> str:
    """The end-effector path (static) of one episode."""
    return f"{WORLD_ROOT}/{part(episode)}/ee_path"
