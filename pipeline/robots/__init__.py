"""Robot descriptions (YAML package data) and the spec loader."""

from __future__ import annotations

from pipeline.robots.dh_yaml import parse_spec
from pipeline.robots.loaders import builtin_robot_names, load_spec
from pipeline.robots.spec import DHRow, Inertial, JointLimits, JointSpec, RobotSpec

__all__ = [
    "DHRow",
    "Inertial",
    "JointLimits",
    "JointSpec",
    "RobotSpec",
    "builtin_robot_names",
    "load_spec",
    "parse_spec",
]
