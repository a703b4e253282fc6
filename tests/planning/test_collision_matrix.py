"""Any URDF plans: a joint's parent and child are never a collision pair (with or without an
SRDF), and ``pipeline robots collision-matrix`` computes disabled pairs as MoveIt's Setup
Assistant does, cross-checked against Pinocchio's collision query (FCL on the real meshes)."""

from __future__ import annotations

from pathlib import Path
from xml.etree import ElementTree

import mujoco
import numpy as np
import pytest

from pipeline.errors import PlanningError, SpecError
from pipeline.model.mjcf import build_mujoco_model
from pipeline.planning import plan_path
from pipeline.planning.collision import CollisionChecker
from pipeline.planning.collision_matrix import (
    collision_matrix,
    default_configuration,
    sample_configurations,
    write_srdf,
)
from pipeline.robots import load_spec
from pipeline.robots.urdf_loader import load_urdf
from tests.robots.panda_files import ERD, copy_panda_urdf, needs_erd

PANDA_SRDF = "robots/panda_description/srdf/panda.srdf"
START = np.array([0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398])  # the SRDF's default
GOAL = np.array([1.3, -0.5, 0.0, -2.0, 0.0, 1.5, 0.785398])


def _panda_without_srdf(folder: Path) -> Path:
    """example-robot-data's Panda URDF copied out (package:// meshes still resolve), with a
    sidecar that locks the fingers and names no SRDF."""
    return copy_panda_urdf(folder)


def _srdf_pairs(path: Path) -> dict[tuple[str, str], str]:
    root = ElementTree.parse(path).getroot()
    return {
        tuple(sorted((el.get("link1") or "", el.get("link2") or ""))): el.get("reason") or ""
        for el in root.iter("disable_collisions")
    }  # type: ignore[misc]


@needs_erd
def test_a_panda_urdf_without_its_srdf_plans(tmp_path):
    spec = load_spec(str(_panda_without_srdf(tmp_path)))
    assert spec.disabled_pairs is None and "no SRDF" in spec.collision_pairs_source
    assert ("panda_link0", "panda_link1") in spec.adjacent_pairs
    plan = plan_path(spec, start=START, goal=GOAL, seed=1)
    assert plan.waypoints.shape[1] == 7
    # the plant excludes the base and the first link too (MuJoCo's own parent filter skips
    # a body welded to the world)
    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    data.qpos[:] = START
    mujoco.mj_forward(model, data)
    base = model.body("panda_link0").id
    for c in data.contact[: data.ncon]:
        bodies = {int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])}
        assert base not in bodies or model.body("panda_link1").id not in bodies


def _box_link(name: str, z: float, half: float = 0.05, x: float = 0.0) -> str:
    return (
        f'<link name="{name}"><collision><origin xyz="{x} 0 {z}"/><geometry>'
        f'<box size="{2 * half} {2 * half} {2 * half}"/></geometry></collision>'
        '<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" '
        'ixz="0" iyz="0"/></inertial></link>'
    )


def _revolute(name: str, parent: str, child: str, z: float) -> str:
    return (
        f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="0 0 {z}"/><axis xyz="0 0 1"/>'
        '<limit lower="-3" upper="3" velocity="1" effort="10"/></joint>'
    )


def _plate_robot(tmp_path: Path, *, link2_z: float, x: float = 0.0) -> Path:
    """base -(fixed)- plate -(revolute)- link1 -(revolute)- link2, each link a box touching
    the next: the plate merges into the base body, and link1 is its joint's child."""
    urdf = tmp_path / "plate.urdf"
    urdf.write_text(
        '<robot name="plate">'
        + _box_link("base", 0.05, x=x)
        + _box_link("plate", 0.0, half=0.06)
        + _box_link("link1", 0.05)
        + _box_link("link2", link2_z, x=x)
        + '<joint name="mount" type="fixed"><parent link="base"/><child link="plate"/>'
        '<origin xyz="0 0 0.15"/></joint>'
        + _revolute("j1", "plate", "link1", 0.06)
        + _revolute("j2", "link1", "link2", 0.1)
        + "</robot>"
    )
    return urdf


