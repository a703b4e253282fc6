"""A mesh file as GLB bytes for the viewers: ``teach`` (viser) and the ``.rrd`` (Rerun,
whose ``Asset3D`` reads STL, OBJ and glTF but not the COLLADA many URDFs use, the Panda's
among them).

trimesh reads the file (COLLADA through pycollada); each part keeps its material's colour
as a flat colour, texture coordinates are dropped and duplicate vertices merged: the
Panda's visual meshes are 10.6 MB of GLB as read and 2.8 MB so, for every arm an ``.rrd``
draws. Each file is converted once per process, and once per machine: the GLB goes into
a content-addressed cache (``$XDG_CACHE_HOME/armlab/mesh_glb``, else
``~/.cache/armlab/mesh_glb``; ``ARMLAB_CACHE_DIR`` overrides the ``armlab`` folder), keyed
by the file's SHA-256, the scale and the converter (this module's version and trimesh's),
written atomically (a temporary file renamed); a cache that cannot be read or written is
skipped, never required. trimesh (1.2 s of imports with its SciPy and networkx) is imported
on the first conversion, not by every ``.rrd``.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import SpecError
from pipeline.fsutil import OutputPathError, atomic_write_bytes

__all__ = ["GLB_MEDIA_TYPE", "cache_dir", "convert_glb", "mesh_glb"]

GLB_MEDIA_TYPE = "model/gltf-binary"
UNIT_SCALE = (1.0, 1.0, 1.0)
CONVERTER_VERSION = "1"
"""Bumped whenever the conversion below changes its output (part of the cache key)."""


def cache_dir() -> Path:
    """Where converted meshes are kept (see the module docstring)."""
    root = os.environ.get("ARMLAB_CACHE_DIR")
    if root:
        return Path(root) / "mesh_glb"
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "armlab" / "mesh_glb"


def _cache_key(path: str, scale: tuple[float, ...]) -> str:
    digest = hashlib.sha256(Path(path).read_bytes())
    try:
        trimesh_version = metadata.version("trimesh")
    except metadata.PackageNotFoundError:
        trimesh_version = "?"
    digest.update(repr((tuple(float(x) for x in scale), CONVERTER_VERSION,
                        trimesh_version)).encode())  # fmt: skip
    return digest.hexdigest()


def _cached(key: str) -> bytes | None:
    try:
        return (cache_dir() / f"{key}.glb").read_bytes()
    except OSError:
        return None


def _store(key: str, glb: bytes) -> None:
    """Write the cache entry atomically; any failure just leaves it out."""
    folder = cache_dir()
    with contextlib.suppress(OSError, OutputPathError):
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(folder / f"{key}.glb", glb)


@functools.lru_cache(maxsize=128)
def mesh_glb(path: str, scale: tuple[float, ...] = UNIT_SCALE) -> bytes:
    """The mesh at ``path`` (scaled by ``scale`` per axis) as a binary glTF, from the
    disk cache when it was converted before (the same bytes).

    Raises:
        SpecError: a file trimesh cannot read (names it and trimesh's reason; a COLLADA
            file without pycollada installed is one), or a file that cannot be read.
    """
    try:
        key = _cache_key(path, scale)
    except OSError as err:
        raise SpecError(f"{path}: cannot read the mesh ({err.strerror or err})") from err
    glb = _cached(key)
    if glb is None:
        glb = convert_glb(path, scale)
        _store(key, glb)
    return glb


def convert_glb(path: str, scale: tuple[float, ...] = UNIT_SCALE) -> bytes:
    """``mesh_glb`` without the caches: trimesh's conversion itself."""
    import trimesh

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
