"""The teach page draws a URDF robot from its own visual meshes, hung on the link frames
the server poses by FK; a DH robot keeps its capsules."""

from __future__ import annotations

import numpy as np

from pipeline.robots import load_spec
from pipeline.robots.link_geometry import link_geometry
from pipeline.teach.server import link_node
from tests.stages.test_urdf_robot_e2e import pytestmark as needs_panda
from tests.teach.conftest import start_server


@needs_panda
def test_panda_page_holds_a_mesh_node_per_visual_on_its_link_frame() -> None:
    spec = load_spec("panda")
    visuals = link_geometry(spec, "visual")
    # every link with a visual: the base, 7 arm links, the hand and two fingers
    assert {g.link for g in visuals} >= {"panda_link0", "panda_link7", "panda_hand",
                                         "panda_leftfinger"}  # fmt: skip
    assert all(g.mesh.endswith(".dae") for g in visuals)
    server = start_server("panda")
    try:
        assert len(server.meshes) == len(visuals)
        for handle, g in zip(server.meshes, visuals, strict=True):
            assert handle.name.startswith(link_node(g.owner + 1) + "/")
            np.testing.assert_allclose(handle.position, g.owner_T_geometry[:3, 3], atol=1e-6)
        # the hand hangs on the last link frame, where the URDF puts it
        hand = next(g for g in visuals if g.link == "panda_hand")
        assert hand.owner == spec.dof - 1
        capsules = [n for n in _node_names(server) if n.endswith("/geom")]
        assert capsules == []
    finally:
        server.close()


def test_dh_robot_page_keeps_its_capsules(ur5_server) -> None:
    assert ur5_server.meshes == []
    names = _node_names(ur5_server)
    assert {f"{link_node(i)}/geom" for i in range(1, 7)} <= set(names)


def _node_names(server) -> list[str]:
    return list(server._server.scene._handle_from_node_name)


def test_unreadable_visual_mesh_falls_back_to_capsules(tmp_path) -> None:
    import trimesh

    from pipeline.teach.meshes import add_link_meshes
    from tests.report.test_rrd_meshes import URDF

    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(tmp_path / "cube.stl")
    (tmp_path / "cube.dae").write_text("<COLLADA/>")  # not a mesh trimesh can read
    (tmp_path / "two.urdf").write_text(URDF)
    spec = load_spec(tmp_path / "two.urdf")
    added: list[str] = []

    class Scene:
        def add_glb(self, name: str, *_: object, **__: object) -> str:
            added.append(name)
            return name

        add_mesh_trimesh = add_glb

    handles, note = add_link_meshes(Scene(), spec, link_node)
    assert handles == [] and added == []
    assert note.startswith("drawn as capsules:") and "cube.dae" in note
    (tmp_path / "cube.dae").unlink()
    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(tmp_path / "cube.dae")
    spec = load_spec(tmp_path / "two.urdf")
    names, note = add_link_meshes(Scene(), spec, link_node)
    assert note == ""
    assert [n.rsplit("/", 1)[0] for n in names] == [link_node(0), link_node(1), link_node(2)]
