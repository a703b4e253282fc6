"""What the robot shares its world with: obstacles (used by planning, the plant and stages)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Box:
    """An axis-aligned box obstacle in the robot base frame.

    Attributes:
        name: geom name.
        center: centre [m].
        half_size: half extents [m].
    """

    name: str
    center: tuple[float, float, float]
    half_size: tuple[float, float, float]
