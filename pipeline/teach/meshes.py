"""A URDF robot's visual meshes on the teach page (viser), hung on the link-frame nodes
the server poses by forward kinematics.

Meshes are sent as GLB (:func:`pipeline.robots.mesh_glb.mesh_glb`: STL, OBJ, glTF and
COLLADA, each part in its material's colour); each file is read once per process.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh

from pipeline import transforms as tf
from pipeline.errors import SpecError
from pipeline.robots import RobotSpec
from pipeline.robots.link_geometry import LinkGeometry, has_link_geometry, link_geometry
from pipeline.robots.mesh_glb import mesh_glb

__all__ = ["add_link_meshes", "geometry_node"]

DEFAULT_RGBA = (0.8, 0.8, 0.8, 1.0)


def geometry_node(owner_node: str, g: LinkGeometry, k: int) -> str:
    """Scene name of one geometry element under its owner's link-frame node."""
    return f"{owner_node}/visual_{k}_{g.link}"


def _primitive(g: LinkGeometry) -> Any:
    if g.shape == "box":
        mesh = trimesh.creation.box(extents=g.size)
    elif g.shape == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=g.size[0])
    else:
        mesh = trimesh.creation.cylinder(radius=g.size[0], height=g.size[1], sections=24)
    rgba = np.array(g.rgba or DEFAULT_RGBA)
    mesh.visual.face_colors = (255 * rgba).astype(np.uint8)
    return mesh


def add_link_meshes(
    scene: Any, spec: RobotSpec, node: Callable[[int], str]
) -> tuple[list[Any], str]:
    """Add a robot's visual geometry to ``scene`` (a viser ``SceneApi``) under the
    link-frame nodes ``node(i)`` (``i`` = 0 for the base, i + 1 for joint i's link).

    Returns:
        the handles added and why none were ("" when some were, or for a robot whose
        format describes no link geometry: DH, MJCF): nothing is added for such a robot,
        one with no visual geometry, or one whose visual meshes cannot be read; the
        caller draws its capsules then.
    """
    if not has_link_geometry(spec):
        return [], ""
    try:
        items = link_geometry(spec, "visual")
        blobs = [mesh_glb(g.mesh, g.size) if g.shape == "mesh" else None for g in items]
    except SpecError as err:
        return [], f"drawn as capsules: {err}"
    if not items:
        return [], "drawn as capsules: its URDF has no visual geometry"
    handles = []
    for k, (g, blob) in enumerate(zip(items, blobs, strict=True)):
        name = geometry_node(node(g.owner + 1), g, k)
        pose = g.owner_T_geometry
        where = {"position": pose[:3, 3], "wxyz": tf.quat_wxyz(pose[:3, :3])}
        if blob is not None:
            handles.append(scene.add_glb(name, blob, **where))
        else:
            handles.append(scene.add_mesh_trimesh(name, _primitive(g), **where))
    return handles, ""
