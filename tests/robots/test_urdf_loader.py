"""URDF robots: the loader against independent parsers, the engines against each other, the
URDF UR5 against our DH ur5, and bad input refused in one line."""

from __future__ import annotations

import textwrap
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from pipeline.errors import SpecError
from pipeline.kinematics.fk import flange_pose
from pipeline.model.dh import forward_kinematics
from pipeline.model.mjcf import build_mujoco_model
from pipeline.robots import RobotSpec, load_spec
from pipeline.robots.packages import package_search_path
from pipeline.robots.spec import pose_matrix
from pipeline.robots.urdf import build_pinocchio_model
from tests.robots.panda_files import assert_fk_matches_yourdfpy

SHARE = next(
    (p / "example-robot-data" / "robots" for p in package_search_path() if
     (p / "example-robot-data").is_dir()),
    None,
)  # fmt: skip
pytestmark = pytest.mark.skipif(SHARE is None, reason="example-robot-data share not found")
UR5_URDF = "ur_description/urdf/ur5_robot.urdf"
PANDA_URDF = "panda_description/urdf/panda.urdf"

THREE_JOINT = """<?xml version="1.0"?>
<robot name="three">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 0.1"/><mass value="2"/>
    <inertia ixx="0.02" iyy="0.02" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.1"/>
      <geometry><cylinder radius="0.04" length="0.2"/></geometry></collision></link>
  <link name="l2"><inertial><origin xyz="0.15 0 0" rpy="0 0.3 0"/><mass value="1.5"/>
    <inertia ixx="0.003" iyy="0.012" izz="0.012" ixy="0.0001" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.15 0 0"/>
      <geometry><box size="0.3 0.05 0.05"/></geometry></collision></link>
  <link name="l3"><inertial><origin xyz="0.1 0 0"/><mass value="0.8"/>
    <inertia ixx="0.001" iyy="0.004" izz="0.004" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><sphere radius="0.03"/></geometry></collision></link>
  <link name="tool0"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="2" effort="50"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.2" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="2" effort="30"/></joint>
  <joint name="j3" type="continuous"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0 0" rpy="0 0 0.2"/><axis xyz="0 0.6 0.8"/>
    <limit velocity="3" effort="10"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="l3"/><child link="tool0"/>
    <origin xyz="0.2 0 0" rpy="0 1.5707963267948966 0"/></joint>
</robot>
"""


def _urdf(name: str) -> str:
    assert SHARE is not None
    return str(SHARE / name)


@pytest.fixture(scope="module")
def three(tmp_path_factory: pytest.TempPathFactory) -> RobotSpec:
    path = tmp_path_factory.mktemp("three") / "three.urdf"
    path.write_text(THREE_JOINT)
    return load_spec(path)


@pytest.fixture(params=["ur5", "panda", "ur5-urdf", "three"])
def any_robot(request: pytest.FixtureRequest, three: RobotSpec) -> RobotSpec:
    return {
        "ur5": lambda: load_spec("ur5"),
        "panda": lambda: load_spec("panda"),
        "ur5-urdf": lambda: load_spec(_urdf(UR5_URDF)),
        "three": lambda: three,
    }[request.param]()


def test_fk_mass_matrix_and_gravity_agree_between_mujoco_and_pinocchio(any_robot):
    spec = any_robot
    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    pmodel = build_pinocchio_model(spec)
    pdata = pmodel.createData()
    site, frame = model.site("tool0").id, pmodel.getFrameId("tool0")
    rng = np.random.default_rng(7)
    mass = np.zeros((spec.dof, spec.dof))
    for _ in range(10):
        q = rng.uniform(spec.lower, spec.upper)
        data.qpos[:] = q
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        pin.framesForwardKinematics(pmodel, pdata, q)
        ours = forward_kinematics(spec, q)
        assert np.abs(data.site_xpos[site] - ours[:3, 3]).max() < 1e-12
        assert np.abs(data.site_xmat[site].reshape(3, 3) - ours[:3, :3]).max() < 1e-12
        assert np.abs(pdata.oMf[frame].homogeneous - ours).max() < 1e-12
        mujoco.mj_fullM(model, data, mass)
        crba = pin.crba(pmodel, pdata, q)
        crba = np.triu(crba) + np.triu(crba, 1).T
        assert np.abs(mass - crba).max() <= 1e-9 * np.abs(crba).max()
        gravity = pin.computeGeneralizedGravity(pmodel, pdata, q)
        assert np.abs(data.qfrc_bias - gravity).max() <= 1e-9 * np.abs(gravity).max()


@pytest.mark.parametrize(
    ("urdf", "tip_frame"), [(UR5_URDF, "tool0"), (PANDA_URDF, "panda_hand_tcp")]
)
def test_fk_matches_yourdfpy(urdf, tip_frame):
    spec = load_spec("panda") if urdf == PANDA_URDF else load_spec(_urdf(urdf))
    assert_fk_matches_yourdfpy(spec, _urdf(urdf), tip_frame, seed=2, poses=10, atol=1e-12)


