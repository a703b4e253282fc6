"""A drawn plant as parameters of one compiled model, bit for bit what a recompile gives.

A campaign draws a plant per seed (link masses, centres of mass, inertias, armature) on
an otherwise fixed robot. Instead of writing and compiling MJCF per draw, the robot's
model is compiled once per process (``build_mujoco_model`` caches it) and each draw sets
``body_mass``, ``body_ipos``, ``body_inertia``, ``body_iquat`` and ``dof_armature`` on a
copy, then ``mj_setConst`` recomputes what the compiler derives from them (subtree
masses, ``dof_invweight0``, ``dof_M0``, ``actuator_acc0``, ``stat``).

The compiler diagonalises a ``fullinertia`` with its own Jacobi iteration
(``mjuu_eig3`` in MuJoCo's ``src/user/user_util.cc``), whose quaternion differs from the
engine's ``mju_eig3`` in the last bits; :func:`principal_axes` follows the compiler's
arithmetic step by step, so the model (and every recording made on it) is identical to
the recompiled one. ``tests/sim/test_plant.py`` compares every array of the two.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import mujoco
import numpy as np

from pipeline.model.mjcf import PlantOptions, build_mujoco_model
from pipeline.model.published import SigmoidFriction
from pipeline.model.scene import Box
from pipeline.robots.spec import RobotSpec

_EPS = 1e-14  # the compiler's mjEPS
_EIG_EPS = 1e-12  # its Jacobi tolerance


def _normalize(v: list[float]) -> None:
    """Unit length in place, left alone within 1e-14 of it (as the compiler does)."""
    norm_sq = 0.0
    for x in v:
        norm_sq += x * x
    if norm_sq < _EPS:
        return
    norm = math.sqrt(norm_sq)
    if abs(norm - 1) > _EPS:
        for i in range(len(v)):
            v[i] = v[i] / norm


def _quat_mat(q: list[float]) -> list[float]:
    if q[0] == 1 and q[1] == 0 and q[2] == 0 and q[3] == 0:
        return [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    q00, q01, q02, q03 = q[0] * q[0], q[0] * q[1], q[0] * q[2], q[0] * q[3]
    q11, q12, q13 = q[1] * q[1], q[1] * q[2], q[1] * q[3]
    q22, q23, q33 = q[2] * q[2], q[2] * q[3], q[3] * q[3]
    return [
        q00 + q11 - q22 - q33, 2 * (q12 - q03), 2 * (q13 + q02),
        2 * (q12 + q03), q00 - q11 + q22 - q33, 2 * (q23 - q01),
        2 * (q13 - q02), 2 * (q23 + q01), q00 - q11 - q22 + q33,
    ]  # fmt: skip


def _quat_mul(a: list[float], b: list[float]) -> list[float]:
    out = [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
    _normalize(out)
    return out


def _mat_mul(a: list[float], b: list[float]) -> list[float]:
    return [
        a[3 * r] * b[c] + a[3 * r + 1] * b[3 + c] + a[3 * r + 2] * b[6 + c]
        for r in range(3)
        for c in range(3)
    ]


def principal_axes(inertia: Sequence[Sequence[float]]) -> tuple[list[float], list[float]]:
    """Principal moments (decreasing) and the quaternion of the principal axes of a 3x3
    inertia [kg m^2], computed as MuJoCo's compiler does for ``fullinertia``."""
    full = [float(inertia[r][c]) for r in range(3) for c in range(3)]
    quat = [1.0, 0.0, 0.0, 0.0]
    moments = [0.0, 0.0, 0.0]
    for _ in range(500):
        v = _quat_mat(quat)
        vt = [v[0], v[3], v[6], v[1], v[4], v[7], v[2], v[5], v[8]]
        d = _mat_mul(_mat_mul(vt, full), v)
        moments = [d[0], d[4], d[8]]
        if abs(d[1]) > abs(d[2]) and abs(d[1]) > abs(d[5]):
            row, col, axis = 0, 1, 2
        elif abs(d[2]) > abs(d[5]):
            row, col, axis = 0, 2, 1
        else:
            row, col, axis = 1, 2, 0
        if abs(d[3 * row + col]) < _EIG_EPS:
            break
        tau = (d[4 * col] - d[4 * row]) / (2 * d[3 * row + col])
        if tau >= 0:
            t = 1.0 / (tau + math.sqrt(1 + tau * tau))
        else:
            t = -1.0 / (-tau + math.sqrt(1 + tau * tau))
        c = 1.0 / math.sqrt(1 + t * t)
        if c > 1.0 - _EIG_EPS:
            break
        rot = [0.0, 0.0, 0.0, 0.0]
        s = math.sqrt(0.5 - 0.5 * c)
        rot[axis + 1] = -s if tau >= 0 else s
        if axis == 1:
            rot[axis + 1] = -rot[axis + 1]
        rot[0] = math.sqrt(1.0 - rot[axis + 1] * rot[axis + 1])
        _normalize(rot)
        quat = _quat_mul(quat, rot)
        _normalize(quat)
    for j in range(3):  # decreasing order: bubble sort 0, 1, 0
        k = j % 2
        if moments[k] + _EIG_EPS < moments[k + 1]:
            moments[k], moments[k + 1] = moments[k + 1], moments[k]
            rot = [0.707106781186548, 0.0, 0.0, 0.0]
            rot[(k + 2) % 3 + 1] = rot[0]
            quat = _quat_mul(quat, rot)
            _normalize(quat)
    return moments, quat


