"""MJCF robots: example-robot-data's Panda URDF -> MuJoCo -> saved MJCF -> our MJCF loader
against the URDF-loaded Panda (Pinocchio and MuJoCo on both) and against MuJoCo's own
compile of that MJCF; bad input refused in one line."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from pipeline.errors import SpecError
from pipeline.model.dh import forward_kinematics
from pipeline.model.mjcf import build_mujoco_model
from pipeline.robots import RobotSpec, load_spec
from pipeline.robots.urdf import build_pinocchio_model
from tests.robots.test_urdf_loader import SHARE, _bad

pytestmark = pytest.mark.skipif(SHARE is None, reason="example-robot-data share not found")
ARM = [f"panda_joint{i}" for i in range(1, 8)]
N_CONFIGS = 20


@pytest.fixture(scope="module")
def mjcf_panda(panda_xml: Path) -> RobotSpec:
    return load_spec(panda_xml)


def _engines(spec: RobotSpec, q: np.ndarray) -> dict[str, np.ndarray]:
    """FK at the flange, mass matrix and gravity of ``spec`` by Pinocchio and by MuJoCo."""
    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    mass = np.zeros((spec.dof, spec.dof))
    mujoco.mj_fullM(model, data, mass)
    site = model.site("tool0").id
    fk = np.eye(4)
    fk[:3, :3], fk[:3, 3] = data.site_xmat[site].reshape(3, 3), data.site_xpos[site]
    pmodel = build_pinocchio_model(spec)
    pdata = pmodel.createData()
    pin.framesForwardKinematics(pmodel, pdata, q)
    crba = pin.crba(pmodel, pdata, q)
    return {
        "mujoco fk": fk,
        "mujoco mass": mass,
        "mujoco gravity": data.qfrc_bias.copy(),
        "pinocchio fk": pdata.oMf[pmodel.getFrameId("tool0")].homogeneous,
        "pinocchio mass": np.triu(crba) + np.triu(crba, 1).T,
        "pinocchio gravity": pin.computeGeneralizedGravity(pmodel, pdata, q),
        "our fk": forward_kinematics(spec, q),
    }


def test_panda_round_trip_through_mjcf_keeps_fk_mass_matrix_and_gravity(mjcf_panda):
    urdf_panda = load_spec("panda")
    assert mjcf_panda.joint_names == urdf_panda.joint_names and mjcf_panda.format == "mjcf"
    np.testing.assert_array_equal(mjcf_panda.lower, urdf_panda.lower)
    np.testing.assert_array_equal(mjcf_panda.effort_limits, urdf_panda.effort_limits)
    rng = np.random.default_rng(17)
    worst = {"fk": 0.0, "mass": 0.0, "gravity": 0.0}
    for _ in range(N_CONFIGS):
        q = rng.uniform(urdf_panda.lower, urdf_panda.upper)
        ref = _engines(urdf_panda, q)
        got = _engines(mjcf_panda, q)
        for key in got:
            quantity = key.split()[1]
            # mj_saveLastXML writes 6 significant digits: that rounding is the difference
            scale = max(1.0, float(np.abs(ref[key]).max()))
            error = float(np.abs(got[key] - ref[key]).max()) / scale
            worst[quantity] = max(worst[quantity], error)
        # within one robot the engines agree to rounding
        for quantity in ("mass", "gravity"):
            a, b = got[f"mujoco {quantity}"], got[f"pinocchio {quantity}"]
            assert np.abs(a - b).max() <= 1e-9 * max(1.0, float(np.abs(b).max()))
        assert np.abs(got["pinocchio fk"] - got["our fk"]).max() < 1e-12
    print("URDF vs MJCF Panda, worst relative difference:", worst)
    assert worst["fk"] < 2e-6 and worst["mass"] < 2e-5 and worst["gravity"] < 2e-5, worst


def test_mjcf_loader_agrees_with_mujocos_own_compile_of_the_file(mjcf_panda, panda_xml):
    own = mujoco.MjModel.from_xml_path(str(panda_xml))  # fingers free, at qpos0 = 0
    data = mujoco.MjData(own)
    dofs = [own.joint(n).dofadr[0] for n in ARM]
    body = own.body("panda_hand_tcp").id
    rng = np.random.default_rng(3)
    full = np.zeros((own.nv, own.nv))
    for _ in range(N_CONFIGS):
        q = rng.uniform(mjcf_panda.lower, mjcf_panda.upper)
        data.qpos[:] = own.qpos0
        data.qpos[[own.joint(n).qposadr[0] for n in ARM]] = q
        mujoco.mj_forward(own, data)
        mujoco.mj_fullM(own, data, full)
        ours = _engines(mjcf_panda, q)
        assert np.abs(ours["our fk"][:3, 3] - data.xpos[body]).max() < 1e-12
        assert np.abs(ours["our fk"][:3, :3] - data.xmat[body].reshape(3, 3)).max() < 1e-12
        # the arm's block of the full mass matrix is the locked-finger arm's (the sidecar's
        # armature on top of the file's none)
        m = full[np.ix_(dofs, dofs)] + np.diag(mjcf_panda.armature)
        assert np.abs(ours["pinocchio mass"] - m).max() <= 1e-9 * np.abs(m).max()
        g = data.qfrc_bias[dofs]
        assert np.abs(ours["pinocchio gravity"] - g).max() <= 1e-9 * np.abs(g).max()


def test_mjcf_robot_states_where_each_fact_came_from(mjcf_panda):
    sources = dict(mjcf_panda.settings_sources)
    assert sources["damping"] == "MJCF <joint damping>"  # the URDF's <dynamics damping=0.003>
    assert mjcf_panda.damping == (0.003,) * 7
    assert sources["velocity"] == "default 2" and sources["armature"].endswith(".armlab.yaml")
    assert {f.name for f in mjcf_panda.frames} >= {"panda_hand", "panda_leftfinger"}


def test_fk_cli_works_on_an_mjcf_file(panda_xml, capsys):
    from tests.test_bad_input import run_cli_out

    ready = ["0", "-0.785398", "0", "-2.35619", "0", "1.5707", "0.785398"]
    code, out, err = run_cli_out(["fk", str(panda_xml), *ready, "--json"], capsys)
    assert code == 0, err
    assert "position" in out


ONE_HINGE = """\
<mujoco model="arm">
  <worldbody>
    <body name="base">
      <body name="l1" pos="0 0 0.1">
        <joint name="j1" axis="0 0 1" range="-2 2" actuatorfrcrange="-10 10"/>
        <geom type="box" size="0.02 0.02 0.1" mass="1"/>
        <body name="l2" pos="0 0 0.2">
          <joint name="j2" axis="0 1 0" range="-2 2" actuatorfrcrange="-10 10"/>
          <geom type="sphere" size="0.05" mass="0.5"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
