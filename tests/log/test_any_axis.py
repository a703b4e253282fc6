"""Joints about any axis, and prismatic joints, in every frame computation: the bag's /tf,
the report's TCP, ``fk``, against an independent URDF forward kinematics (yourdfpy).

The /tf check reads the bag with ``rosbags`` (an independent reader) and recomputes every
published transform from the /joint_states positions of the same stamp.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yourdfpy
from numpy.typing import NDArray
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from pipeline import transforms as tf
from pipeline.analysis.task_space import TaskSpace
from pipeline.constants import TOPIC_JOINT_STATES, TOPIC_TF
from pipeline.log.bag import tf_poses
from pipeline.model.dh import forward_kinematics, link_frames
from pipeline.model.frames import tf_edges
from pipeline.robots import RobotSpec, load_spec
from pipeline.robots.chain import FLANGE, joint_motion, joint_motions, then_joint_motions
from pipeline.robots.packages import package_search_path
from pipeline.robots.spec import JointKind, JointLimits, JointSpec
from tests.test_bad_input import run_cli, run_cli_out

TOL_M = 1e-9
# (a, b, c) normalised: an axis no coordinate plane holds
SKEW = tuple(v / math.sqrt(14.0) for v in (1.0, 2.0, -3.0))

_INERTIAL = (
    '<inertial><origin xyz="{com}"/><mass value="{mass}"/>'
    '<inertia ixx="{i}" iyy="{i}" izz="{i}" ixy="0" ixz="0" iyz="0"/></inertial>'
)
# joint name, type, axis, origin xyz, origin rpy, lower, upper, effort; child mass, com
JOINTS = (
    ("j1", "revolute", (0.0, 0.0, -1.0), "0 0 0.1", "0 0 0", -3.0, 3.0, 150.0, 3.0, "0 0 0.05"),
    ("j2", "revolute", (0.0, 1.0, 0.0), "0 0 0.15", "0.1 0 0", -2.0, 2.0, 150.0, 2.5, "0.1 0 0"),
    ("j3", "revolute", (0.0, -1.0, 0.0), "0.25 0 0", "0 0 0.2", -2.5, 2.5, 100.0, 2.0, "0.1 0 0"),
    ("j4", "revolute", (1.0, 0.0, 0.0), "0.2 0 0", "0 0.3 0", -3.0, 3.0, 50.0, 1.0, "0.1 0 0"),
    (
        "j5",
        "revolute",
        (-1.0, 0.0, 0.0),
        "0.2 0.05 0",
        "0 0.2 0.3",
        -3.0,
        3.0,
        50.0,
        0.8,
        "0.1 0 0",
    ),
    ("j6", "continuous", SKEW, "0.2 0 0", "0.4 -0.2 0.1", -3.0, 3.0, 30.0, 0.6, "0.1 0 0"),
    ("j7", "prismatic", (0.0, 0.6, 0.8), "0.2 0 0", "0 0 0", -0.05, 0.08, 200.0, 0.4, "0 0 0"),
)


def any_axis_urdf() -> str:
    """A 7-joint arm with joints about -z, +y, -y, +x, -x, a skew unit axis, and one
    prismatic joint; inertials and limits on every joint, a tool0 with a turned origin."""
    links = ['<link name="base_link"/>', '<link name="tool0"/>']
    joints = []
    parent = "base_link"
    for k, (name, kind, axis, xyz, rpy, lo, hi, effort, mass, com) in enumerate(JOINTS, 1):
        child = f"link{k}"
        inertial = _INERTIAL.format(com=com, mass=mass, i=0.01 * mass)
        links.append(f'<link name="{child}">{inertial}</link>')
        ax = " ".join(repr(v) for v in axis)
        velocity = 0.5 if kind == "prismatic" else 2.0
        joints.append(
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{ax}"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="{effort}" velocity="{velocity}"/></joint>'
        )
        parent = child
    joints.append(
        f'<joint name="tool_joint" type="fixed"><parent link="{parent}"/><child link="tool0"/>'
        '<origin xyz="0.03 -0.02 0.04" rpy="0.3 -0.5 1.1"/></joint>'
    )
    return (
        '<?xml version="1.0"?>\n<robot name="anyaxis">\n  '
        + "\n  ".join(links + joints)
        + "\n</robot>\n"
    )


def ur_urdfs() -> list[Path]:
    """example-robot-data's UR5, UR10, UR3 URDFs (those installed)."""
    for share in package_search_path():
        folder = share / "example-robot-data" / "robots" / "ur_description" / "urdf"
        if folder.is_dir():
            names = ("ur5_robot.urdf", "ur10_robot.urdf", "ur3_robot.urdf")
            return [folder / n for n in names if (folder / n).is_file()]
    return []


