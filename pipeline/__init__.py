"""armlab pipeline: plan, simulate, record and analyse manipulator control experiments."""

from __future__ import annotations

__version__ = "0.1.0"
