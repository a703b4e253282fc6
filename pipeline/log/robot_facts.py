"""What a recording says about its robot, whichever kind of bag it is: the one adapter the
analysis and the report ask for a robot's name, joints, model and effort limits.

- **Ours** (``armlab_metadata``): the robot spec recorded in ``settings.robot``, else the
  built-in robot of the recorded name; effort limits from that spec (else the joints'
  ``limits.effort`` as recorded, when the spec does not parse).
- **Foreign** (a bag we did not write, or ours without its robot): the robot name its
  URDF declares (:mod:`pipeline.log.labels`), the joints of ``/joint_states`` and the
  effort limits its ``/robot_description`` URDF declares; never a built-in robot of the
  same name (a URDF that names its robot ``ur5`` is not our ur5).
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from pipeline.errors import SpecError
from pipeline.log.recording import Recording
from pipeline.model.urdf_xml import urdf_effort_limits
from pipeline.robots import RobotSpec, builtin_robot_names, load_spec, parse_spec

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
    data = rec.settings.robot if rec.settings is not None else None
    spec = _spec(rec, data)
    if not rec.armlab_metadata or (spec is None and data is None):
        # a bag we did not write (or ours without its robot): the limits its
        # /robot_description (URDF) declares, never a built-in robot's of the same name
        for name, urdf_limit in urdf_effort_limits(rec.robot_description or "").items():
            if name in limits:
                limits[name] = urdf_limit
        return RobotFacts(rec.robot, rec.joint_names, spec, limits, "urdf")
    if spec is not None:
        for j in spec.joints:
            if j.name in limits:
                limits[j.name] = j.limits.effort
        return RobotFacts(
            rec.robot, rec.joint_names, spec, limits, "settings" if data else "builtin"
        )
    joints = data.get("joints") if data is not None else None
    for j in joints if isinstance(joints, list | tuple) else []:
        if not isinstance(j, Mapping):
            continue
        lim = j.get("limits")
        value = lim.get("effort") if isinstance(lim, Mapping) else None
        if j.get("name") in limits and isinstance(value, int | float) and math.isfinite(value):
            limits[str(j["name"])] = float(value)
    return RobotFacts(rec.robot, rec.joint_names, None, limits, "settings")


def _spec(rec: Recording, data: Mapping[str, Any] | None) -> RobotSpec | None:
    """The robot as recorded in settings.robot; else the built-in robot of the recorded
    name; None for a bag without our metadata."""
    if not rec.armlab_metadata:
        return None
    if data is not None and data.get("format") not in (None, "dh-yaml"):
        return _file_spec(data)
    if data is not None:
        # a campaign's episodes carry the same robot: parse it once
        return _parsed_spec(json.dumps(dict(data), sort_keys=True))
    if rec.robot in builtin_robot_names():
        return load_spec(rec.robot)
    return None


def _file_spec(data: Mapping[str, Any]) -> RobotSpec | None:
    """The robot of a recording that names its robot file: that file, while it still has the
    recorded SHA-256 (else None: the recording's own limits stand)."""
    source = data.get("robot") or data.get("source")
    if not isinstance(source, str):
        return None
    try:
        spec = load_spec(source)
    except SpecError:
        return None
    return spec if spec.source_sha256 == data.get("sha256") else None


_YAML_JOINT_KEYS = ("name", "dh", "limits", "inertial", "collision", "armature")


def _robot_dict_to_yaml_form(data: dict[str, Any]) -> dict[str, Any]:
    """Accept a spec dumped with ``dataclasses.asdict`` as well as the YAML form."""
    joints = []
    for j in data.get("joints", []):
        if not isinstance(j, dict):
            return data
        jj = dict(j)
        dh = jj.get("dh")
        if isinstance(dh, dict):
            jj["dh"] = [dh.get("alpha"), dh.get("a"), dh.get("d"), dh.get("theta_offset")]
        inertial = jj.get("inertial")
        if isinstance(inertial, dict) and isinstance(inertial.get("inertia"), list | tuple):
            m = inertial["inertia"]
            if len(m) == 3 and all(isinstance(r, list | tuple) for r in m):
                inertial = dict(inertial)
                inertial["inertia"] = [m[0][0], m[1][1], m[2][2], m[0][1], m[0][2], m[1][2]]
                jj["inertial"] = inertial
        if "collision_radius" in jj:
            jj["collision"] = {"radius": jj.pop("collision_radius")}
        # the joint model's own fields (origins, capsules) follow from the DH rows
        joints.append({k: v for k, v in jj.items() if k in _YAML_JOINT_KEYS})
    out = {k: v for k, v in data.items() if k in ("name", "convention", "angle_unit")}
    out["joints"] = joints
    return out


@functools.lru_cache(maxsize=64)
def _parsed_spec(text: str) -> RobotSpec | None:
    data = json.loads(text)
    for candidate in (data, _robot_dict_to_yaml_form(data)):
        try:
            return parse_spec(candidate, source="settings.robot")
        except (SpecError, TypeError, ValueError):
            continue
    return None