def test_urdf_ur5_and_dh_ur5_agree_at_the_flange():
    urdf, dh = load_spec(_urdf(UR5_URDF)), load_spec("ur5")
    # ROS-Industrial's base_link is the UR "base" frame (DH frame 0) turned by pi about z
    base = next(f for f in urdf.frames if f.name == "base")
    base_link_T_base = pose_matrix(base.pose)
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.uniform(dh.lower, dh.upper)
        got = np.linalg.solve(base_link_T_base, forward_kinematics(urdf, q))
        np.testing.assert_allclose(got, forward_kinematics(dh, q), atol=1e-6)


def urdf_vs_dh_ur5_mass_matrix_difference(n: int = 50) -> tuple[float, float]:
    """Largest |M_urdf - M_dh| [kg m^2] and its ratio to max |M_dh| over ``n`` random
    configurations (link inertias only: the armature left out of both)."""
    urdf, dh = load_spec(_urdf(UR5_URDF)), load_spec("ur5")
    models = [build_pinocchio_model(s) for s in (urdf, dh)]
    for m in models:
        m.armature[:] = 0.0
    datas = [m.createData() for m in models]
    rng = np.random.default_rng(0)
    worst, scale = 0.0, 0.0
    for _ in range(n):
        q = rng.uniform(dh.lower, dh.upper)
        mu, md = (pin.crba(m, d, q) for m, d in zip(models, datas, strict=True))
        mu, md = (np.triu(x) + np.triu(x, 1).T for x in (mu, md))
        worst, scale = max(worst, float(np.abs(mu - md).max())), max(scale, float(np.abs(md).max()))
    return worst, worst / scale


def test_urdf_and_dh_ur5_mass_matrices_differ_by_their_inertia_sources(capsys):
    worst, rel = urdf_vs_dh_ur5_mass_matrix_difference()
    with capsys.disabled():
        print(f"\nUR5 URDF vs DH mass matrix: max |dM| = {worst:.4g} kg m^2 ({rel:.1%} of max |M|)")
    assert 0.0 < rel < 0.5  # the same arm: different inertia sources (centres of mass)


def test_panda_fingers_are_locked_and_their_mass_counts():
    panda = load_spec("panda")
    assert panda.dof == 7 and "panda_finger_joint1" not in panda.joint_names
    frames = {f.name: f.link for f in panda.frames}
    assert frames["panda_leftfinger"] == frames["panda_hand"] == "panda_link7"
    # link7 + hand + fingers, as the URDF lists them
    assert panda.joints[-1].inertial is not None
    assert panda.joints[-1].inertial.mass == pytest.approx(0.735522 + 0.73 + 2 * 0.015, rel=1e-9)
    assert panda.disabled_pairs and ("panda_link6", "panda_link7") in panda.disabled_pairs
    assert panda.armature.tolist() == [0.1] * 7
    assert "Menagerie" in dict(panda.settings_sources)["armature"]


def _bad(tmp_path: Path, text: str, name: str = "bad.urdf") -> str:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    with pytest.raises(SpecError) as err:
        load_spec(path)
    message = str(err.value)
    assert "\n" not in message and str(path) in message
    return message


@pytest.mark.parametrize(
    ("old", "new", "says"),
    [
        ('<sphere radius="0.03"/>', '<mesh filename="meshes/none.stl"/>', "missing mesh"),
        ('<sphere radius="0.03"/>', '<mesh filename="package://no_such_pkg/m.stl"/>',
         "unresolved package 'no_such_pkg'"),
        ('<joint name="tool_joint" type="fixed"><parent link="l3"/>',
         '<joint name="loop" type="fixed"><parent link="l3"/><child link="l1"/></joint>'
         '<joint name="tool_joint" type="fixed"><parent link="l3"/>', "closed loop"),
        ('type="revolute"><parent link="base"/>', 'type="floating"><parent link="base"/>',
         "floating base"),
        ('<mass value="1.5"/>', '<mass value="-1.5"/>', "mass -1.5"),
        ('ixx="0.003" iyy="0.012" izz="0.012"', 'ixx="0.03" iyy="0.012" izz="0.012"',
         "non-physical inertia"),
        ('<limit lower="-2" upper="2" velocity="2" effort="30"/>', "", "needs <limit"),
    ],
)  # fmt: skip
def test_bad_urdf_is_one_line_naming_the_file(tmp_path, old, new, says):
    assert old in THREE_JOINT
    assert says in _bad(tmp_path, THREE_JOINT.replace(old, new))


