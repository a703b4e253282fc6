"""recording.rrd draws a URDF robot from its meshes (each link's geometry logged once under
a link frame posed by FK each frame): Rerun's own formats as they are, COLLADA converted to
glTF in its own colours, else the collision geometry with the reason; DH robots keep their
capsules."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun as rr

from pipeline.report import entities as ent
from pipeline.report.rrd_meshes import drawn_geometry, link_meshes, send_link_meshes
from pipeline.robots import load_spec
from pipeline.robots.link_geometry import RERUN_MESH_SUFFIXES, link_geometry, rerun_geometry
from pipeline.robots.mesh_glb import GLB_MEDIA_TYPE, mesh_glb
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
    columns: list[str] = []
    capsules: list[Any] = []
    real_send = rr.RecordingStream.send_columns

    def send(self: Any, entity_path: str, *args: Any, **kwargs: Any) -> Any:
        columns.append(entity_path)
        return real_send(self, entity_path, *args, **kwargs)

    monkeypatch.setattr(rr.RecordingStream, "send_columns", send)
    monkeypatch.setattr(rr.Capsules3D, "columns", lambda *a, **k: capsules.append(1))
    out = tmp_path / "rep"
    code, _, err = run_cli_out(["report", "--recordings", str(tmp_path / "rec"), "--out", str(out)],
                               capsys)  # fmt: skip
    assert code == 0, err
    spec = load_spec("panda")
    # read back from the file: one Asset3D per visual mesh, the COLLADA converted to glTF
    assets = _assets(out / "recording.rrd")
    visuals = [g for g in link_geometry(spec, "visual") if g.shape == "mesh"]
    assert sorted(assets) == sorted(
        (ent.arm_link_path("panda-ctc", _carrier(spec, g)), g.link) for g in visuals
    )
    for g in visuals:
        media_type, blob = assets[(ent.arm_link_path("panda-ctc", _carrier(spec, g)), g.link)]
        assert media_type == GLB_MEDIA_TYPE and blob == mesh_glb(g.mesh)
    assert capsules == []
    for joint in spec.joints:  # every link frame posed over time
        assert ent.arm_link_path("panda-ctc", joint.link) in columns
    proc = subprocess.run([str(RERUN), "rrd", "verify", str(out / "recording.rrd")],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr


def _carrier(spec: Any, g: Any) -> str:
    """The link whose frame entity carries ``g`` (the base or a joint's link)."""
    return spec.base_link if g.owner < 0 else spec.joints[g.owner].link


def _assets(rrd: Path) -> dict[tuple[str, str], tuple[str, bytes]]:
    """Every static Asset3D in ``rrd``: (link entity, URDF link) -> (media type, bytes)."""
    from rerun.chunk import RrdReader

    out: dict[tuple[str, str], tuple[str, bytes]] = {}
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        if not chunk.is_static or "Asset3D:blob" not in batch.schema.names:
            continue
        parent, _, leaf = chunk.entity_path.lstrip("/").rpartition("/")
        link = leaf.split("_", 1)[1]  # "<k>_<link>"
        media_type = batch.column("Asset3D:media_type").to_pylist()[-1]
        blob = batch.column("Asset3D:blob").to_pylist()[-1]
        out[(parent, link)] = (media_type[0] if media_type else "", bytes(blob[0]))
    return out


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


def test_a_collada_visual_is_drawn_converted_and_an_unreadable_one_falls_back(
    tmp_path: Path,
) -> None:
    import trimesh

    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(tmp_path / "cube.stl")
    (tmp_path / "cube.dae").write_text("<COLLADA/>")  # not a mesh: the collision cylinder
    (tmp_path / "two.urdf").write_text(URDF)
    spec = load_spec(tmp_path / "two.urdf")
    geometry, note = drawn_geometry(spec)
    assert {g.link: g.shape for g in geometry}["lower"] == "cylinder"
    assert note.startswith("1 link(s) drawn from their collision geometry (lower)")
    assert "cube.dae" in note
    arm = link_meshes(spec, np.zeros((2, 2)))
    assert arm is not None and arm.note == note
    stream = rr.RecordingStream("test-fallback")
    stream.save(tmp_path / "arm.rrd")
    send_link_meshes(stream, "e", np.array([0.0, 0.1]), arm, (10, 20, 30))
    stream.disconnect()
    from rerun.chunk import RrdReader

    texts = [
        str(chunk.to_record_batch().column("TextDocument:text").to_pylist())
        for chunk in RrdReader(tmp_path / "arm.rrd").stream()
        if chunk.entity_path.endswith("/arm/mesh_note")
    ]
    assert len(texts) == 1 and "cube.dae" in texts[0]  # the reason, beside the arm
    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    box.visual.face_colors = (10, 138, 199, 255)
    box.export(tmp_path / "box.dae")  # a real COLLADA file, coloured
    (tmp_path / "two.urdf").write_text(URDF.replace("cube.dae", "box.dae"))
    spec = load_spec(tmp_path / "two.urdf")
    geometry, note = drawn_geometry(spec)
    lower = {g.link: g for g in geometry}["lower"]
    assert note == "" and lower.shape == "mesh" and lower.mesh.endswith("box.dae")
    back = trimesh.load(trimesh.util.wrap_as_stream(mesh_glb(lower.mesh)), file_type="glb",
                        force="mesh")  # fmt: skip
    np.testing.assert_allclose(back.extents, [0.1, 0.2, 0.3], atol=1e-6)
    assert tuple(back.visual.vertex_colors[0]) == (10, 138, 199, 255)  # its own colour