UR_URDFS = ur_urdfs()
needs_ur = pytest.mark.skipif(not UR_URDFS, reason="example-robot-data's UR URDFs not found")


def reference(path: Path) -> yourdfpy.URDF:
    """The URDF as yourdfpy reads it (no meshes: kinematics only)."""
    return yourdfpy.URDF.load(
        str(path), load_meshes=False, build_collision_scene_graph=False,
        load_collision_meshes=False,
    )  # fmt: skip


def reference_pose(urdf: yourdfpy.URDF, spec: RobotSpec, q: NDArray[np.float64], frame: str,
                   relative_to: str) -> NDArray[np.float64]:  # fmt: skip
    """``relative_to_T_frame`` at ``q``, by yourdfpy."""
    cfg = dict(zip(spec.joint_names, (float(v) for v in q), strict=True))
    if cfg != getattr(urdf, "_armlab_cfg", None):
        # trimesh's scene graph keeps an edge whose new matrix is within 1e-8 of the old one
        # (EnforcedForest.add_edge): move every joint far away first, so each call recomputes
        urdf.update_cfg({name: value + 1.0 for name, value in cfg.items()})
        urdf.update_cfg(cfg)
        urdf._armlab_cfg = cfg  # type: ignore[attr-defined]
    return np.asarray(urdf.get_transform(frame_to=frame, frame_from=relative_to), dtype=float)


def random_configurations(spec: RobotSpec, n: int, seed: int) -> NDArray[np.float64]:
    rng = np.random.default_rng(seed)
    lower = np.array([max(j.limits.lower, -math.pi) for j in spec.joints])
    upper = np.array([min(j.limits.upper, math.pi) for j in spec.joints])
    return rng.uniform(lower, upper, size=(n, spec.dof))


def assert_same_pose(a: NDArray[np.float64], b: NDArray[np.float64], what: str) -> None:
    """Positions within 1e-9 m, rotations within ~1e-9 rad (largest entry of R_a - R_b: the
    angle's arccos form cannot resolve angles below ~2e-8 rad)."""
    dp = float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
    dr = float(np.abs(a[:3, :3] - b[:3, :3]).max())
    assert dp < TOL_M and dr < 1e-9, f"{what}: {dp:.3g} m, rotation entries {dr:.3g} apart"


@pytest.fixture(scope="module")
def any_axis_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("anyaxis") / "anyaxis.urdf"
    path.write_text(any_axis_urdf(), encoding="utf-8")
    return path


def test_the_test_robot_has_every_kind_of_axis(any_axis_path: Path) -> None:
    spec = load_spec(any_axis_path)
    assert [(j.kind, j.axis) for j in spec.joints] == [(j[1], j[2]) for j in JOINTS]


def _joint(name: str, kind: JointKind, axis: tuple[float, float, float]) -> JointSpec:
    limits = JointLimits(lower=-3.0, upper=3.0, velocity=1.0, acceleration=1.0, effort=1.0)
    return JointSpec(name, limits, None, 0.05, axis=axis, kind=kind)