LEAF = '<geom type="sphere" size="0.05" mass="0.5"/>'
SECOND_LEAF = (  # closes l2, opens l3 on l1
    '</body><body name="l3" pos="0 0.1 0.2">'
    '<joint name="j3" range="-1 1" actuatorfrcrange="-5 5"/><geom size="0.03" mass="0.2"/>'
)


def test_a_small_mjcf_arm_loads_and_its_sidecar_wins(tmp_path):
    path = tmp_path / "arm.xml"
    path.write_text(ONE_HINGE.replace('range="-2 2"', 'range="-2 2" damping="0.4"', 1))
    spec = load_spec(path)
    assert spec.joint_names == ("j1", "j2") and spec.base_link == "base"
    assert spec.damping == (0.4, 0.0) and spec.joints[0].shapes[0].kind == "box"
    folder = tmp_path / "with_sidecar"
    folder.mkdir()
    (folder / "arm.xml").write_text(path.read_text() + " ")  # another file: not the cached one
    (folder / "arm.armlab.yaml").write_text("damping: [1.0, 2.0]\nvelocity: 3.0\n")
    spec = load_spec(folder / "arm.xml")
    assert spec.damping == (1.0, 2.0) and spec.velocity_limits.tolist() == [3.0, 3.0]
    assert dict(spec.settings_sources)["damping"] == str(folder / "arm.armlab.yaml")


