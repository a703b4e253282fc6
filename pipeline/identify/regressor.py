"""The joint-torque regressor and its base parameters.

Torque is linear in the *standard parameters*: per joint j, the ten inertial parameters
of the link it moves (Pinocchio's order ``m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz,
I_yz, I_zz``; first moment and rotational inertia about the URDF link frame, the frame
right after the joint's rotation), then the rotor ``armature`` (the plant adds
``armature_j * qdd_j``, as MuJoCo's joint armature), Coulomb friction ``fc``
(``sign(qd_j)``), viscous friction ``fv`` (``qd_j``) and a torque ``offset`` (``1``)::

    tau = Y(q, qd, qdd) theta        Y: (dof, 14 dof)

Many columns are zero or combinations of others (link 1's mass never shows in a
torque), so only the *base parameters* ``beta = E theta`` can be identified. They come
from a QR decomposition with column pivoting of the regressor stacked over random
samples (Gautier 1990; FloBaRoID): the first ``rank`` pivoted columns are independent,
``beta = theta_indep + K theta_dep`` with ``K = R11^-1 R12``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg
from numpy.typing import NDArray

from pipeline.errors import IdentificationError
from pipeline.identify.model_file import TransitionSpeed, coulomb_shape
from pipeline.robots.chain import chain
from pipeline.robots.spec import Inertial, RobotSpec
from pipeline.robots.urdf import build_pinocchio_model

F64 = NDArray[np.float64]

INERTIAL_NAMES = ("m", "mx", "my", "mz", "ixx", "ixy", "iyy", "ixz", "iyz", "izz")
"""Pinocchio's dynamic-parameter order (first moment and inertia at the link frame)."""
JOINT_NAMES = ("armature", "fc", "fv", "offset")
"""Per-joint drive parameters: armature [kg m^2], Coulomb [N m], viscous [N m s/rad],
offset [N m]."""
PER_JOINT = len(INERTIAL_NAMES) + len(JOINT_NAMES)
ARMATURE, COULOMB, VISCOUS, OFFSET = 10, 11, 12, 13
"""Offsets of the drive parameters inside a joint's block of :data:`PER_JOINT`."""

RANK_TOL = 1e-9
"""A pivoted column is dependent when its ``|R_ii|`` is below this share of ``|R_00|``."""


def standard_names(spec: RobotSpec) -> tuple[str, ...]:
    """``joint.parameter`` for every standard parameter, in regressor column order."""
    return tuple(f"{j}.{p}" for j in spec.joint_names for p in (*INERTIAL_NAMES, *JOINT_NAMES))


def standard_parameters(
    spec: RobotSpec,
    *,
    coulomb_nm: F64 | None = None,
    viscous_nm_s_rad: F64 | None = None,
    offset_nm: F64 | None = None,
) -> F64:
    """The spec's standard parameter vector (its inertials and armature; friction given or 0)."""
    spec.require_dynamics("identification")
    model = build_pinocchio_model(spec)
    dof = spec.dof
    theta = np.zeros(PER_JOINT * dof)
    for j in range(dof):
        block = theta[PER_JOINT * j : PER_JOINT * (j + 1)]
        block[:10] = model.inertias[j + 1].toDynamicParameters()
        block[ARMATURE] = spec.armature[j]
    for offset, values in ((COULOMB, coulomb_nm), (VISCOUS, viscous_nm_s_rad), (OFFSET, offset_nm)):
        if values is not None:
            theta[offset::PER_JOINT] = values
    return theta


def link_inertial(spec: RobotSpec, joint: int, params: F64) -> Inertial:
    """The spec's :class:`Inertial` (DH frame i, about the centre of mass) of 10 dynamic
    parameters at the URDF link frame (the inverse of what :func:`standard_parameters` reads).
    """
    inertia = pin.Inertia.FromDynamicParameters(np.asarray(params, dtype=float))
    post = chain(spec)[joint].post
    rot, pos = post[:3, :3], post[:3, 3]
    com = rot.T @ (np.asarray(inertia.lever) - pos)
    tensor = rot.T @ np.asarray(inertia.inertia) @ rot
    tensor = (tensor + tensor.T) / 2
    return Inertial(
        mass=float(inertia.mass),
        com=(float(com[0]), float(com[1]), float(com[2])),
        inertia=tuple((float(row[0]), float(row[1]), float(row[2])) for row in tensor),
    )