@pytest.mark.parametrize(
    "joint",
    [
        _joint("z", "revolute", (0.0, 0.0, 1.0)),
        _joint("mx", "revolute", (-1.0, 0.0, 0.0)),
        _joint("skew", "continuous", SKEW),
        _joint("p", "prismatic", (0.0, 0.6, 0.8)),
    ],
    ids=lambda j: j.name,
)
def test_batched_joint_motions_equal_the_scalar_motion(joint: JointSpec) -> None:
    q = np.linspace(-2.5, 2.5, 11)
    fixed = tf.trans(0.1, -0.2, 0.3) @ tf.rot_axis(np.array(SKEW), 0.7)
    rot, shift = joint_motions(joint, q)
    translation, quat = then_joint_motions(fixed, joint, q)
    for k, qk in enumerate(q):
        scalar = joint_motion(joint, float(qk))
        np.testing.assert_allclose(rot[k], scalar[:3, :3], atol=1e-15)
        np.testing.assert_allclose(shift[k], scalar[:3, 3], atol=1e-15)
        composed = fixed @ scalar
        np.testing.assert_allclose(translation[k], composed[:3, 3], atol=1e-15)
        np.testing.assert_allclose(tf.quat_to_matrix(quat[k]), composed[:3, :3], atol=1e-14)
    # a revolute joint turns about its axis: the axis stays put
    if joint.kind != "prismatic":
        np.testing.assert_allclose(rot @ np.array(joint.axis), np.tile(joint.axis, (11, 1)))


def test_tf_poses_equal_the_tree_transforms_for_every_axis(any_axis_path: Path) -> None:
    spec = load_spec(any_axis_path)
    q = random_configurations(spec, 20, seed=1)
    frames, translation, quat_xyzw = tf_poses(spec, q)
    for m in range(q.shape[0]):
        edges = tf_edges(spec, q[m])
        assert frames == [(e.parent, e.child) for e in edges]
        for e, edge in enumerate(edges):
            np.testing.assert_allclose(translation[m, e], edge.parent_T_child[:3, 3], atol=1e-15)
            rot = tf.quat_to_matrix(quat_xyzw[m, e, [3, 0, 1, 2]])
            np.testing.assert_allclose(rot, edge.parent_T_child[:3, :3], atol=1e-14)
    assert np.all(quat_xyzw[..., 3] >= 0)


@pytest.mark.parametrize("which", ["anyaxis", *(p.stem for p in UR_URDFS)])
def test_fk_tf_and_tcp_agree_with_yourdfpy(which: str, any_axis_path: Path) -> None:
    path = any_axis_path if which == "anyaxis" else next(p for p in UR_URDFS if p.stem == which)
    spec = load_spec(path)
    urdf = reference(path)
    q = random_configurations(spec, 25, seed=7)
    tcp = TaskSpace(spec).tcp_poses(q)
    _, translation, quat_xyzw = tf_poses(spec, q)
    for m in range(q.shape[0]):
        flange = reference_pose(urdf, spec, q[m], FLANGE, spec.base_link)
        assert_same_pose(forward_kinematics(spec, q[m]), flange, f"{which} fk at {q[m]}")
        assert_same_pose(tcp[m], flange, f"{which} TCP at {q[m]}")
        for joint, frame in zip(spec.joints, link_frames(spec, q[m]), strict=True):
            link = reference_pose(urdf, spec, q[m], joint.link_name, spec.base_link)
            assert_same_pose(frame, link, f"{which} link {joint.link_name}")
        for e, edge in enumerate(tf_edges(spec, q[m])):
            published = np.eye(4)
            published[:3, :3] = tf.quat_to_matrix(quat_xyzw[m, e, [3, 0, 1, 2]])
            published[:3, 3] = translation[m, e]
            expected = reference_pose(urdf, spec, q[m], edge.child, edge.parent)
            assert_same_pose(published, expected, f"{which} /tf {edge.parent}->{edge.child}")


