"""One spec, three engines: DH FK, MuJoCo and Pinocchio must agree."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from pipeline.model.dh import forward_kinematics, link_frames
from pipeline.model.mjcf import build_mujoco_model
from pipeline.robots.chain import FLANGE
from pipeline.robots.urdf import build_pinocchio_model, build_urdf

N_SAMPLES = 50


def _random_q(spec, rng):
    return rng.uniform(spec.lower, spec.upper)


def test_fk_dh_equals_mujoco_site_equals_pinocchio_frame(any_robot):
    model = build_mujoco_model(any_robot)
    data = mujoco.MjData(model)
    pmodel = build_pinocchio_model(any_robot)
    pdata = pmodel.createData()
    site = model.site(FLANGE).id
    frame = pmodel.getFrameId(FLANGE)
    rng = np.random.default_rng(1)
    for _ in range(N_SAMPLES):
        q = _random_q(any_robot, rng)
        base_T_flange = forward_kinematics(any_robot, q)
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        pin.framesForwardKinematics(pmodel, pdata, q)
        assert np.abs(data.site_xpos[site] - base_T_flange[:3, 3]).max() <= 1e-9
        assert np.abs(data.site_xmat[site].reshape(3, 3) - base_T_flange[:3, :3]).max() <= 1e-9
        assert np.abs(pdata.oMf[frame].translation - base_T_flange[:3, 3]).max() <= 1e-9
        assert np.abs(pdata.oMf[frame].rotation - base_T_flange[:3, :3]).max() <= 1e-9


def test_every_mujoco_body_sits_at_its_dh_frame(any_robot):
    model = build_mujoco_model(any_robot)
    data = mujoco.MjData(model)
    q = _random_q(any_robot, np.random.default_rng(2))
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    for joint, base_T_i in zip(any_robot.joints, link_frames(any_robot, q), strict=True):
        body = model.joint(joint.name).bodyid[0]
        assert np.abs(data.xpos[body] - base_T_i[:3, 3]).max() <= 1e-9
        assert np.abs(data.xmat[body].reshape(3, 3) - base_T_i[:3, :3]).max() <= 1e-9


def test_mass_matrix_and_bias_agree(dynamic_robot):
    model = build_mujoco_model(dynamic_robot)
    data = mujoco.MjData(model)
    pmodel = build_pinocchio_model(dynamic_robot)
    pdata = pmodel.createData()
    rng = np.random.default_rng(3)
    mass = np.zeros((model.nv, model.nv))
    for _ in range(N_SAMPLES):
        q = _random_q(dynamic_robot, rng)
        v = rng.normal(0.0, 1.5, dynamic_robot.dof)
        data.qpos[:] = q
        data.qvel[:] = v
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, mass)
        crba = pin.crba(pmodel, pdata, q)
        crba = np.triu(crba) + np.triu(crba, 1).T
        assert np.abs(mass - crba).max() <= 1e-9 * np.abs(crba).max()
        bias = pin.rnea(pmodel, pdata, q, v, np.zeros(dynamic_robot.dof))
        assert np.abs(data.qfrc_bias - bias).max() <= 1e-9 * np.abs(bias).max()
        gravity = pin.computeGeneralizedGravity(pmodel, pdata, q)
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        assert np.abs(data.qfrc_bias - gravity).max() <= 1e-9 * np.abs(gravity).max()


def test_total_mass_matches_the_yaml(dynamic_robot):
    model = build_mujoco_model(dynamic_robot)
    pmodel = build_pinocchio_model(dynamic_robot)
    expected = sum(j.inertial.mass for j in dynamic_robot.joints)
    assert model.body_subtreemass[1] == pytest.approx(expected)
    assert sum(inertia.mass for inertia in pmodel.inertias) == pytest.approx(expected)


def test_every_model_compiles_and_steps_one_second_without_warnings(any_robot):
    model = build_mujoco_model(any_robot)
    data = mujoco.MjData(model)
    for _ in range(round(1.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    assert all(w.number == 0 for w in data.warning), [w.number for w in data.warning]
    assert np.isfinite(data.qpos).all()


def test_zero_pose_is_collision_free(any_robot):
    model = build_mujoco_model(any_robot)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert data.ncon == 0


def test_model_angles_are_radians(ur5):
    model = build_mujoco_model(ur5)
    assert model.jnt_range[0, 1] == pytest.approx(2 * np.pi)
    assert '<compiler angle="radian"' in __import__(
        "pipeline.model.mjcf", fromlist=["x"]
    ).build_mjcf(ur5)


def test_urdf_carries_names_limits_and_flange(ur5):
    urdf = build_urdf(ur5)
    for name in ur5.joint_names:
        assert f'name="{name}"' in urdf
    assert '<link name="tool0"/>' in urdf
    assert 'effort="28.0"' in urdf


def test_tf_tree_composes_to_the_dh_flange(any_robot):
    from pipeline.model.frames import tf_edges

    rng = np.random.default_rng(4)
    for _ in range(10):
        q = _random_q(any_robot, rng)
        pose = np.eye(4)
        for edge in tf_edges(any_robot, q):
            pose = pose @ edge.parent_T_child
        assert np.abs(pose - forward_kinematics(any_robot, q)).max() <= 1e-9


def test_inverse_dynamics_with_armature_agree(dynamic_robot):
    """Rotor armature enters both engines the same way: M + diag(armature), tau += a * qdd."""
    assert (dynamic_robot.armature > 0).all(), "built-in dynamic robots carry armature"
    model = build_mujoco_model(dynamic_robot)
    # rigid-body dynamics only: random poses may touch themselves (contact forces)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    data = mujoco.MjData(model)
    pmodel = build_pinocchio_model(dynamic_robot)
    pdata = pmodel.createData()
    rng = np.random.default_rng(5)
    for _ in range(N_SAMPLES):
        q = _random_q(dynamic_robot, rng)
        v = rng.normal(0.0, 1.5, dynamic_robot.dof)
        a = rng.normal(0.0, 3.0, dynamic_robot.dof)
        data.qpos[:], data.qvel[:], data.qacc[:] = q, v, a
        mujoco.mj_inverse(model, data)
        tau = pin.rnea(pmodel, pdata, q, v, a)
        assert np.abs(data.qfrc_inverse - tau).max() <= 1e-9 * np.abs(tau).max()
    # and the armature is really there: removing it changes M's diagonal by exactly it
    bare = build_pinocchio_model(
        type(dynamic_robot)(
            name=dynamic_robot.name,
            convention=dynamic_robot.convention,
            joints=tuple(replace(j, armature=0.0) for j in dynamic_robot.joints),
            source=dynamic_robot.source,
        )
    )
    q = _random_q(dynamic_robot, rng)
    diff = pin.crba(pmodel, pmodel.createData(), q) - pin.crba(bare, bare.createData(), q)
    assert np.allclose(np.diag(diff), dynamic_robot.armature, atol=1e-12)