@pytest.mark.parametrize(
    ("old", "new", "says"),
    [
        ('<body name="base">', '<body name="base"><freejoint name="free"/><geom size="0.1"/>',
         "joint 'free' is free (a floating base)"),
        ('<joint name="j2" axis="0 1 0" range="-2 2" actuatorfrcrange="-10 10"/>',
         '<joint name="j2" type="ball"/>', "joint 'j2' is ball"),
        ("</worldbody>", '</worldbody><equality><connect name="loop" body1="l2" body2="base" '
         'anchor="0 0 0"/></equality>', "<equality> 'loop' (connect): a closed loop"),
        (LEAF, LEAF + SECOND_LEAF, "several leaf chains end at bodies l2, l3"),
        ('actuatorfrcrange="-10 10"/>\n        <geom type="box"', '/>\n        <geom type="box"',
         "joint 'j1': no effort limit"),
        ('<joint name="j2"',
         '<joint name="j2b" range="-1 1" actuatorfrcrange="-1 1"/><joint name="j2"',
         "body 'l2' has 2 joints"),
        ("<worldbody>", "<worldbody><bogus/>", "MuJoCo cannot load it"),
        ('<joint name="j1"', '<joint name="j1" ref="0.5"', "joint 'j1' has ref 0.0087"),
    ],
)  # fmt: skip
def test_bad_mjcf_is_one_line_naming_the_file_and_element(tmp_path, old, new, says):
    assert old in ONE_HINGE
    assert says in _bad(tmp_path, ONE_HINGE.replace(old, new), name="bad.xml")


def test_several_leaves_with_a_tip_lock_the_others(tmp_path):
    (tmp_path / "arm.xml").write_text(ONE_HINGE.replace(LEAF, LEAF + SECOND_LEAF))
    (tmp_path / "arm.armlab.yaml").write_text("tip: l2\n")
    spec = load_spec(tmp_path / "arm.xml")
    assert spec.joint_names == ("j1", "j2")
    assert spec.joints[0].inertial is not None and spec.joints[0].inertial.mass == pytest.approx(
        1.2
    )