def _params(robot: Path, start: list[float], goal: list[float]) -> str:
    return f"""\
sim: {{physics_dt_s: 0.0005, control_period_steps: 2, integrator: RK4, joint_state_decimation: 1,
      tf_rate_hz: 100.0, ros_distro: jazzy}}
scenarios:
  s:
    robot: {robot}
    start: {start}
    goal: {{joints: {goal}}}
    planner: {{time_limit_s: 5.0, simplify: true, seed: 0}}
    plant: {{}}
    preroll_s: 0.05
    hold_s: 0.1
controllers:
  ctc: {{type: ctc, gains: {{kp: 1600.0, kd: 80.0}}}}
episodes:
  e-ctc: {{scenario: s, controller: ctc, seed: 0}}
"""


def _record_and_report(tmp_path: Path, capsys: pytest.CaptureFixture[str], robot: Path,
                       start: list[float], goal: list[float]) -> Path:  # fmt: skip
    """Record one episode of ``robot`` and report it; the bag's folder."""
    params = tmp_path / "params.yaml"
    params.write_text(_params(robot, start, goal), encoding="utf-8")
    code, err = run_cli(["record", "--params", str(params), "--out", str(tmp_path / "rec")], capsys)
    assert code == 0, err
    code, _, err = run_cli_out(
        ["report", "--recordings", str(tmp_path / "rec"), "--out", str(tmp_path / "rep")], capsys
    )
    assert code == 0, err
    text = (tmp_path / "rep" / "report.md").read_text(encoding="utf-8")
    assert "| TCP max position error [mm] |" in text, "the report has no task-space metrics"
    return tmp_path / "rec" / "e-ctc"


def assert_bag_tf_matches_yourdfpy(bag: Path, robot: Path) -> None:
    """Every /tf transform of the bag, read by rosbags, equals yourdfpy's FK of the
    /joint_states positions at its stamp; so does the TCP the report computes."""
    spec = load_spec(robot)
    urdf = reference(robot)
    positions: dict[int, NDArray[np.float64]] = {}
    transforms: list[tuple[int, list[tuple[str, str, NDArray[np.float64]]]]] = []
    with AnyReader([bag], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.topic == TOPIC_JOINT_STATES:
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                assert tuple(msg.name) == spec.joint_names
                positions[stamp] = np.asarray(msg.position, dtype=float)
            elif connection.topic == TOPIC_TF:
                edges = []
                for t in msg.transforms:
                    pose = np.eye(4)
                    r, p = t.transform.rotation, t.transform.translation
                    pose[:3, :3] = tf.quat_to_matrix(np.array([r.w, r.x, r.y, r.z]))
                    pose[:3, 3] = (p.x, p.y, p.z)
                    edges.append((t.header.frame_id, t.child_frame_id, pose))
                st = msg.transforms[0].header.stamp
                transforms.append((st.sec * 1_000_000_000 + st.nanosec, edges))
    assert len(transforms) > 10
    children = {child for _, edges in transforms for _, child, _ in edges}
    assert children == {*(j.link_name for j in spec.joints), FLANGE}
    qs = np.array([positions[stamp] for stamp, _ in transforms])
    tcp = TaskSpace(spec).tcp_poses(qs)
    for (stamp, edges), q, tcp_pose in zip(transforms, qs, tcp, strict=True):
        for parent, child, pose in edges:
            expected = reference_pose(urdf, spec, q, child, parent)
            assert_same_pose(pose, expected, f"/tf {parent}->{child} at {stamp} ns")
        flange = reference_pose(urdf, spec, q, FLANGE, spec.base_link)
        assert_same_pose(tcp_pose, flange, f"TCP at {stamp} ns")


@pytest.mark.slow
def test_a_robot_with_every_axis_records_and_reports_with_true_frames(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], any_axis_path: Path
) -> None:
    start = [0.0, -0.6, -0.3, 0.2, 0.1, 0.0, 0.0]
    goal = [0.4, -0.4, -0.1, -0.3, 0.4, 0.6, 0.05]
    bag = _record_and_report(tmp_path, capsys, any_axis_path, start, goal)
    assert_bag_tf_matches_yourdfpy(bag, any_axis_path)
    # the report's labels say rad for every joint: the prismatic one is named as in m
    text = (tmp_path / "rep" / "report.md").read_text(encoding="utf-8")
    assert "**e-ctc**: j7: prismatic: its position, errors and effort are in m" in text