def same_geometry(spec: RobotSpec, plant_spec: RobotSpec) -> bool:
    """``plant_spec`` is ``spec`` but for link inertials and armature: the same geometry
    and collision filtering (what ``pipeline.sim.contact_gate`` checks on ``spec``)."""
    return (
        len(spec.joints) == len(plant_spec.joints)
        and all(
            dataclasses.replace(p, inertial=j.inertial, armature=j.armature) == j
            for j, p in zip(spec.joints, plant_spec.joints, strict=True)
        )
        and dataclasses.replace(plant_spec, joints=spec.joints) == spec
    )


def _same_robot_but_inertials(spec: RobotSpec, plant_spec: RobotSpec) -> bool:
    """``plant_spec`` is ``spec`` with other link inertials and armature only."""
    if (
        len(spec.joints) != len(plant_spec.joints)
        or dataclasses.replace(plant_spec, joints=spec.joints) != spec
    ):
        return False
    return all(
        dataclasses.replace(p, inertial=j.inertial, armature=j.armature) == j
        and p.inertial is not None
        for j, p in zip(spec.joints, plant_spec.joints, strict=True)
    )


def plant_model(
    spec: RobotSpec,
    plant_spec: RobotSpec,
    *,
    timestep_s: float,
    plant: PlantOptions,
    obstacles: Sequence[Box],
    integrator: str,
) -> mujoco.MjModel:
    """The compiled plant: ``spec``'s model (compiled once per process) with
    ``plant_spec``'s link inertials and armature set on a copy; the same model as
    ``build_mujoco_model(plant_spec, ...)``, bit for bit. Falls back to that call when
    ``plant_spec`` differs from ``spec`` in more than inertials and armature, or when a
    drawn inertia is one the compiler would refuse (it then says why)."""

    def compiled(robot: RobotSpec) -> mujoco.MjModel:
        return build_mujoco_model(
            robot, timestep_s=timestep_s, plant=plant, obstacles=obstacles, integrator=integrator
        )

    if plant_spec == spec or spec.joints[0].inertial is None:
        return compiled(plant_spec)
    if not _same_robot_but_inertials(spec, plant_spec):
        return compiled(plant_spec)
    from pipeline.robots.chain import link_name

    extra = list(plant.armature) or [0.0]
    extra = extra * spec.dof if len(extra) == 1 else extra
    draws = []
    for joint in plant_spec.joints:
        inertial = joint.inertial
        assert inertial is not None
        moments, quat = principal_axes(inertial.inertia)
        a, b, c = moments
        if c < _EPS or a + b < c or a + c < b or b + c < a or inertial.mass < 0:
            return compiled(plant_spec)  # the compiler's own error
        draws.append((inertial, moments, quat))
    model = compiled(spec)
    bodies = [
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, link_name(j.name)) for j in spec.joints
    ]
    joints = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j.name) for j in spec.joints]
    if min(bodies + joints) < 0:  # a model named otherwise: compile the plant
        return compiled(plant_spec)
    for i, (joint, (inertial, moments, quat)) in enumerate(
        zip(plant_spec.joints, draws, strict=True)
    ):
        body, dof = bodies[i], model.jnt_dofadr[joints[i]]
        model.body_mass[body] = inertial.mass
        model.body_ipos[body] = inertial.com
        model.body_inertia[body] = moments
        model.body_iquat[body] = quat
        model.dof_armature[dof] = joint.armature + extra[i]
    data = mujoco.MjData(model)
    mujoco.mj_setConst(model, data)
    _set_statistics(model, data)
    return model


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    d0, d1, d2 = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    return math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


