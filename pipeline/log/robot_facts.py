"""What a recording says about its robot, whichever kind of bag it is: the one adapter the
analysis and the report ask for a robot's name, joints, model and effort limits.

- **Ours** (``armlab_metadata``): the robot recorded by value in ``settings.robot``
  (:mod:`pipeline.robots.recorded`; never re-loaded from its file), else the built-in
  robot of the recorded name; effort limits from that spec.
- **Foreign** (a bag we did not write, or ours without its robot): the robot name its
  URDF declares (:mod:`pipeline.log.labels`), the joints of ``/joint_states`` and the
  effort limits its ``/robot_description`` URDF declares; never a built-in robot of the
  same name (a URDF that names its robot ``ur5`` is not our ur5).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from pipeline.log.recording import Recording
from pipeline.model.urdf_xml import urdf_effort_limits
from pipeline.robots import RobotSpec, builtin_robot_names, load_spec

__all__ = ["RobotFacts", "robot_facts"]

FactsSource = Literal["settings", "builtin", "urdf"]


@dataclass(frozen=True)
class RobotFacts:
    """A recording's robot as far as the recording tells.

    Attributes:
        name: the robot's name (our metadata or settings, a foreign bag's URDF; "n/a").
        joint_names: joint order, as in ``/joint_states``.
        spec: the robot spec (kinematics, inertials, limits); None when the recording
            does not give one (a foreign bag, or settings without a usable robot).
        effort_limits_nm: effort limit per joint [N m] (None where unknown).
        source: where ``spec`` and the limits come from: our recorded ``settings``, the
            ``builtin`` robot of the recorded name, or the bag's ``urdf``.
    """

    name: str
    joint_names: tuple[str, ...]
    spec: RobotSpec | None
    effort_limits_nm: Mapping[str, float | None]
    source: FactsSource


def robot_facts(rec: Recording) -> RobotFacts:
    """The robot facts of ``rec`` (see the module doc)."""
    limits: dict[str, float | None] = dict.fromkeys(rec.joint_names)
    spec = _spec(rec)
    if spec is None:
        # a bag we did not write (or ours without its settings): the limits its
        # /robot_description (URDF) declares, never a built-in robot's of the same name
        for name, urdf_limit in urdf_effort_limits(rec.robot_description or "").items():
            if name in limits:
                limits[name] = urdf_limit
        return RobotFacts(rec.robot, rec.joint_names, spec, limits, "urdf")
    for j in spec.joints:
        if j.name in limits:
            limits[j.name] = j.limits.effort
    source: FactsSource = "settings" if rec.settings is not None else "builtin"
    return RobotFacts(rec.robot, rec.joint_names, spec, limits, source)


def _spec(rec: Recording) -> RobotSpec | None:
    """The robot as recorded in settings.robot (by value); else the built-in robot of the
    recorded name; None for a bag without our metadata."""
    if not rec.armlab_metadata:
        return None
    if rec.settings is not None:
        return rec.settings.robot
    if rec.robot in builtin_robot_names():
        return load_spec(rec.robot)
    return None