@needs_ur
@pytest.mark.slow
def test_ur5_robot_urdf_records_and_reports_with_true_frames(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ur5 = next(p for p in UR_URDFS if p.name == "ur5_robot.urdf")
    start = [0.0, -1.2, 1.0, -1.0, -1.57, 0.0]
    goal = [0.3, -1.0, 0.8, -1.1, -1.5, 0.2]
    bag = _record_and_report(tmp_path, capsys, ur5, start, goal)
    assert_bag_tf_matches_yourdfpy(bag, ur5)


def test_an_episode_failing_inside_bag_writing_at_j1_fails_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], any_axis_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """The bug this file guards against, put back for one robot (fault injection: /tf
    refuses any joint not about +z, as it did): at ``-j 1`` that episode fails with a
    one-line reason, and the run's next episode still runs and keeps its bag."""
    from pipeline.log import topics as topics_module
    from pipeline.log.reader import read_recording

    real = topics_module.tf_poses

    def z_only(spec: RobotSpec, q: NDArray[np.float64]) -> object:
        if any(j.axis != (0.0, 0.0, 1.0) for j in spec.joints):
            raise AssertionError("tf_edges is no longer constant @ Rz(q_i); update tf_poses")
        return real(spec, q)

    monkeypatch.setattr(topics_module, "tf_poses", z_only)
    params = tmp_path / "params.yaml"
    params.write_text(
        f"""\
sim: {{physics_dt_s: 0.001, control_period_steps: 2, integrator: RK4}}
scenarios:
  any: {{robot: {any_axis_path}, start: [0.0, -0.6, -0.3, 0.2, 0.1, 0.0, 0.0],
        goal: {{joints: [0.1, -0.5, -0.3, 0.2, 0.1, 0.0, 0.0]}}, plant: {{}}, hold_s: 0.05}}
  ur5: {{robot: ur5, start: [0.0, -1.2, 1.0, -1.0, -1.57, 0.0],
        goal: {{joints: [0.1, -1.1, 1.0, -1.0, -1.57, 0.0]}}, plant: {{}}, hold_s: 0.05}}
controllers:
  ctc: {{type: ctc}}
episodes:
  a-any: {{scenario: any, controller: ctc, seed: 0}}
  b-ur5: {{scenario: ur5, controller: ctc, seed: 0}}
""",
        encoding="utf-8",
    )
    out = tmp_path / "rec"
    code, err = run_cli(["record", "--params", str(params), "--out", str(out), "-j", "1"], capsys)
    assert code == 1, err
    # (the test robot states no armature nor acceleration limits: warned about first)
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("warning:")]
    assert len(lines) == 1 and "a-any" in lines[0] and "internal error" in lines[0], err
    assert "AssertionError" in lines[0] and "Traceback" not in err
    assert not (out / "a-any").exists()
    assert read_recording(out / "b-ur5").joint_names == load_spec("ur5").joint_names
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["b-ur5"]


def test_the_fk_command_agrees_with_yourdfpy_for_every_axis(
    any_axis_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = load_spec(any_axis_path)
    q = random_configurations(spec, 1, seed=3)[0]
    code, out, err = run_cli_out(
        ["fk", str(any_axis_path), *(repr(float(v)) for v in q), "--json"], capsys
    )
    assert code == 0, err
    answer = json.loads(out)
    pose = np.eye(4)
    pose[:3, :3] = tf.quat_to_matrix(np.array(answer["quaternion_wxyz"]))
    pose[:3, 3] = answer["position"]
    expected = reference_pose(reference(any_axis_path), spec, q, FLANGE, spec.base_link)
    assert_same_pose(pose, expected, "pipeline fk")