def _set_statistics(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """``stat.meanmass``, ``meaninertia`` (the solver's scale) and ``meansize`` as the
    compiler computes them at ``qpos0`` (``mj_setConst`` leaves them as they were)."""
    data.qpos[:] = model.qpos0
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_crb(model, data)
    xipos, anchor, geom_xpos = data.xipos.tolist(), data.xanchor.tolist(), data.geom_xpos.tolist()
    size = [0.0] * model.nbody
    for j in range(model.njnt):
        for body in (int(model.jnt_bodyid[j]), int(model.body_parentid[model.jnt_bodyid[j]])):
            size[body] = max(size[body], _dist(xipos[body], anchor[j]))
    size[0] = 0.0
    rbound = model.geom_rbound.tolist()
    for i in range(1, model.nbody):
        first = int(model.body_geomadr[i])
        for g in range(first, first + int(model.body_geomnum[i])):
            if rbound[g] > 0:
                size[i] = max(size[i], rbound[g] + _dist(xipos[i], geom_xpos[g]))
    if model.nbody > 1:
        meansize = 0.0
        for i in range(1, model.nbody):
            meansize += max(size[i], 1e-5) / (model.nbody - 1)
        model.stat.meansize = meansize
        model.stat.extent = max(model.stat.extent, 2 * meansize)
        meanmass = 0.0
        for m in model.body_mass.tolist()[1:]:
            meanmass += m
        model.stat.meanmass = meanmass / (model.nbody - 1)
    if model.nv:
        meaninertia = 0.0
        mass_matrix = data.M.tolist()  # each row's last entry is its diagonal
        for adr, nnz in zip(model.M_rowadr.tolist(), model.M_rownnz.tolist(), strict=True):
            meaninertia += mass_matrix[adr + nnz - 1]
        model.stat.meaninertia = meaninertia / model.nv


SIGMOID_FRICTION = (
    "sigmoid (Gaz et al. 2019), a generalized force from the velocity at each control "
    "instant, held over the control period; + the frictionloss (stick-slip Coulomb) and "
    "viscous damping given, if any"
)


class SigmoidForce:
    """A sigmoid joint friction (:class:`pipeline.model.published.SigmoidFriction`) on a
    MuJoCo plant: ``qfrc_applied = -tau_f(qd)``, from the velocity at each control instant
    and held over the control period, as the motor torque is.

    MuJoCo has no sigmoid friction law, and evaluating it per physics step (or per RK4
    stage) means a Python callback inside ``mj_step`` (``mjcb_passive``), which leaves the C
    loop 4 times a step. Held per control period (1 ms in params.yaml) it costs a few
    numpy operations per control step; ``benches/published_plant.py`` measures both its
    cost and its difference from the per-stage callback.
    """

    def __init__(self, friction: SigmoidFriction, data: mujoco.MjData) -> None:
        # phi1 / (1 + exp(-phi2 x)) = phi1 / 2 (1 + tanh(phi2 x / 2)): five in-place
        # operations per call, no temporaries
        a = np.asarray(friction.phi1_nm, dtype=np.float64)
        b = np.asarray(friction.phi2_s_rad, dtype=np.float64)
        self._c = np.asarray(friction.phi3_rad_s, dtype=np.float64)
        self._half_a = 0.5 * a
        self._half_b = 0.5 * b
        # tau_f(qd) = half_a tanh(half_b (qd + c)) - shift, with tau_f(0) = 0
        self._shift = self._half_a * np.tanh(self._half_b * self._c)
        self._tmp = np.empty_like(a)
        self._out = data.qfrc_applied

    def apply(self, qd: np.ndarray) -> None:
        """Set ``qfrc_applied`` to the friction force at velocity ``qd`` [rad/s]."""
        tmp = self._tmp
        np.add(qd, self._c, out=tmp)
        tmp *= self._half_b
        np.tanh(tmp, out=tmp)
        tmp *= self._half_a
        np.subtract(self._shift, tmp, out=self._out)  # -(tau_f): the force opposes motion
