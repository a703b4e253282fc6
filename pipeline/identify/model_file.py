"""The identified model file (``MODEL.yaml``): a robot description plus friction and provenance.

::

    format: armlab.identified-model/1
    robot: {...}            # a robot YAML (pipeline/robots/*.yaml) with identified
                            # inertials and armature: load_spec-compatible
    friction:               # per joint, in the robot's joint order
      coulomb_nm: [...]
      viscous_nm_s_rad: [...]
      offset_nm: [...]
    identification: {...}   # provenance: bags and their SHA-256, method, filter,
                            # condition number, base parameters with standard errors
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pipeline.errors import IdentificationError, PipelineError
from pipeline.robots.dh_yaml import parse_spec
from pipeline.robots.spec import RobotSpec
from pipeline.yamlio import parse_yaml

FORMAT = "armlab.identified-model/1"


@dataclass(frozen=True)
class Friction:
    """Identified joint friction: ``tau_f = fc sign(qd) + fv qd + offset`` per joint."""

    coulomb_nm: tuple[float, ...]
    viscous_nm_s_rad: tuple[float, ...]
    offset_nm: tuple[float, ...]

    def torque_nm(self, qd: np.ndarray) -> np.ndarray:
        """Friction torque [N m] at joint velocities ``qd`` [rad/s] (any leading shape)."""
        return np.asarray(
            np.asarray(self.coulomb_nm) * np.sign(qd)
            + np.asarray(self.viscous_nm_s_rad) * qd
            + np.asarray(self.offset_nm),
            dtype=float,
        )


@dataclass(frozen=True)
class IdentifiedModel:
    """A loaded ``MODEL.yaml``."""

    path: Path
    spec: RobotSpec
    friction: Friction
    identification: dict[str, Any]


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
    from pipeline.fileio import atomic_write_bytes  # the fit's; the record stage only reads

    text = yaml.safe_dump(dict(document), sort_keys=False, width=100, default_flow_style=None)
    try:
        atomic_write_bytes(Path(path), text.encode("utf-8"))
    except OSError as err:
        raise IdentificationError(f"{path}: cannot write ({err.strerror or err})") from err


def load_model(path: str | Path) -> IdentifiedModel:
    """Read a ``MODEL.yaml``.

    Raises:
        IdentificationError: missing, not YAML, another format, a bad robot or friction.
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
    try:
        spec = parse_spec(data.get("robot"), source=f"{p}: robot")
    except PipelineError as err:
        raise IdentificationError(str(err)) from err
    spec.require_dynamics("an identified model")
    friction_data = data.get("friction")
    if not isinstance(friction_data, dict):
        raise IdentificationError(f"{p}: friction: expected a mapping")
    values = {}
    for key in ("coulomb_nm", "viscous_nm_s_rad", "offset_nm"):
        v = friction_data.get(key)
        if not (
            isinstance(v, list)
            and len(v) == spec.dof
            and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
            and all(math.isfinite(x) for x in v)
        ):
            raise IdentificationError(
                f"{p}: friction.{key}: expected {spec.dof} finite numbers, got {v!r}"
            )
        values[key] = tuple(float(x) for x in v)
    ident = data.get("identification")
    return IdentifiedModel(
        path=p,
        spec=spec,
        friction=Friction(**values),
        identification=ident if isinstance(ident, dict) else {},
    )


SEED_FIELD = "{seed}"
"""In a scenario's ``nominal:`` path, the episode's seed: each drawn plant's own model."""


def nominal_path(path: str | None, *, seed: int) -> str | None:
    """A scenario's ``nominal:`` path for the episode of ``seed`` (``{seed}`` filled in)."""
    return None if path is None else path.replace(SEED_FIELD, str(seed))


def nominal_spec(spec: RobotSpec, path: str | None, *, where: str = "nominal") -> RobotSpec:
    """The controllers' nominal robot: ``spec`` itself, or the identified model at ``path``.

    Raises:
        IdentificationError: a bad model file, or one of another robot (joint names).
    """
    if path is None:
        return spec
    from pipeline.identify.identity import kinematics_mismatch, robot_file_sha256

    model = load_model(path)
    if model.spec.joint_names != spec.joint_names:
        raise IdentificationError(
            f"{where}.nominal: {path} is a model of joints {', '.join(model.spec.joint_names)}, "
            f"the scenario's robot '{spec.name}' has {', '.join(spec.joint_names)}"
        )
    fitted_on = str(model.identification.get("robot", model.spec.name))
    why = kinematics_mismatch(model.spec, spec)
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
