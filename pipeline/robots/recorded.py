"""The robot as a recording carries it: a :class:`RobotSpec` by value, and back.

Every bag's ``settings.robot`` holds the robot whole, so a report (or anything reading the
bag) builds it from the bag alone, on a machine that has never seen its files:

- **A robot given as DH rows**: its YAML form (name, convention, ``angle_unit: rad``,
  joints with DH row, limits, inertial, collision radius and armature; the armature's
  source), which :func:`pipeline.robots.dh_yaml.parse_spec` rebuilds exactly.
- **Any other robot** (URDF, MJCF): every :class:`RobotSpec` field under its own name
  (joints with kind, axis, origin, limits, inertial, armature, damping and friction; named
  frames incl. the flange; base link; named states; collision shapes; the description
  text; where the facts its file lacks came from), the nested dataclasses as mappings and
  tuples as lists. One declaration: the dataclasses in :mod:`pipeline.robots.spec` are the
  schema, so a field added there travels without an edit here. Meshes travel by
  reference only (their paths as loaded): what needs no mesh (kinematics, dynamics, TCP
  metrics) works without them.

:func:`robot_from_dict` also reads the forms older bags hold: a non-DH robot recorded by
its file path and SHA-256 is loaded from that file while it still has that SHA-256, and
refused in one line otherwise.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping
from dataclasses import asdict
from typing import Any

from pydantic import TypeAdapter, ValidationError

from pipeline.errors import SpecError
from pipeline.robots.dh_yaml import format_validation_error, parse_spec
from pipeline.robots.spec import JointSpec, RobotSpec

__all__ = ["RECORDED_SOURCE", "robot_from_dict", "robot_to_dict"]

RECORDED_SOURCE = "settings.robot"
"""The ``source`` of a DH robot rebuilt from a recording (its YAML form names no file)."""

_SPEC: TypeAdapter[RobotSpec] = TypeAdapter(RobotSpec)


def _inertia_six(j: JointSpec) -> dict[str, Any]:
    if j.inertial is None:
        return {}
    t = j.inertial.inertia
    return {
        "inertial": {
            "mass": j.inertial.mass,
            "com": list(j.inertial.com),
            "inertia": [t[0][0], t[1][1], t[2][2], t[0][1], t[0][2], t[1][2]],
        }
    }


def robot_to_dict(spec: RobotSpec) -> dict[str, Any]:
    """``spec`` as plain JSON data, as recorded in every bag (see the module doc)."""
    rows = spec.dh_rows
    if rows is None:
        data: dict[str, Any] = _SPEC.dump_python(spec, mode="json")
        return data
    return {
        "name": spec.name,
        "convention": spec.convention,
        "angle_unit": "rad",
        "joints": [
            {
                "name": j.name,
                "dh": [dh.alpha, dh.a, dh.d, dh.theta_offset],
                "limits": asdict(j.limits),
                **_inertia_six(j),
                "collision": {"radius": j.collision_radius},
                "armature": j.armature,
            }
            for j, dh in zip(spec.joints, rows, strict=True)
        ],
        **({"armature_source": spec.armature_source} if spec.armature_source else {}),
    }


def robot_from_dict(data: Any, *, where: str = RECORDED_SOURCE) -> RobotSpec:
    """The robot a recording's ``settings.robot`` holds (any form :func:`robot_to_dict`
    writes or older bags hold); the inverse of :func:`robot_to_dict` (a DH robot's
    ``source`` is :data:`RECORDED_SOURCE`).

    Raises:
        SpecError: not a robot (names the field), or an old bag's robot file gone or changed.
    """
    if not isinstance(data, Mapping):
        raise SpecError(f"{where}: expected a mapping (the robot by value)")
    if "source_sha256" in data:  # by value: every RobotSpec field
        return _by_value(json.dumps(dict(data), sort_keys=True), where)
    if "sha256" in data and "convention" not in data:  # older bags: by path
        return _by_path(data, where)
    # a campaign's episodes carry the same robot: parse it once
    return _dh_form(json.dumps(dict(data), sort_keys=True), where)


@functools.lru_cache(maxsize=64)
def _by_value(text: str, where: str) -> RobotSpec:
    try:
        return _SPEC.validate_json(text)
    except ValidationError as err:
        raise SpecError(format_validation_error(where, err)) from err


@functools.lru_cache(maxsize=64)
def _dh_form(text: str, where: str) -> RobotSpec:
    data = json.loads(text)
    try:
        return parse_spec(data, source=where)
    except SpecError:
        legacy = _asdict_form(data)
        if legacy is None:
            raise
        return parse_spec(legacy, source=where)


def _by_path(data: Mapping[str, Any], where: str) -> RobotSpec:
    """A robot an older bag recorded by its file path and SHA-256: that file, while it
    still has that SHA-256."""
    from pipeline.robots.loaders import load_spec

    path = data.get("robot") or data.get("source")
    sha = str(data.get("sha256") or "")
    stale = (
        f"{where}: recorded by path ({path}, SHA-256 {sha[:12]}...) by an older armlab, "
        "and that file is"
    )
    if not isinstance(path, str) or not path:
        raise SpecError(f"{where}: recorded by path, but names no robot file")
    try:
        spec = load_spec(path)
    except SpecError as err:
        raise SpecError(f"{stale} not readable here ({err}); record the episode again") from err
    if spec.source_sha256 != sha:
        raise SpecError(f"{stale} changed since (SHA-256 {spec.source_sha256[:12]}...)")
    return spec


_YAML_JOINT_KEYS = ("name", "dh", "limits", "inertial", "collision", "armature")


def _asdict_form(data: Any) -> dict[str, Any] | None:
    """A DH robot dumped with ``dataclasses.asdict`` (early bags) in the YAML form; None
    when it is not one."""
    if not isinstance(data, dict) or not isinstance(data.get("joints"), list):
        return None
    joints = []
    for j in data["joints"]:
        if not isinstance(j, dict):
            return None
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
