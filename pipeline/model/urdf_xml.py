"""Facts read from a URDF's XML (robot name, effort limits), for recordings of any robot.

Neutral ground for the log reader (a bag's ``/robot_description``) and the analysis (limits
for saturation): neither reaches into the other for them.
"""

from __future__ import annotations

from xml.etree import ElementTree

import numpy as np

__all__ = ["urdf_effort_limits", "urdf_robot_name"]


def _urdf_root(urdf: str) -> ElementTree.Element | None:
    try:
        root = ElementTree.fromstring(urdf)
    except ElementTree.ParseError:
        return None
    return root if root.tag == "robot" else None


def urdf_robot_name(urdf: str) -> str | None:
    """The ``<robot name=...>`` of a URDF, None if it is not one."""
    root = _urdf_root(urdf)
    return root.get("name") if root is not None else None


def urdf_effort_limits(urdf: str) -> dict[str, float]:
    """``<limit effort=...>`` per joint of a URDF [N m] (joints without one left out)."""
    root = _urdf_root(urdf)
    limits: dict[str, float] = {}
    for joint in root.iter("joint") if root is not None else ():
        limit = joint.find("limit")
        name = joint.get("name")
        if limit is None or name is None:
            continue
        try:
            value = float(limit.get("effort", "nan"))
        except ValueError:
            continue
        if np.isfinite(value) and value > 0:
            limits[name] = value
    return limits
