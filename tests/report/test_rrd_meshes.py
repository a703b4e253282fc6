"""recording.rrd draws a URDF robot from its meshes (each link's geometry logged once under
a link frame posed by FK each frame), Rerun's own formats or else the collision geometry;
DH robots keep their capsules."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun as rr

from pipeline.report import entities as ent
from pipeline.report.rrd_meshes import link_meshes
from pipeline.robots import load_spec
from pipeline.robots.link_geometry import RERUN_MESH_SUFFIXES, link_geometry, rerun_geometry
from tests.stages.test_urdf_robot_e2e import PARAMS
from tests.stages.test_urdf_robot_e2e import pytestmark as needs_panda
from tests.test_bad_input import run_cli, run_cli_out

RERUN = Path(sys.executable).with_name("rerun")


@needs_panda
def test_panda_draws_collision_meshes_where_its_visuals_are_collada() -> None:
    spec = load_spec("panda")
    assert all(g.mesh.endswith(".dae") for g in link_geometry(spec, "visual"))
    drawn = rerun_geometry(spec)
    meshes = [g for g in drawn if g.shape == "mesh"]
    assert {g.link for g in meshes} >= {f"panda_link{i}" for i in range(8)} | {"panda_hand"}
    assert all(Path(g.mesh).suffix in RERUN_MESH_SUFFIXES for g in meshes)
    assert {g.link for g in drawn if g.shape == "box"} == {"panda_leftfinger", "panda_rightfinger"}


def test_dh_robot_has_no_mesh_arm() -> None:
    assert link_meshes(load_spec("ur5"), np.zeros((2, 6))) is None


@needs_panda
@pytest.mark.slow
def test_panda_rrd_holds_a_mesh_per_link_posed_by_fk(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(PARAMS)
    code, err = run_cli(["record", "--params", str(params), "--out", str(tmp_path / "rec")], capsys)
    assert code == 0, err
    assets: list[str] = []
    columns: list[str] = []
    capsules: list[Any] = []
    real_asset, real_send = rr.Asset3D, rr.RecordingStream.send_columns

    def asset(*args: Any, path: Any = None, **kwargs: Any) -> Any:
        assets.append(str(path))
        return real_asset(*args, path=path, **kwargs)

    def send(self: Any, entity_path: str, *args: Any, **kwargs: Any) -> Any:
        columns.append(entity_path)
        return real_send(self, entity_path, *args, **kwargs)

    monkeypatch.setattr(rr, "Asset3D", asset)
    monkeypatch.setattr(rr.RecordingStream, "send_columns", send)
    monkeypatch.setattr(rr.Capsules3D, "columns", lambda *a, **k: capsules.append(1))
    out = tmp_path / "rep"
    code, _, err = run_cli_out(["report", "--recordings", str(tmp_path / "rec"), "--out", str(out)],
                               capsys)  # fmt: skip
    assert code == 0, err
    spec = load_spec("panda")
    drawn = [g for g in rerun_geometry(spec) if g.shape == "mesh"]
    assert sorted(assets) == sorted(g.mesh for g in drawn)  # each mesh once
    assert capsules == []
    for joint in spec.joints:  # every link frame posed over time
        assert ent.arm_link_path("panda-ctc", joint.link) in columns
    proc = subprocess.run([str(RERUN), "rrd", "verify", str(out / "recording.rrd")],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr


URDF = """<robot name="two">
  <link name="base">
    <visual><origin xyz="0 0 0.05"/><geometry><box size="0.2 0.2 0.1"/></geometry>
      <material name="grey"><color rgba="0.5 0.5 0.5 1"/></material></visual>
  </link>
  <link name="upper">
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>
    </inertial>
    <visual><geometry><mesh filename="cube.stl" scale="2 2 2"/></geometry></visual>
  </link>
  <link name="lower">
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>
    </inertial>
    <visual><geometry><mesh filename="cube.dae"/></geometry></visual>
    <collision><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.03" length="0.2"/></geometry>
    </collision>
  </link>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="1" effort="10"/></joint>
  <joint name="j2" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" velocity="1" effort="10"/></joint>
  <joint name="fix" type="fixed"><parent link="lower"/><child link="tip"/>
    <origin xyz="0 0 0.2"/></joint>
</robot>
"""


def test_each_link_draws_its_visuals_where_rerun_reads_them_else_its_collision(
    tmp_path: Path,
) -> None:
    import trimesh

    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(tmp_path / "cube.stl")
    (tmp_path / "cube.dae").write_text("<COLLADA/>")  # never read: Rerun cannot load it
    (tmp_path / "two.urdf").write_text(URDF)
    spec = load_spec(tmp_path / "two.urdf")
    by_link = {g.link: g for g in rerun_geometry(spec)}
    assert set(by_link) == {"base", "upper", "lower"}
    base, upper, lower = by_link["base"], by_link["upper"], by_link["lower"]
    assert (base.owner, base.shape, base.size, base.rgba) == (-1, "box", (0.2, 0.2, 0.1),
                                                              (0.5, 0.5, 0.5, 1.0))  # fmt: skip
    assert (upper.owner, upper.shape, upper.size) == (0, "mesh", (2.0, 2.0, 2.0))
    assert upper.mesh == str((tmp_path / "cube.stl").resolve())
    assert (lower.owner, lower.shape, lower.size) == (1, "cylinder", (0.03, 0.2))  # collision
    np.testing.assert_allclose(lower.owner_T_geometry[:3, 3], [0.0, 0.0, 0.1])
    arm = link_meshes(spec, np.array([[0.0, 0.0], [0.5, -0.3]]))
    assert arm is not None and arm.links == ("base", "upper", "lower")
    assert arm.base_T_link.shape == (2, 2, 4, 4)
