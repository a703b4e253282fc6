"""The published Panda plant (Gaz et al. 2019) against the authors' own model, its hand,
its friction law, and the refusal of a robot it does not describe."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from pipeline.errors import ModelError
from pipeline.model.mjcf import build_mujoco_model
from pipeline.model.published import GAZ_PANDA, gaz_links, profile_plant
from pipeline.robots import load_spec
from pipeline.robots.packages import package_search_path
from pipeline.robots.urdf import build_pinocchio_model
from pipeline.sim.plant import SigmoidForce
from tests.model.gaz_reference import G0, MASS_MATRICES, gravity_nm

pytestmark = pytest.mark.skipif(
    not any((p / "example-robot-data").is_dir() for p in package_search_path()),
    reason="example-robot-data is not installed",
)
WITHIN = 0.02  # of the largest entry: the symbolic files use the reverse-engineered
# coefficients, which differ from the feasible parameters (issue 28)


@pytest.fixture(scope="module")
def panda():
    return load_spec("panda")


@pytest.fixture(scope="module")
def arm_as_identified(panda):
    """The plant's links without the hand, and no armature: the arm the authors modelled."""
    plant = profile_plant(panda, "gaz-panda")
    joints = tuple(
        replace(j, inertial=link, armature=0.0)
        for j, link in zip(plant.joints, gaz_links(hand=False), strict=True)
    )
    return replace(plant, joints=joints)


def _mujoco_g_and_m(spec, q):
    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    data.qpos[:] = q
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    return data.qfrc_bias.copy(), full, float(-model.opt.gravity[2])


@pytest.mark.parametrize("k", range(len(MASS_MATRICES)))
def test_plant_gravity_and_mass_matrix_equal_the_authors_model(arm_as_identified, k):
    q = np.array(MASS_MATRICES[k][0])
    theirs_m = np.array(MASS_MATRICES[k][1])
    mj_g, mj_m, g = _mujoco_g_and_m(arm_as_identified, q)
    theirs_g = gravity_nm(q) * g / G0  # their g0 is 9.80665, the plant's g is 9.81
    pmodel = build_pinocchio_model(arm_as_identified)
    pdata = pmodel.createData()
    pin_g = pin.computeGeneralizedGravity(pmodel, pdata, q)
    pin_m = pin.crba(pmodel, pdata, q)
    pin_m = np.triu(pin_m) + np.triu(pin_m, 1).T
    for ours_g, ours_m in ((mj_g, mj_m), (pin_g, pin_m)):
        assert np.abs(ours_g - theirs_g).max() <= WITHIN * np.abs(theirs_g).max()
        assert np.abs(ours_m - theirs_m).max() <= WITHIN * np.abs(theirs_m).max()


def test_a_wrong_transcription_would_fail_the_cross_check(arm_as_identified):
    """Link 4's mass 10 % off moves gravity beyond the tolerance: the check can fail."""
    joints = list(arm_as_identified.joints)
    inertial = joints[3].inertial
    joints[3] = replace(joints[3], inertial=replace(inertial, mass=inertial.mass * 1.1))
    wrong = replace(arm_as_identified, joints=tuple(joints))
    q = np.array(MASS_MATRICES[0][0])
    ours, _, g = _mujoco_g_and_m(wrong, q)
    theirs = gravity_nm(q) * g / G0
    assert np.abs(ours - theirs).max() > WITHIN * np.abs(theirs).max()


def test_every_published_link_is_physically_consistent():
    for link in gaz_links(hand=True):
        moments = np.linalg.eigvalsh(np.array(link.inertia))
        assert link.mass > 0 and moments.min() > 0
        a, b, c = moments
        assert a + b >= c and a + c >= b and b + c >= a  # triangle inequality


def test_the_hand_lumped_on_link_7_is_the_robot_files(panda):
    """The profile lumps the transcribed Franka Hand on link 7 as the URDF loader lumps
    the URDF's hand and fingers: example-robot-data's link 7 is Gaz et al.'s, so the two
    lumped bodies agree to rounding."""
    ours, theirs = GAZ_PANDA.links[6], panda.joints[6].inertial
    assert ours.mass == pytest.approx(theirs.mass, abs=1e-12)
    np.testing.assert_allclose(ours.com, theirs.com, atol=1e-12)
    np.testing.assert_allclose(ours.inertia, theirs.inertia, atol=1e-12)
    # and links 1-6 are the URDF's (its authors took Gaz et al.'s feasible set)
    for j, link in zip(panda.joints[:6], GAZ_PANDA.links[:6], strict=True):
        assert j.inertial == link