class Regressor:
    """Evaluates the standard regressor of one robot (a Pinocchio model and its data).

    Args:
        spec: the robot.
        transition_speed_rad_s: the Coulomb column is ``sign(qd)`` (0) or the smooth
            ``tanh(qd / v_s)`` (``v_s`` > 0, the ``sigmoid`` friction model; one per
            joint, or one for all).
        armature: the armature columns are ``qdd``; False: zero (torque sensed on the
            link side of the gearbox: the rotor's inertia does not show).
    """

    def __init__(
        self,
        spec: RobotSpec,
        *,
        transition_speed_rad_s: TransitionSpeed = 0.0,
        armature: bool = True,
    ) -> None:
        spec.require_dynamics("identification")
        self.spec = spec
        self.transition_speed_rad_s = transition_speed_rad_s
        self.armature = armature
        self.dof = spec.dof
        self.n_standard = PER_JOINT * spec.dof
        self._model = build_pinocchio_model(spec)
        self._data = self._model.createData()
        inertial = [PER_JOINT * j + k for j in range(spec.dof) for k in range(10)]
        self._inertial_columns = np.array(inertial)

    def stacked(self, q: F64, qd: F64, qdd: F64, *, coulomb: F64 | None = None) -> F64:
        """Regressor rows of N samples, sample-major: row ``k * dof + j`` is joint j at k.

        Args:
            q, qd, qdd: (N, dof) position [rad], velocity [rad/s], acceleration [rad/s^2].
            coulomb: (N, dof) the Coulomb columns when given (filtered samples: the
                friction sign low-passed like the torque, :meth:`.JointSamples.coulomb`);
                default ``sign(qd)`` or ``tanh(qd / v_s)``.

        Returns:
            (N dof, 14 dof) regressor.
        """
        n, dof = q.shape
        out = np.zeros((n, dof, self.n_standard))
        inertial = np.empty((n, dof, 10 * dof))
        model, data = self._model, self._data
        for k in range(n):
            inertial[k] = pin.computeJointTorqueRegressor(model, data, q[k], qd[k], qdd[k])
        out[:, :, self._inertial_columns] = inertial
        joints = np.arange(dof)
        base = PER_JOINT * joints
        if self.armature:
            out[:, joints, base + ARMATURE] = qdd
        if coulomb is None:
            coulomb = coulomb_shape(qd, self.transition_speed_rad_s)
        out[:, joints, base + COULOMB] = coulomb
        out[:, joints, base + VISCOUS] = qd
        out[:, joints, base + OFFSET] = 1.0
        return out.reshape(n * dof, self.n_standard)


@dataclass(frozen=True)
class BaseParameters:
    """Which combinations of the standard parameters a torque recording can determine.

    Attributes:
        names: a name per base parameter: its independent standard parameter, with
            ``+ ...`` when dependent ones are folded into it.
        columns: (rank,) standard columns kept (the independent ones, pivot order).
        projection: (rank, n_standard) ``E``: ``beta = E theta``, ``Y theta = Y[:, columns] beta``.
    """

    names: tuple[str, ...]
    columns: NDArray[np.intp]
    projection: F64

    @property
    def rank(self) -> int:
        return int(self.columns.size)

    def of(self, theta: F64) -> F64:
        """Base parameters of a standard parameter vector."""
        return np.asarray(self.projection @ theta, dtype=float)


def random_samples(spec: RobotSpec, *, n: int, seed: int) -> tuple[F64, F64, F64]:
    """``n`` random states within the joint limits (position clipped to one turn each way)."""
    rng = np.random.default_rng(seed)
    lower = np.maximum(spec.lower, -np.pi)
    upper = np.minimum(spec.upper, np.pi)
    q = rng.uniform(lower, upper, (n, spec.dof))
    qd = rng.uniform(-1, 1, (n, spec.dof)) * spec.velocity_limits
    qdd = rng.uniform(-1, 1, (n, spec.dof)) * spec.acceleration_limits
    return q, qd, qdd


@functools.lru_cache(maxsize=16)
def base_parameters(
    spec: RobotSpec, *, samples: int = 200, seed: int = 0, armature: bool = True
) -> BaseParameters:
    """Base parameters by pivoted QR of the regressor stacked over random states
    (``armature=False``: without the armature columns, link-side torque).

    Raises:
        IdentificationError: the robot has no independent parameter (cannot happen for a
            robot with dynamics).
    """
    reg = Regressor(spec, armature=armature)
    y = reg.stacked(*random_samples(spec, n=samples, seed=seed))
    _, r, perm = scipy.linalg.qr(y, mode="economic", pivoting=True)
    diag = np.abs(np.diag(r))
    rank = int(np.sum(diag > RANK_TOL * diag[0])) if diag.size and diag[0] > 0 else 0
    if rank == 0:
        raise IdentificationError(f"{spec.source}: the regressor is zero: nothing to identify")
    indep, dep = perm[:rank], perm[rank:]
    k = scipy.linalg.solve_triangular(r[:rank, :rank], r[:rank, rank:])
    k[np.abs(k) < 1e-10] = 0.0  # round-off of exact structural zeros
    projection = np.zeros((rank, reg.n_standard))
    projection[np.arange(rank), indep] = 1.0
    projection[:, dep] = k
    std = standard_names(spec)
    names = tuple(std[c] + (" + ..." if np.any(k[i] != 0) else "") for i, c in enumerate(indep))
    order = np.argsort(indep)  # report in standard order (joint by joint), not pivot order
    return BaseParameters(
        names=tuple(names[i] for i in order),
        columns=np.asarray(indep[order], dtype=np.intp),
        projection=projection[order],
    )
