"""A mesh file as GLB bytes for the viewers: ``teach`` (viser) and the ``.rrd`` (Rerun,
whose ``Asset3D`` reads STL, OBJ and glTF but not the COLLADA many URDFs use, the Panda's
among them).

trimesh reads the file (COLLADA through pycollada); each part keeps its material's colour
as a flat colour, texture coordinates are dropped and duplicate vertices merged: the
Panda's visual meshes are 10.6 MB of GLB as read and 2.8 MB so, for every arm an ``.rrd``
draws. Each file is converted once per process.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import trimesh

from pipeline.errors import SpecError

__all__ = ["GLB_MEDIA_TYPE", "mesh_glb"]

GLB_MEDIA_TYPE = "model/gltf-binary"
UNIT_SCALE = (1.0, 1.0, 1.0)


@functools.lru_cache(maxsize=128)
def mesh_glb(path: str, scale: tuple[float, ...] = UNIT_SCALE) -> bytes:
    """The mesh at ``path`` (scaled by ``scale`` per axis) as a binary glTF.

    Raises:
        SpecError: a file trimesh cannot read (names it and trimesh's reason; a COLLADA
            file without pycollada installed is one).
    """
    if path.lower().endswith(".dae"):
        _need_pycollada(path)
    try:
        scene: Any = trimesh.load(path, force="scene")
        out: Any = trimesh.Scene()
        for node in scene.graph.nodes_geometry:
            node_T_part, name = scene.graph[node]
            part = scene.geometry[name]
            flat: Any = trimesh.Trimesh(part.vertices, part.faces, process=True)  # merged vertices
            flat.visual.face_colors = _colour(part)
            out.add_geometry(flat, node_name=node, geom_name=name, transform=node_T_part)
    except Exception as err:  # trimesh raises what its readers raise
        raise SpecError(f"{path}: cannot read the mesh ({err})") from err
    if not out.geometry:
        raise SpecError(f"{path}: cannot read the mesh (no triangles in it)")
    try:
        if tuple(scale) != UNIT_SCALE:
            out.apply_transform(np.diag([*scale, 1.0]))
        return bytes(out.export(file_type="glb", include_normals=True))
    except Exception as err:  # a degenerate scale or part trimesh cannot export
        raise SpecError(f"{path}: cannot convert the mesh to glTF ({err})") from err


def _colour(part: Any) -> Any:
    """The part's colour (RGBA, 0..255): its material's main colour, else its own."""
    visual = part.visual
    material = getattr(visual, "material", None)
    return material.main_color if material is not None else visual.main_color


def _need_pycollada(path: str) -> None:
    try:
        import collada  # type: ignore[import-untyped]  # noqa: F401  (trimesh's COLLADA reader)
    except ImportError as err:
        raise SpecError(
            f"{path}: cannot read the mesh (COLLADA needs pycollada: pip install pycollada)"
        ) from err
