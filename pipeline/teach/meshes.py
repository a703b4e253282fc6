"""A URDF robot's visual meshes on the teach page (viser), hung on the link-frame nodes
the server poses by forward kinematics.

Meshes are read with trimesh (STL, OBJ, glTF, and COLLADA through pycollada), their
materials kept, and sent as GLB; each file is read once per process.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh

from pipeline.errors import SpecError
from pipeline.model import transforms as tf
from pipeline.robots import RobotSpec
from pipeline.robots.link_geometry import LinkGeometry, link_geometry

__all__ = ["add_link_meshes", "geometry_node"]

DEFAULT_RGBA = (0.8, 0.8, 0.8, 1.0)


def geometry_node(owner_node: str, g: LinkGeometry, k: int) -> str:
    """Scene name of one geometry element under its owner's link-frame node."""
    return f"{owner_node}/visual_{k}_{g.link}"


@functools.lru_cache(maxsize=64)
def _mesh_glb(path: str, scale: tuple[float, ...]) -> bytes:
    try:
        scene: Any = trimesh.load(path, force="scene")
    except Exception as err:  # trimesh raises what its readers raise
        raise SpecError(f"{path}: cannot read the mesh ({err})") from err
    if scale != (1.0, 1.0, 1.0):
        scene.apply_transform(np.diag([*scale, 1.0]))
    data = scene.export(file_type="glb")
    return bytes(data)


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
    """Add a URDF robot's visual geometry to ``scene`` (a viser ``SceneApi``) under the
    link-frame nodes ``node(i)`` (``i`` = 0 for the base, i + 1 for joint i's link).

    Returns:
        the handles added and why none were ("" when some were, or for a robot that is not
        a URDF): nothing is added for a robot that is not a URDF, has no visual geometry,
        or whose visual meshes cannot be read; the caller draws its capsules then.
    """
    if spec.format != "urdf":
        return [], ""
    try:
        items = link_geometry(spec, "visual")
        blobs = [_mesh_glb(g.mesh, g.size) if g.shape == "mesh" else None for g in items]
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
