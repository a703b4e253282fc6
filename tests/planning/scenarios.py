"""Shared planning scenarios: the paper's start/goal and a box that blocks the straight path."""

from __future__ import annotations

import numpy as np

from pipeline.model.dh import forward_kinematics
from pipeline.model.scene import Box
from pipeline.robots import RobotSpec

# The paper's scenario (seeds/000, Table 2): start at zero, this goal [rad].
PAPER_GOAL = np.array([-0.15, -0.5, 0.785, -1.15, -0.3925, 0.0])
START = np.zeros(6)


def blocking_box(spec: RobotSpec) -> Box:
    """A 6 cm cube beside the midpoint of the start/goal flange positions, placed so
    that the straight joint-space segment hits it but start and goal are clear."""
    mid = 0.5 * (
        forward_kinematics(spec, START)[:3, 3] + forward_kinematics(spec, PAPER_GOAL)[:3, 3]
    )
    centre = mid + np.array([-0.08, 0.0, 0.0])
    return Box("blocker", (float(centre[0]), float(centre[1]), float(centre[2])), (0.03,) * 3)
