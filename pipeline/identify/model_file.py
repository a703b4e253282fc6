"""The identified model file (``MODEL.yaml``): identified link inertials, armature, friction
and provenance, for a robot of any description format (DH rows, URDF, MJCF).

::

    format: armlab.identified-model/1
    robot: {...}            # DH robots only: a robot YAML (pipeline/robots/*.yaml) with the
                            # identified inertials and armature (load_spec-compatible; the
                            # layout of the first model files, still read)
    description:            # any other robot: the description the model is of
      name: panda
      format: urdf
      robot: panda          # what load_spec loads it from (a built-in name or a path)
      sha256: ...           # the description file's
    links:                  # every robot: per joint, the link it moves (link frame, about
      - joint: panda_joint1 # the centre of mass; inertia [ixx, iyy, izz, ixy, ixz, iyz])
        inertial: {mass: .., com: [..], inertia: [..]}
        armature: ..
    friction:               # per joint, in the robot's joint order
      model: coulomb        # coulomb: fc sign(qd); sigmoid: fc tanh(qd / v_s)
      transition_speed_rad_s: 0.0   # v_s of the sigmoid model
      coulomb_nm: [...]
      viscous_nm_s_rad: [...]
      offset_nm: [...]      # the torque sensor's offset per joint
    torque_side: motor      # motor: the torque includes the rotor (armature identified);
                            # link: sensed after the gearbox (armature not observable:
                            # the description's value is kept)
    identification: {...}   # provenance: bags and their SHA-256, method, filter,
                            # condition number, base parameters with standard errors

A model file applies to a robot spec format-neutrally (:func:`apply_model`): the identified
values replace the spec's per-joint inertials, armature and friction.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pipeline.errors import IdentificationError, PipelineError
from pipeline.params import SEED_FIELD as SEED_FIELD
from pipeline.params import nominal_path as nominal_path
from pipeline.robots.dh_yaml import parse_spec
from pipeline.robots.spec import Inertial, RobotSpec
from pipeline.yamlio import parse_yaml

FORMAT = "armlab.identified-model/1"


FRICTION_MODELS = ("coulomb", "sigmoid")
"""``coulomb``: ``fc sign(qd)``; ``sigmoid``: ``fc tanh(qd / v_s)`` (a smooth sign change
over about the transition speed ``v_s``, as real arms' friction)."""
TORQUE_SIDES = ("motor", "link")

TransitionSpeed = float | tuple[float, ...]
"""The sigmoid friction's transition speed ``v_s`` [rad/s]: one for every joint, or one per
joint; 0: Coulomb friction ``sign(qd)``."""


def is_sigmoid(transition_speed_rad_s: TransitionSpeed) -> bool:
    """Whether ``v_s`` selects the sigmoid ``tanh(qd / v_s)`` (not ``sign(qd)``)."""
    return bool(np.all(np.asarray(transition_speed_rad_s, dtype=float) > 0))


def speed_text(transition_speed_rad_s: TransitionSpeed) -> str:
    """``v_s`` for a message: ``0.1`` or, per joint, ``0.2/0.05/...``."""
    if isinstance(transition_speed_rad_s, tuple):
        return "/".join(f"{v:g}" for v in transition_speed_rad_s)
    return f"{transition_speed_rad_s:g}"


def coulomb_shape(qd: np.ndarray, transition_speed_rad_s: TransitionSpeed) -> np.ndarray:
    """The Coulomb term's shape: ``sign(qd)``, or ``tanh(qd / v_s)`` for ``v_s > 0``
    (``qd``'s last axis is the joints when ``v_s`` is per joint)."""
    if is_sigmoid(transition_speed_rad_s):
        speeds = np.asarray(transition_speed_rad_s, dtype=float)
        return np.asarray(np.tanh(qd / speeds), dtype=float)
    return np.asarray(np.sign(qd), dtype=float)


@dataclass(frozen=True)
class Friction:
    """Identified joint friction per joint: ``tau_f = fc s(qd) + fv qd + offset``, with
    ``s = sign`` (``coulomb``) or ``tanh(qd / v_s)`` (``sigmoid``); ``offset`` is the
    torque sensor's."""

    coulomb_nm: tuple[float, ...]
    viscous_nm_s_rad: tuple[float, ...]
    offset_nm: tuple[float, ...]
    model: str = "coulomb"
    transition_speed_rad_s: TransitionSpeed = 0.0

    def torque_nm(self, qd: np.ndarray) -> np.ndarray:
        """Friction torque [N m] at joint velocities ``qd`` [rad/s] (any leading shape)."""
        return np.asarray(
            np.asarray(self.coulomb_nm) * coulomb_shape(qd, self.transition_speed_rad_s)
            + np.asarray(self.viscous_nm_s_rad) * qd
            + np.asarray(self.offset_nm),
            dtype=float,
        )


@dataclass(frozen=True)
class IdentifiedModel:
    """A loaded ``MODEL.yaml``.

    Attributes:
        spec: the identified robot (the description with the identified values applied).
        torque_side: ``motor`` or ``link`` (see the module doc).
    """

    path: Path
    spec: RobotSpec
    friction: Friction
    identification: dict[str, Any]
    torque_side: str = "motor"


def _inertia_list(i: Inertial) -> list[float]:
    t = i.inertia
    return [t[0][0], t[1][1], t[2][2], t[0][1], t[0][2], t[1][2]]


def links_document(
    spec: RobotSpec, *, armature_from: Mapping[str, str] | None = None
) -> list[dict[str, Any]]:
    """Per joint, the inertial of the link it moves and the armature (any robot format);
    ``armature_from`` (joint -> ``data``, ``prior`` or ``description``): where each
    armature value comes from, written beside it (``prior``: the data cannot separate it
    from the link inertias, the value is the CAD prior's, never identified)."""
    out = []
    for j in spec.joints:
        entry: dict[str, Any] = {"joint": j.name}
        if j.inertial is not None:
            entry["inertial"] = {
                "mass": j.inertial.mass,
                "com": list(j.inertial.com),
                "inertia": _inertia_list(j.inertial),
            }
        entry["armature"] = j.armature
        if armature_from is not None:
            entry["armature_from"] = armature_from[j.name]
        out.append(entry)
    return out


def description_document(spec: RobotSpec) -> dict[str, Any]:
    """Which description a model of a non-DH robot is of (what loads it again)."""
    return {
        "name": spec.name,
        "format": spec.format,
        "robot": spec.loaded_from or spec.source,
        "sha256": spec.source_sha256,
    }


def model_robot_document(
    spec: RobotSpec, *, armature_from: Mapping[str, str] | None = None
) -> dict[str, Any]:
    """The robot part of a model file: ``robot`` (DH) or ``description``, and ``links``
    (``armature_from``: see :func:`links_document`)."""
    head = (
        {"robot": spec_document(spec)}
        if spec.dh_rows is not None
        else {"description": description_document(spec)}
    )
    return {**head, "links": links_document(spec, armature_from=armature_from)}


def _finite(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


class ModelJointsError(IdentificationError):
    """A model file of other joints than the robot it is applied to."""


def _joints_error(where: str, joints: Any, spec: RobotSpec) -> ModelJointsError:
    return ModelJointsError(
        f"{where} is a model of joints {', '.join(map(str, joints))}, robot '{spec.name}' "
        f"has {', '.join(spec.joint_names)}"
    )


def _parse_links(data: Any, spec: RobotSpec, where: str) -> dict[str, tuple[Inertial, float]]:
    if not isinstance(data, list):
        raise IdentificationError(
            f"{where}: links: expected a list with one entry per joint, got {data!r:.60}"
        )
    names = [e.get("joint") if isinstance(e, dict) else None for e in data]
    if names != list(spec.joint_names):
        raise _joints_error(where, names, spec)
    out: dict[str, tuple[Inertial, float]] = {}
    for k, entry in enumerate(data):
        at = f"{where}.links[{k}]"
        if not isinstance(entry, dict) or entry.get("joint") not in spec.joint_names:
            got = entry.get("joint") if isinstance(entry, dict) else entry
            raise IdentificationError(
                f"{at}.joint: expected one of {', '.join(spec.joint_names)}, got {got!r}"
            )
        inertial = entry.get("inertial")
        ok = isinstance(inertial, dict)
        mass, com, tensor = (
            (inertial.get("mass"), inertial.get("com"), inertial.get("inertia"))
            if isinstance(inertial, dict)
            else (None, None, None)
        )
        ok = ok and _finite(mass) and float(mass or 0.0) > 0
        ok = ok and isinstance(com, list) and len(com) == 3 and all(map(_finite, com))
        ok = ok and isinstance(tensor, list) and len(tensor) == 6 and all(map(_finite, tensor))
        if not ok:
            raise IdentificationError(
                f"{at}.inertial: expected mass > 0, com [3] and inertia [ixx, iyy, izz, ixy, "
                f"ixz, iyz], got {inertial!r}"
            )
        armature = entry.get("armature", 0.0)
        if not (_finite(armature) and float(armature) >= 0):
            raise IdentificationError(f"{at}.armature: expected a number >= 0, got {armature!r}")
        assert isinstance(com, list) and isinstance(tensor, list) and mass is not None
        ixx, iyy, izz, ixy, ixz, iyz = (float(x) for x in tensor)
        out[str(entry["joint"])] = (
            Inertial(
                mass=float(mass),
                com=(float(com[0]), float(com[1]), float(com[2])),
                inertia=((ixx, ixy, ixz), (ixy, iyy, iyz), (ixz, iyz, izz)),
            ),
            float(armature),
        )
    return out


def apply_model(
    spec: RobotSpec,
    links: Mapping[str, tuple[Inertial, float]],
    friction: Friction | None,
    *,
    source: str,
) -> RobotSpec:
    """``spec`` (any format) with the identified inertials and armature of ``links`` (by
    joint name) and the identified friction as its stated damping / friction loss."""
    joints = []
    for k, j in enumerate(spec.joints):
        inertial, armature = links[j.name]
        extra: dict[str, Any] = {}
        if friction is not None:
            extra = {
                "damping_nm_s_rad": friction.viscous_nm_s_rad[k],
                "frictionloss_nm": friction.coulomb_nm[k],
            }
        joints.append(replace(j, inertial=inertial, armature=armature, **extra))
    return replace(spec, joints=tuple(joints), armature_source=f"identified ({source})")


def spec_document(spec: RobotSpec) -> dict[str, Any]:
    """The robot as a robot-YAML mapping (radians), the format of ``pipeline/robots``."""
    rows = spec.dh_rows
    if rows is None:
        raise IdentificationError(
            f"{spec.source}: robot '{spec.name}' is given as {spec.format}; an identified "
            "model file is written for robots given as DH rows only"
        )
    joints = []
    for j, dh in zip(spec.joints, rows, strict=True):
        entry: dict[str, Any] = {
            "name": j.name,
            "dh": [dh.alpha, dh.a, dh.d, dh.theta_offset],
            "limits": asdict(j.limits),
        }
        if j.inertial is not None:
            t = j.inertial.inertia
            entry["inertial"] = {
                "mass": j.inertial.mass,
                "com": list(j.inertial.com),
                "inertia": [t[0][0], t[1][1], t[2][2], t[0][1], t[0][2], t[1][2]],
            }
        entry["collision"] = {"radius": j.collision_radius}
        entry["armature"] = j.armature
        joints.append(entry)
    document: dict[str, Any] = {
        "name": spec.name,
        "convention": spec.convention,
        "angle_unit": "rad",
        "joints": joints,
    }
    if spec.armature_source:
        document["armature_source"] = spec.armature_source
    return document


def write_model(path: Path, document: Mapping[str, Any]) -> None:
    """Write ``MODEL.yaml`` atomically."""
    from pipeline.fsutil import atomic_write_bytes  # the fit's; the record stage only reads

    text = yaml.safe_dump(dict(document), sort_keys=False, width=100, default_flow_style=None)
    try:
        atomic_write_bytes(Path(path), text.encode("utf-8"))
    except OSError as err:
        raise IdentificationError(f"{path}: cannot write ({err.strerror or err})") from err


def load_model(path: str | Path, *, robot: RobotSpec | None = None) -> IdentifiedModel:
    """Read a ``MODEL.yaml``.

    Args:
        path: the model file.
        robot: the robot to apply it to (a scenario's); default: the model's own
            description (``robot`` of a DH model, else ``description.robot`` loaded).

    Raises:
        IdentificationError: missing, not YAML, another format, a bad robot, links or
            friction, or links of other joints than ``robot``'s.
    """
    p = Path(path)
    if not p.is_file():
        raise IdentificationError(f"{p}: no such model file")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise IdentificationError(f"{p}: cannot read ({err})") from err
    data = parse_yaml(text, source=str(p), error=IdentificationError)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        got = data.get("format") if isinstance(data, dict) else None
        raise IdentificationError(f"{p}: format: expected {FORMAT!r}, got {got!r}")
    friction_data = data.get("friction")
    if not isinstance(friction_data, dict):
        raise IdentificationError(f"{p}: friction: expected a mapping")
    side = data.get("torque_side", "motor")
    if side not in TORQUE_SIDES:
        raise IdentificationError(
            f"{p}: torque_side: expected one of {', '.join(TORQUE_SIDES)}, got {side!r}"
        )
    if isinstance(data.get("robot"), dict):  # a DH model: the robot YAML carries the values
        try:
            own = parse_spec(data.get("robot"), source=f"{p}: robot")
        except PipelineError as err:
            raise IdentificationError(str(err)) from err
        base = own if robot is None else robot
        links = {j.name: (j.inertial, j.armature) for j in own.joints if j.inertial is not None}
        if len(links) != own.dof:
            own.require_dynamics("an identified model")
    else:
        desc = data.get("description")
        ref = desc.get("robot") if isinstance(desc, dict) else None
        if robot is None:
            if not isinstance(ref, str) or not ref:
                raise IdentificationError(
                    f"{p}: description.robot: expected the robot the model is of (a name or "
                    f"path), got {ref!r}"
                )
            from pipeline.robots.loaders import load_spec

            try:
                robot = load_spec(ref)
            except PipelineError as err:
                raise IdentificationError(f"{p}: description.robot: {err}") from err
        base = robot
        links = _parse_links(data.get("links"), base, str(p))
    if list(links) != list(base.joint_names):
        raise _joints_error(str(p), links, base)
    values: dict[str, tuple[float, ...]] = {}
    for key in ("coulomb_nm", "viscous_nm_s_rad", "offset_nm"):
        v = friction_data.get(key)
        if not (isinstance(v, list) and len(v) == base.dof and all(map(_finite, v))):
            raise IdentificationError(
                f"{p}: friction.{key}: expected {base.dof} finite numbers, got {v!r}"
            )
        values[key] = tuple(float(x) for x in v)
    model = friction_data.get("model", "coulomb")
    speed = friction_data.get("transition_speed_rad_s", 0.0)
    if model not in FRICTION_MODELS:
        raise IdentificationError(
            f"{p}: friction.model: expected one of {', '.join(FRICTION_MODELS)}, got {model!r}"
        )
    per_joint = isinstance(speed, list) and model == "sigmoid"
    speeds = speed if per_joint else [speed]
    if not (
        len(speeds) == (base.dof if per_joint else 1)
        and all(_finite(v) and (v > 0 if model == "sigmoid" else v >= 0) for v in speeds)
    ):
        raise IdentificationError(
            f"{p}: friction.transition_speed_rad_s: expected a number > 0 (or {base.dof}, one "
            f"per joint) for the sigmoid model, got {speed!r}"
        )
    v_s: TransitionSpeed = (
        tuple(float(v) for v in speeds) if per_joint else float(speed if model == "sigmoid" else 0)
    )
    friction = Friction(**values, model=str(model), transition_speed_rad_s=v_s)
    is_dh_file = isinstance(data.get("robot"), dict)
    spec = (
        own if is_dh_file and robot is None else apply_model(base, links, friction, source=str(p))
    )
    ident = data.get("identification")
    return IdentifiedModel(
        path=p,
        spec=spec,
        friction=friction,
        identification=ident if isinstance(ident, dict) else {},
        torque_side=str(side),
    )


def nominal_spec(spec: RobotSpec, path: str | None, *, where: str = "nominal") -> RobotSpec:
    """The controllers' nominal robot: ``spec`` itself, or the identified model at ``path``.

    Raises:
        IdentificationError: a bad model file, or one of another robot (joint names).
    """
    if path is None:
        return spec
    from pipeline.identify.identity import kinematics_mismatch, robot_file_sha256

    try:
        model = load_model(path, robot=spec)
    except ModelJointsError as err:
        raise IdentificationError(f"{where}.nominal: {err}") from err
    if model.spec.joint_names != spec.joint_names:
        raise IdentificationError(
            f"{where}.nominal: {path} is a model of joints {', '.join(model.spec.joint_names)}, "
            f"the scenario's robot '{spec.name}' has {', '.join(spec.joint_names)}"
        )
    fitted_on = str(model.identification.get("robot", model.spec.name))
    try:  # the robot it was fitted on, as the file describes it (``model`` is ``spec``'s)
        own: RobotSpec | None = load_model(path).spec
    except IdentificationError:  # its description's file is not here: the hash below decides
        own = None
    why = kinematics_mismatch(own, spec) if own is not None else None
    if why is not None:
        raise IdentificationError(
            f"{where}.nominal: {path} is a model of robot '{fitted_on}', not of the "
            f"scenario's robot '{spec.name}' ({why}); identify this robot (pipeline identify fit)"
        )
    held = model.identification.get("robot_sha256")
    now = robot_file_sha256(spec)
    if isinstance(held, str) and held and now and held != now:
        raise IdentificationError(
            f"{where}.nominal: {path} was identified on robot file sha256 {held[:12]}, the "
            f"scenario's robot '{spec.name}' ({spec.source}) is now {now[:12]}; identify it "
            "again (pipeline identify fit)"
        )
    return model.spec


FRICTION_KEYS = {
    "friction_coulomb_nm": "coulomb_nm",
    "friction_viscous_nm_s_rad": "viscous_nm_s_rad",
}
"""Friction feed-forward gains a nominal model file fills in -> its ``friction`` fields."""


def with_nominal_friction(gains: Mapping[str, Any], path: str | None) -> dict[str, Any]:
    """``gains`` with the friction feed-forward's Coulomb and viscous values taken from
    the nominal model file at ``path``, when ``friction_ff`` is on and the gains do not
    give them (explicit values win; without a model file nothing changes).

    Raises:
        IdentificationError: a bad model file.
    """
    out = dict(gains)
    if path is None or out.get("friction_ff") is not True:
        return out
    friction = load_model(path).friction
    for key, field in FRICTION_KEYS.items():
        out.setdefault(key, [float(x) for x in getattr(friction, field)])
    return out
