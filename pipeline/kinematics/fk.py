"""Flange forward kinematics from the robot's Pinocchio model, for any robot format.

The kinematics package needs nothing from the robot description beyond joint
count, names and limits (:class:`~pipeline.robots.spec.RobotSpec`) and the
Pinocchio model built from it, whose ``tool0`` frame is the flange. So FK here
works for every robot the model layer can load, whatever its source format.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import KinematicsError
from pipeline.kinematics.limits import joint_vector
from pipeline.robots.chain import FLANGE
from pipeline.robots.spec import RobotSpec
from pipeline.robots.urdf import pinocchio_model

Array = NDArray[np.float64]


@lru_cache(maxsize=16)
def flange_model(spec: RobotSpec) -> tuple[pin.Model, pin.Data, int]:
    """(model, scratch data, flange frame id), once per spec and process.

    The model is shared: do not modify it. The data is scratch space, so these
    helpers are not thread-safe (as Pinocchio's own ``Data`` is not).
    """
    model = pinocchio_model(spec)
    return model, model.createData(), int(model.getFrameId(FLANGE))


def flange_pose(spec: RobotSpec, q: ArrayLike) -> Array:
    """Flange pose ``base_T_flange`` (4x4, [m]) of joint vector ``q`` [rad].

    Raises:
        KinematicsError: not one finite value per joint.
    """
    qs = joint_vector(spec, q)
    if not np.all(np.isfinite(qs)):
        raise KinematicsError(f"joint values must be finite [rad], got {qs.tolist()}")
    model, data, fid = flange_model(spec)
    pin.forwardKinematics(model, data, qs)
    out: Array = pin.updateFramePlacement(model, data, fid).homogeneous
    return out


__all__ = ["flange_model", "flange_pose"]