def test_a_link_merged_through_a_fixed_joint_is_its_body_for_adjacency(tmp_path):
    spec = load_spec(str(_plate_robot(tmp_path, link2_z=0.2)))
    assert spec.base_link == "base" and spec.adjacent_pairs == (
        ("base", "link1"), ("link1", "link2"))  # fmt: skip
    checker = CollisionChecker(spec)
    q = np.zeros(2)
    assert checker.contacts(q) == []  # the plate (base body) overlaps link1: its joint's child
    plan = plan_path(spec, start=q, goal=np.array([1.0, -1.0]), seed=0)
    assert plan.waypoints.shape[1] == 2


def test_a_clearance_error_names_the_pair_and_says_no_srdf_was_used(tmp_path):
    # link2 hangs back down onto the base: a pair no joint joins
    spec = load_spec(str(_plate_robot(tmp_path, link2_z=-0.2)))
    checker = CollisionChecker(spec)
    with pytest.raises(PlanningError) as err:
        checker.check_state(np.zeros(2), "start")
    message = str(err.value)
    assert "base touches link2" in message and "no SRDF" in message
    assert "\n" not in message


def test_a_start_too_near_names_the_pair_and_says_no_srdf_was_used(tmp_path):
    # beside the stack, link2's box ends 1 mm above the base's (link2's frame is 0.31 m up)
    spec = load_spec(str(_plate_robot(tmp_path, link2_z=-0.159, x=0.2)))
    q = np.zeros(2)
    assert CollisionChecker(spec).contacts(q) == []
    with pytest.raises(PlanningError) as err:
        plan_path(spec, start=q, goal=np.array([0.0, 1.0]), seed=0)
    assert str(err.value) == (
        "start: base is 1.00 mm from link2; expected at least 2 mm clearance for planning "
        "(the pair base-link2 is checked; no SRDF: adjacent links and links touching at "
        "q = 0 are not checked; `pipeline robots collision-matrix` writes an SRDF)"
    )


@needs_erd
def test_a_clearance_error_names_the_srdf_it_used(tmp_path):
    spec = load_spec("panda")
    checker = CollisionChecker(spec)
    q = np.array([-0.8, 0.19, 2.47, -3.07, -1.96, 2.7, -0.61])  # the elbow folded shut
    assert checker.contacts(q) == [("panda_link2", "panda_link5")]
    with pytest.raises(PlanningError, match=r"is not disabled by SRDF .*panda\.srdf"):
        checker.check_state(q, "goal")


@pytest.fixture(scope="module")
def panda_matrix(tmp_path_factory):
    spec = load_spec(str(_panda_without_srdf(tmp_path_factory.mktemp("panda"))))
    return spec, collision_matrix(spec, samples=10_000, seed=3)


@needs_erd
def test_the_matrix_disables_every_pair_the_shipped_srdf_marks_adjacent(panda_matrix):
    assert ERD is not None
    _, matrix = panda_matrix
    shipped = _srdf_pairs(ERD / PANDA_SRDF)
    adjacent = {pair for pair, reason in shipped.items() if reason == "Adjacent"}
    assert len(adjacent) == 10
    mine = {(p.link1, p.link2): p.reason for p in matrix.disabled}
    assert {pair: mine.get(pair) for pair in adjacent} == dict.fromkeys(adjacent, "Adjacent")
    # and it agrees with MoveIt's own on the rest of the Panda's pairs but a few
    agree = sum(mine.get(pair) == reason for pair, reason in shipped.items())
    assert agree >= 0.8 * len(shipped)