OFFSET_ARM = """\
<mujoco model="offset">
  <compiler angle="degree"/>
  <worldbody>
    <body name="base" pos="0.3 0 0" euler="0 0 30">
      <body name="l1" pos="0 0 0.1" euler="10 0 0">
        <joint name="j1" pos="0.02 0 0.05" axis="0 0.6 0.8" range="-120 120"
               actuatorfrcrange="-10 10"/>
        <geom type="box" size="0.02 0.03 0.1" pos="0 0 0.1" euler="0 20 0" mass="1"/>
        <body name="l2" pos="0.05 0 0.2">
          <joint name="j2" type="slide" axis="1 0 0" range="-0.1 0.2" actuatorfrcrange="-50 50"/>
          <geom type="cylinder" size="0.03 0.08" mass="0.7"/>
          <body name="l3" pos="0.1 0.02 0">
            <joint name="j3" pos="0 0.01 0.03" axis="0 1 0" actuatorfrcrange="-5 5"/>
            <geom type="capsule" size="0.02 0.05" pos="0.05 0 0" mass="0.3"/>
            <site name="tool0" pos="0.12 0 0" euler="0 90 0"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_joint_offsets_slides_and_frames_match_mujocos_own_compile(tmp_path):
    path = tmp_path / "offset.xml"
    path.write_text(OFFSET_ARM)
    spec = load_spec(path)
    assert [j.kind for j in spec.joints] == ["revolute", "prismatic", "continuous"]
    own = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(own)
    base = np.eye(4)  # our base frame is the body "base": MuJoCo's world pose of it
    base[:3, :3], base[:3, 3] = mujoco_rotation(own.body("base").quat), own.body("base").pos
    rng = np.random.default_rng(5)
    full = np.zeros((own.nv, own.nv))
    for _ in range(N_CONFIGS):
        q = rng.uniform(spec.lower, spec.upper)
        data.qpos[:] = q
        mujoco.mj_forward(own, data)
        mujoco.mj_fullM(own, data, full)
        ours = _engines(spec, q)
        tool = np.eye(4)
        tool[:3, :3] = data.site_xmat[own.site("tool0").id].reshape(3, 3)
        tool[:3, 3] = data.site_xpos[own.site("tool0").id]
        assert np.abs(base @ ours["our fk"] - tool).max() < 1e-12
        assert np.abs(ours["pinocchio mass"] - full).max() <= 1e-9 * np.abs(full).max()
        assert np.abs(ours["mujoco mass"] - full).max() <= 1e-9 * np.abs(full).max()
        # gravity in the base frame: the file turns the base about z only
        assert np.abs(ours["pinocchio gravity"] - data.qfrc_bias).max() <= 1e-9 * max(
            1.0, float(np.abs(data.qfrc_bias).max())
        )


def mujoco_rotation(quat: np.ndarray) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(quat, dtype=np.float64))
    return out.reshape(3, 3)


@pytest.mark.slow
def test_an_mjcf_robot_records_and_reports(panda_xml, tmp_path, capsys):
    from pipeline.log.reader import read_recording
    from tests.stages.test_urdf_robot_e2e import PARAMS
    from tests.test_bad_input import run_cli, run_cli_out

    params = tmp_path / "params.yaml"
    params.write_text(PARAMS.replace("robot: panda", f"robot: {panda_xml}"))
    code, err = run_cli(["record", "--params", str(params), "--out", str(tmp_path / "rec")], capsys)
    assert code == 0, err
    rec = read_recording(tmp_path / "rec" / "panda-ctc")
    assert rec.settings is not None and rec.settings.robot.format == "mjcf"
    assert rec.settings.plant.damping == (0.003,) * 7  # the file's, the scenario gives none
    code, _, err = run_cli_out(
        ["report", "--recordings", str(tmp_path / "rec"), "--out", str(tmp_path / "rep")], capsys
    )
    assert code == 0, err
    text = (tmp_path / "rep" / "report.md").read_text(encoding="utf-8")
    assert "from mjcf" in text and "damping: MJCF <joint damping>" in text


def test_a_motors_ctrlrange_times_gain_and_gear_is_its_effort_limit(tmp_path):
    """<motor gear="100" ctrlrange="-1 1"/> without forcerange: 100 N m (not refused)."""
    text = ONE_HINGE.replace(' actuatorfrcrange="-10 10"', "", 1).replace(
        "</worldbody>",
        '</worldbody><actuator><motor joint="j1" gear="100" ctrlrange="-1 1"/></actuator>',
    )
    (tmp_path / "motor.xml").write_text(text)
    assert load_spec(tmp_path / "motor.xml").effort_limits.tolist() == [100.0, 10.0]


def test_a_urdf_named_dot_xml_is_not_read_as_mjcf(tmp_path):
    """``arm.urdf.xml`` goes to the URDF loader; a URDF named ``arm.xml`` is refused in one
    line (MuJoCo would import it with its own URDF parser, unlike ours)."""
    from tests.robots.test_urdf_loader import THREE_JOINT

    (tmp_path / "arm.urdf.xml").write_text(THREE_JOINT)
    assert load_spec(tmp_path / "arm.urdf.xml").format == "urdf"
    assert "root element <robot>, expected <mujoco>" in _bad(tmp_path, THREE_JOINT, name="arm.xml")


@pytest.mark.parametrize("fact", ["velocity: -1.0", "acceleration: 0", "damping: [-1, 0]"])
def test_a_sidecar_with_a_non_physical_limit_is_one_line(tmp_path, fact):
    (tmp_path / "arm.xml").write_text(ONE_HINGE)
    (tmp_path / "arm.armlab.yaml").write_text(fact + "\n")
    with pytest.raises(SpecError) as err:
        load_spec(tmp_path / "arm.xml")
    assert "\n" not in str(err.value) and "arm.armlab.yaml" in str(err.value)
