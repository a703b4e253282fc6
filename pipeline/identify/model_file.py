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
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pipeline.errors import IdentificationError, PipelineError
from pipeline.fileio import atomic_write_bytes
from pipeline.identify.fit import FitResult
from pipeline.identify.regressor import (
    ARMATURE,
    COULOMB,
    OFFSET,
    PER_JOINT,
    VISCOUS,
    link_inertial,
)
from pipeline.identify.samples import JointSamples
from pipeline.robots.spec import RobotSpec, parse_spec
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
    joints = []
    for j in spec.joints:
        entry: dict[str, Any] = {
            "name": j.name,
            "dh": [j.dh.alpha, j.dh.a, j.dh.d, j.dh.theta_offset],
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
    return {"name": spec.name, "convention": spec.convention, "angle_unit": "rad", "joints": joints}


def identified_spec(spec: RobotSpec, theta: np.ndarray) -> RobotSpec:
    """``spec`` with the inertials and armature of standard parameters ``theta``."""
    joints = tuple(
        replace(
            joint,
            inertial=link_inertial(spec, j, theta[PER_JOINT * j : PER_JOINT * j + 10]),
            armature=float(theta[PER_JOINT * j + ARMATURE]),
        )
        for j, joint in enumerate(spec.joints)
    )
    return replace(spec, joints=joints)


def _floats(values: np.ndarray | Sequence[float]) -> list[float]:
    return [float(x) for x in values]


def model_document(
    spec: RobotSpec,
    fit: FitResult,
    samples: Sequence[JointSamples],
    *,
    method: Mapping[str, Any],
) -> dict[str, Any]:
    """The ``MODEL.yaml`` content of an identification.

    Args:
        spec: the robot identified (the CAD model).
        fit: the identification.
        samples: the recordings it used (paths and SHA-256).
        method: how the samples were made (filter, cutoff, speed threshold).
    """
    theta = fit.theta
    rel = np.abs(fit.std_error) / np.maximum(np.abs(fit.beta_wls), 1e-12) * 100
    return {
        "format": FORMAT,
        "robot": spec_document(identified_spec(spec, theta)),
        "friction": {
            "coulomb_nm": _floats(theta[COULOMB::PER_JOINT]),
            "viscous_nm_s_rad": _floats(theta[VISCOUS::PER_JOINT]),
            "offset_nm": _floats(theta[OFFSET::PER_JOINT]),
        },
        "identification": {
            "robot": spec.name,
            "robot_source": spec.source,
            "recordings": [
                {"path": s.source, "sha256": s.sha256, "ground_truth": s.truth} for s in samples
            ],
            "method": {
                "regressor": "pinocchio computeJointTorqueRegressor + armature (qdd) + "
                "friction (Coulomb sign(qd), viscous qd, offset 1) per joint",
                "base_parameters": "QR with column pivoting of the regressor stacked over "
                "random states",
                "estimator": "weighted least squares, weights 1/sigma_j from an OLS residual",
                "physical": "log-Cholesky pseudo-inertia per link (Rucker & Wensing 2022), "
                "armature and friction >= 0; Levenberg-Marquardt from the CAD model",
                **dict(method),
            },
            "equations": fit.rows,
            "condition_number": fit.condition_number,
            "condition_number_scaled": fit.condition_number_scaled,
            "projection_cost": fit.projection_cost,
            "joint_sigma_nm": _floats(fit.joint_sigma_nm),
            "residual_rms_nm": _floats(fit.residual_rms_nm),
            "torque_rms_nm": _floats(fit.torque_rms_nm),
            "base_parameters": [
                {
                    "name": name,
                    "wls": float(b),
                    "std_error": float(se),
                    "rel_std_error_pct": float(r),
                    "physical": float(p),
                    "cad": float(c),
                }
                for name, b, se, r, p, c in zip(
                    fit.base.names,
                    fit.beta_wls,
                    fit.std_error,
                    rel,
                    fit.beta,
                    fit.base.of(fit.theta_cad),
                    strict=True,
                )
            ],
        },
    }


def write_model(path: Path, document: Mapping[str, Any]) -> None:
    """Write ``MODEL.yaml`` atomically."""
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