def test_several_leaves_need_a_tip_and_the_error_lists_them():
    with pytest.raises(SpecError, match="panda_link7, panda_leftfinger") as err:
        load_spec(_urdf(PANDA_URDF))
    assert "tip:" in str(err.value)


def test_srdf_naming_an_unknown_link_is_refused(tmp_path):
    (tmp_path / "three.urdf").write_text(THREE_JOINT)
    (tmp_path / "three.srdf").write_text(
        '<robot name="three"><disable_collisions link1="l1" link2="l9" reason="x"/></robot>'
    )
    with pytest.raises(
        SpecError, match=r"three.srdf: disable_collisions\[0\].link2: unknown link 'l9'"
    ):
        load_spec(tmp_path / "three.urdf")


@pytest.mark.parametrize("srdf_at", ["urdf/three.srdf", "srdf/three.srdf"])
def test_an_srdf_found_beside_a_urdf_given_by_a_relative_path_is_read(
    tmp_path, monkeypatch, srdf_at
):
    # example-robot-data's layout (robots/X/urdf/X.urdf, robots/X/srdf/X.srdf), the URDF
    # named relative to the working directory, as `pipeline fk robots/z1/urdf/z1.urdf`
    (tmp_path / "arm" / "urdf").mkdir(parents=True)
    (tmp_path / "arm" / "srdf").mkdir()
    (tmp_path / "arm" / "urdf" / "three.urdf").write_text(THREE_JOINT)
    (tmp_path / "arm" / srdf_at).write_text(
        '<robot name="three"><disable_collisions link1="l1" link2="l3" reason="x"/>'
        '<group_state name="bent" group="arm"><joint name="j1" value="0"/>'
        '<joint name="j2" value="0.5"/><joint name="j3" value="0"/></group_state>'
        "</robot>"
    )
    monkeypatch.chdir(tmp_path)
    spec = load_spec("arm/urdf/three.urdf")
    pairs = dict(spec.settings_sources)["collision_pairs"]
    assert pairs == f"SRDF {(tmp_path / 'arm' / srdf_at).resolve()}"
    assert dict(spec.named_states)["bent"] == (0.0, 0.5, 0.0)
    assert spec.disabled_pairs  # the file's pair, not only the joints' own


_CAM = """  <link name="cam"><inertial><mass value="{mass}"/>
    <inertia ixx="{i}" iyy="{i}" izz="{i}" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="cam_joint" type="fixed"><parent link="l3"/><child link="cam"/>
    <origin xyz="0.05 0.02 -0.03" rpy="0.3 -0.2 0.1"/></joint>
</robot>"""


def _three_with_cam(folder: Path, *, mass: str, i: str, sidecar: str = "") -> Path:
    folder.mkdir()
    path = folder / "three.urdf"
    path.write_text(THREE_JOINT.replace("</robot>", _CAM.format(mass=mass, i=i)))
    if sidecar:
        (folder / "three.armlab.yaml").write_text(sidecar)
    return path


def test_a_placeholder_mass_on_a_frame_link_is_read_as_massless(tmp_path):
    # Gazebo wants a mass on every link, so frame links often state 1e-9 kg (SO-101)
    spec = load_spec(_three_with_cam(tmp_path / "placeholder", mass="1e-9", i="0"))
    plain = load_spec(_three_with_cam(tmp_path / "massless", mass="0", i="0"))
    assert spec.dof == 3 and "cam" in {f.name for f in spec.frames}
    assert [j.inertial for j in spec.joints] == [j.inertial for j in plain.joints]


def test_a_tiny_mass_with_a_real_inertia_is_still_refused(tmp_path):
    with pytest.raises(SpecError, match=r"link 'cam': mass 1e-09 kg is out of range"):
        load_spec(_three_with_cam(tmp_path / "arm", mass="1e-9", i="0.001"))


def test_a_tip_fixed_to_the_last_link_is_where_the_arm_ends(tmp_path):
    # tip: a frame link (SO-101's gripper_frame_link): the flange is its frame, as
    # Pinocchio's own URDF parser places it
    path = _three_with_cam(tmp_path / "arm", mass="0", i="0", sidecar="tip: cam\n")
    spec = load_spec(path)
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    q = np.array([0.4, -0.7, 1.1])
    config = pin.neutral(model)
    for name, value in zip(spec.joint_names, q, strict=True):
        joint = model.joints[model.getJointId(name)]
        if joint.nq == 2:  # continuous: (cos, sin)
            config[joint.idx_q : joint.idx_q + 2] = [np.cos(value), np.sin(value)]
        else:
            config[joint.idx_q] = value
    pin.framesForwardKinematics(model, data, config)
    expected = data.oMf[model.getFrameId("cam")].homogeneous
    np.testing.assert_allclose(flange_pose(spec, q), expected, atol=1e-12)
    # the default flange of a tip that is a body is unchanged: tool0 where there is one
    tool0 = load_spec(_three_with_cam(tmp_path / "tool0", mass="0", i="0"))
    assert not np.allclose(flange_pose(tool0, q), expected)