def _fcl_collisions(spec, configurations, pairs):
    """The link ``pairs`` colliding in any of the configurations, from Pinocchio + FCL on
    the URDF's real collision meshes (nothing disabled): independent of MuJoCo."""
    import pinocchio as pin

    assert ERD is not None
    model, geoms = pin.buildModelsFromUrdf(
        spec.source, package_dirs=[str(ERD.parent)], geometry_types=pin.GeometryType.COLLISION
    )  # type: ignore[misc]
    link_of = [model.frames[g.parentFrame].name for g in geoms.geometryObjects]
    for i in range(len(link_of)):
        for j in range(i + 1, len(link_of)):
            if (min(link_of[i], link_of[j]), max(link_of[i], link_of[j])) in pairs:
                geoms.addCollisionPair(pin.CollisionPair(i, j))
    data, gdata = model.createData(), pin.GeometryData(geoms)
    arm = [model.getJointId(name) for name in spec.joint_names]
    found = set()
    for q_arm in configurations:
        q = pin.neutral(model)  # the fingers at 0, as the sidecar locks them
        for jid, v in zip(arm, q_arm, strict=True):
            q[model.joints[jid].idx_q] = v
        pin.computeCollisions(model, data, geoms, gdata, q, False)
        for k, result in enumerate(gdata.collisionResults):
            if result.isCollision():
                pair = geoms.collisionPairs[k]
                a, b = link_of[pair.first], link_of[pair.second]
                if a != b:
                    found.add((min(a, b), max(a, b)))
    return found


@needs_erd
def test_the_matrix_disables_no_pair_seen_in_collision(panda_matrix, tmp_path):
    spec, matrix = panda_matrix
    never = {(p.link1, p.link2) for p in matrix.disabled if p.reason == "Never"}
    assert len(never) >= 15
    counts = dict(matrix.collision_counts)
    assert all(counts[pair] == 0 for pair in never)
    # an independent query on the matrix's own samples and on fresh ones
    own = sample_configurations(spec, 10_000, 3)[:150]
    fresh = sample_configurations(spec, 250, 12345)
    seen = _fcl_collisions(spec, np.vstack([own, fresh]), never | set(matrix.checked))
    assert seen, "the samples must hit some self-collisions"
    assert not seen & never
    assert seen & set(matrix.checked)  # the pairs MuJoCo saw colliding stay checked
    # the SRDF written beside the URDF drives the planner, and the default pose is clear
    write_srdf(matrix, Path(spec.source).with_suffix(".srdf"))
    again = load_urdf(Path(spec.source))  # load_spec caches by the URDF's bytes alone
    assert again.collision_pairs_source.startswith("SRDF ")
    assert CollisionChecker(again).is_valid(default_configuration(again))


def test_write_srdf_refuses_an_existing_file_without_force(tmp_path):
    from pipeline.errors import PipelineError
    from pipeline.planning.collision_matrix import CollisionMatrix

    matrix = CollisionMatrix("r", (), (), (), 1, 0, ())
    out = tmp_path / "r.srdf"
    out.write_text("keep")
    with pytest.raises(PipelineError, match="exists; pass --force"):
        write_srdf(matrix, out)
    assert out.read_text() == "keep"
    write_srdf(matrix, out, force=True)
    assert '<robot name="r">' in out.read_text()
    assert [p.name for p in tmp_path.iterdir()] == ["r.srdf"]  # no temp file left


def test_a_robot_without_collision_geometry_has_no_matrix():
    with pytest.raises(SpecError, match="no collision geometry"):
        collision_matrix(load_spec("ur5"), samples=10)


@needs_erd
def test_the_command_writes_an_srdf_the_loader_reads(tmp_path):
    import json

    from typer.testing import CliRunner

    from pipeline.cli import app

    urdf = _panda_without_srdf(tmp_path)
    out = tmp_path / "panda.srdf"
    argv = ["robots", "collision-matrix", str(urdf), "--out", str(out), "--samples", "300"]
    result = CliRunner().invoke(app, [*argv, "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["disabled"]["Adjacent"] == 10 and summary["samples"] == 300
    assert set(_srdf_pairs(out).values()) <= {"Adjacent", "Default", "Always", "Never"}
    assert load_urdf(urdf).collision_pairs_source == f"SRDF {out}"
    again = CliRunner().invoke(app, argv)
    assert again.exit_code != 0 and "pass --force" in str(again.exception)