def test_the_plant_keeps_the_robots_armature_and_joints(panda):
    plant = profile_plant(panda, "gaz-panda")
    np.testing.assert_array_equal(plant.armature, panda.armature)
    assert plant.joint_names == panda.joint_names


def test_friction_is_zero_at_rest_and_its_sign_turns_over_a_band_of_speeds():
    friction = GAZ_PANDA.friction
    np.testing.assert_array_equal(friction.torque_nm(np.zeros(7)), np.zeros(7))
    phi1 = np.array(friction.phi1_nm)
    for j in range(7):
        speeds = np.linspace(-1.5, 1.5, 3001)
        qd = np.zeros((speeds.size, 7))
        qd[:, j] = speeds
        tau = friction.torque_nm(qd)[:, j]
        assert np.all(np.diff(tau) > 0)  # monotone: no stiction peak
        assert np.all(np.sign(tau) == np.sign(speeds))  # opposes motion either way
        # not a jump at 0: from 10 % to 90 % of the span takes 0.2-1 rad/s
        span = (tau - tau[0]) / (tau[-1] - tau[0])
        band = speeds[np.argmax(span > 0.9)] - speeds[np.argmax(span > 0.1)]
        assert 0.2 < band < 1.0
        # the transition is centred at -phi3 (a few cm/s off zero: not odd)
        centre = speeds[np.argmax(span > 0.5)]
        assert abs(centre + friction.phi3_rad_s[j]) < 0.02
        assert abs(tau[-1] - tau[0]) == pytest.approx(phi1[j], rel=0.02)


def test_the_plant_force_is_minus_the_friction_torque(panda):
    model = build_mujoco_model(panda)
    data = mujoco.MjData(model)
    force = SigmoidForce(GAZ_PANDA.friction, data)
    qd = np.array([0.3, -0.2, 0.05, -0.01, 1.0, -1.0, 0.0])
    force.apply(qd)
    np.testing.assert_allclose(data.qfrc_applied, -GAZ_PANDA.friction.torque_nm(qd), atol=1e-15)


def test_a_profile_for_another_robot_is_refused_in_one_line():
    with pytest.raises(ModelError) as err:
        profile_plant(load_spec("ur5"), "gaz-panda", where="scenarios.x.plant.profile")
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("scenarios.x.plant.profile: gaz-panda describes the Franka")
    assert "ur5 has 6 joints (shoulder_pan_joint" in message


def test_a_panda_with_other_link_frames_is_refused(panda):
    """Same joint names, other frames: the published parameters would not be its links'."""
    joints = list(panda.joints)
    origin = np.array(joints[3].origin)
    origin[0, 3] += 0.01
    joints[3] = replace(joints[3], origin=tuple(tuple(float(x) for x in r) for r in origin))
    with pytest.raises(ModelError, match="link frame of panda_joint4 is not the profile's"):
        profile_plant(replace(panda, joints=tuple(joints)), "gaz-panda")


def test_friction_held_per_control_period_follows_the_continuous_law(panda):
    """The sigmoid held over a 1 ms control period (2 RK4 steps of 0.5 ms) against the
    law evaluated at every RK4 stage (a passive-force callback inside mj_step): a free
    arm thrown at 0.5 rad/s per joint, falling for 0.5 s (up to 6 rad/s), ends within
    1 % of what the friction changes in its motion (0.4 mrad of 175 mrad)."""
    friction = GAZ_PANDA.friction

    def run(per_stage: bool, frictionless: bool = False) -> np.ndarray:
        model = build_mujoco_model(panda, timestep_s=0.0005, integrator="RK4")
        data = mujoco.MjData(model)
        data.qpos[:] = panda.named_state("default")
        data.qvel[:] = 0.5
        force = SigmoidForce(friction, data)
        for _ in range(500):
            if not (per_stage or frictionless):
                force.apply(data.qvel.copy())
            mujoco.mj_step(model, data, 2)
        return np.concatenate([data.qpos, data.qvel])

    held = run(per_stage=False)
    without = run(per_stage=False, frictionless=True)

    def passive(model, data):
        data.qfrc_passive[:] -= friction.torque_nm(data.qvel)

    mujoco.set_mjcb_passive(passive)
    try:
        staged = run(per_stage=True)
    finally:
        mujoco.set_mjcb_passive(None)
    friction_effect = np.abs(without[:7] - staged[:7]).max()
    assert friction_effect > 0.1
    assert np.abs(held[:7] - staged[:7]).max() < 0.01 * friction_effect