_BAD_INERTIA = 'ixx="2e-8" iyy="3e-8" izz="4e-8" ixy="6e-8" ixz="1e-8" iyz="8e-9"'
_EXTRAS = """  <link name="head"><inertial><mass value="0.5"/>
    <inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="head_pan" type="revolute"><parent link="base"/><child link="head"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="10000" effort="50000"/></joint>
  <link name="antenna"><inertial><mass value="1e-6"/><inertia {bad}/></inertial></link>
  <joint name="antenna_joint" type="fixed"><parent link="{on}"/><child link="antenna"/>
    <limit lower="-3" upper="3" velocity="10000" effort="50000"/></joint>
</robot>"""


def _three_with_extras(folder: Path, *, antenna_on: str) -> Path:
    # Baxter's head (velocity="10000"), its fixed torso joint with a <limit>, TIAGo's
    # antenna (1e-6 kg, an inertia that is no rigid body's) on the base or on the arm
    folder.mkdir()
    (folder / "three.armlab.yaml").write_text("tip: l3\n")
    path = folder / "three.urdf"
    path.write_text(
        THREE_JOINT.replace("</robot>", _EXTRAS.format(bad=_BAD_INERTIA, on=antenna_on))
    )
    return path


def test_what_moves_nothing_the_arm_does_is_not_refused(tmp_path):
    spec = load_spec(_three_with_extras(tmp_path / "base", antenna_on="base"))
    assert spec.joint_names == ("j1", "j2", "j3")
    assert spec.base_link == "base" and "antenna" in {f.name for f in spec.frames}


def test_an_unphysical_inertial_moving_with_the_arm_is_refused(tmp_path):
    with pytest.raises(SpecError, match=r"link 'antenna': non-physical inertia"):
        load_spec(_three_with_extras(tmp_path / "arm", antenna_on="l3"))


def test_an_arm_joints_speed_beyond_the_cap_is_refused_with_the_same_line(tmp_path):
    path = _three_with_extras(tmp_path / "arm", antenna_on="base")
    path.write_text(
        path.read_text().replace('velocity="2" effort="30"', 'velocity="10000" effort="30"')
    )
    with pytest.raises(SpecError, match=r"joint 'j2'.limit.velocity: 10000.0 is out of range"):
        load_spec(path)


def test_sidecar_states_where_armature_comes_from(tmp_path):
    (tmp_path / "three.urdf").write_text(THREE_JOINT)
    (tmp_path / "three.armlab.yaml").write_text(
        "armature: [0.1, 0.2, 0.3]\narmature_source: datasheet X\n"
    )
    spec = load_spec(tmp_path / "three.urdf")
    assert spec.armature.tolist() == [0.1, 0.2, 0.3]
    assert dict(spec.settings_sources)["armature"] == "datasheet X"
    assert spec.source_sha256 and spec.format == "urdf"


def test_package_uris_resolve_through_ros_package_path(tmp_path, monkeypatch):
    assert SHARE is not None
    text = (
        Path(_urdf(UR5_URDF)).read_text().replace("package://example-robot-data/", "package://erd/")
    )
    (tmp_path / "ur5.urdf").write_text(text)
    (tmp_path / "share").mkdir()
    (tmp_path / "share" / "erd").symlink_to(SHARE.parent)
    with pytest.raises(SpecError, match="unresolved package 'erd'"):
        load_spec(tmp_path / "ur5.urdf")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "share"))
    assert load_spec(tmp_path / "ur5.urdf").dof == 6


def test_dh_rows_and_the_joint_model_they_load_into_agree(any_robot):
    from pipeline.model.dh import dh_link_frames, link_frames

    if any_robot.dh_rows is None:
        pytest.skip("not given as DH rows")
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = rng.uniform(any_robot.lower, any_robot.upper)
        for a, b in zip(dh_link_frames(any_robot, q), link_frames(any_robot, q), strict=True):
            assert np.abs(a - b).max() < 1e-14


def test_urdf_robots_compile_and_step_a_second_without_warnings(any_robot):
    model = build_mujoco_model(any_robot)
    data = mujoco.MjData(model)
    data.qpos[:] = 0.5 * (any_robot.lower + any_robot.upper)
    pmodel = build_pinocchio_model(any_robot)
    pdata = pmodel.createData()
    for _ in range(int(1.0 / model.opt.timestep)):
        # hold against gravity: the nominal model's gravity torque
        data.ctrl[:] = pin.computeGeneralizedGravity(pmodel, pdata, data.qpos.copy())
        mujoco.mj_step(model, data)
    assert all(w.number == 0 for w in data.warning)
    assert np.all(np.isfinite(data.qpos))
