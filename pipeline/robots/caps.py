"""Stated caps on what a robot file may ask for, checked before any work.

A robot file is input: a hostile or broken one (a 1,000-joint chain, a mimic cycle, an
origin of 1e300 m, a 500 MB mesh, a random-bytes STL) must end in one line naming the file
and what was wrong, never in a ``MemoryError``, a ``RecursionError`` or an engine's error
deep inside a build. The numbers are generous for a manipulator: a real arm (UR, Panda,
the example-robot-data arms) is far inside every one of them.
"""

from __future__ import annotations

import functools
import math
import os
import struct
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np

from pipeline.errors import SpecError

__all__ = [
    "MAX_JOINTS",
    "MAX_LINKS",
    "MAX_MASS_KG",
    "MAX_MESH_BYTES",
    "MAX_MESH_FACES",
    "MAX_MIMIC_CHAIN",
    "MAX_ORIGIN_M",
    "MAX_XML_DEPTH",
    "MIN_MASS_KG",
    "check_mesh",
    "check_xml_depth",
]

MAX_JOINTS = 64
"""Movable joints in one robot file (the arm, its fingers and any locked joints). Kinematics
memory grows with the cube of the chain length (0.69 GB at 200 joints)."""
MAX_LINKS = 512
"""Links (and so joints, fixed ones included) in one robot file."""
MAX_XML_DEPTH = 32
"""Element nesting of a URDF or SRDF (a URDF is 3 deep; an MJCF body tree is bounded by
:data:`MAX_LINKS` anyway)."""
MAX_MIMIC_CHAIN = 8
"""Joints a mimic joint may follow through (``a`` mimics ``b`` mimics ``c`` ...)."""
MAX_ORIGIN_M = 100.0
"""|xyz| of any origin (joint, inertial, collision) and the range of a prismatic joint [m]."""
MIN_MASS_KG, MAX_MASS_KG = 1e-6, 1e5
"""A link's stated mass (0, or absent, is a massless frame) [kg]."""
MAX_INERTIA_KG_M2 = 1e5
"""|entry| of a link's inertia tensor [kg m^2]."""
MAX_MESH_BYTES = 64 * 2**20
"""A collision mesh file (the largest in example-robot-data is 2.8 MB)."""
MAX_MESH_FACES = 200_000
"""Triangles of one collision mesh (MuJoCo collides its convex hull)."""

_STL_HEADER = 84
_STL_FACET = 50


def check_xml_depth(text: str, where: str, *, max_depth: int = MAX_XML_DEPTH) -> None:
    """Refuse XML nested deeper than ``max_depth``, before it is built into a tree.

    Raises:
        SpecError: naming ``where`` and the cap. Malformed XML passes (its parser names it).
    """
    parser: ElementTree.XMLPullParser[Any] = ElementTree.XMLPullParser(events=("start", "end"))
    depth = 0
    try:
        for start in range(0, len(text), 1 << 16):
            parser.feed(text[start : start + (1 << 16)])
            for item in parser.read_events():
                depth += 1 if item[0] == "start" else -1
                if depth > max_depth:
                    raise SpecError(f"{where}: elements nested more than {max_depth} deep")
    except ElementTree.ParseError:
        return


def check_mesh(path: Path, where: str) -> None:
    """Refuse a collision mesh MuJoCo cannot read, before it sees it: too big, an STL whose
    triangle count does not match its size, an OBJ without faces or with a malformed line,
    non-finite vertices, too many faces (:data:`MAX_MESH_BYTES`, :data:`MAX_MESH_FACES`).

    Raises:
        SpecError: ``where``, the file and what was wrong, in one line.
    """
    try:
        st = path.stat()
    except OSError as err:
        raise SpecError(f"{where}: mesh {path}: cannot read it ({err.strerror or err})") from err
    problem = _mesh_problem(str(path), st.st_size, st.st_mtime_ns)
    if problem:
        raise SpecError(f"{where}: mesh {path}: {problem}")


@functools.lru_cache(maxsize=256)
def _mesh_problem(path: str, size: int, mtime_ns: int) -> str:
    """What is wrong with the mesh at ``path`` ("" if nothing); cached per file version."""
    del mtime_ns  # part of the cache key only
    if size > MAX_MESH_BYTES:
        return f"{size} bytes, more than the cap of {MAX_MESH_BYTES} bytes"
    if size == 0:
        return "empty file"
    suffix = os.path.splitext(path)[1].lower()
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as err:
        return f"cannot read it ({err.strerror or err})"
    if suffix == ".stl":
        return _stl_problem(data)
    if suffix == ".obj":
        return _obj_problem(data)
    return ""


def _faces_problem(n: int) -> str:
    if n == 0:
        return "no triangles"
    if n > MAX_MESH_FACES:
        return f"{n} triangles, more than the cap of {MAX_MESH_FACES}"
    return ""


def _stl_problem(data: bytes) -> str:
    if len(data) >= _STL_HEADER:
        (n,) = struct.unpack_from("<I", data, 80)
        if len(data) == _STL_HEADER + _STL_FACET * n:  # binary STL
            if problem := _faces_problem(n):
                return problem
            facets = np.frombuffer(
                data, dtype=np.dtype([("f", "<f4", (12,)), ("attr", "<u2")]), count=n,
                offset=_STL_HEADER,
            )  # fmt: skip
            if not np.isfinite(facets["f"][:, 3:]).all():
                return "non-finite vertex coordinates"
            return ""
    if not data.lstrip().lower().startswith(b"solid"):
        claimed = struct.unpack_from("<I", data, 80)[0] if len(data) >= _STL_HEADER else None
        said = f" (header claims {claimed} triangles)" if claimed is not None else ""
        return (
            f"not an STL: {len(data)} bytes fit neither a binary STL{said} nor an ASCII one "
            "(starting 'solid')"
        )
    text = data.decode("ascii", errors="replace")
    vertices = []
    for number, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if words[:1] == ["vertex"]:
            try:
                xyz = [float(w) for w in words[1:]]
            except ValueError:
                xyz = []
            if len(xyz) != 3:
                return f"line {number}: malformed vertex {line.strip()[:60]!r}"
            vertices.append(xyz)
    if not vertices or len(vertices) % 3:
        return f"ASCII STL with {len(vertices)} vertices, not whole triangles"
    if problem := _faces_problem(len(vertices) // 3):
        return problem
    if not np.isfinite(np.asarray(vertices)).all():
        return "non-finite vertex coordinates"
    return ""


def _obj_problem(data: bytes) -> str:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return "not a text OBJ file (not UTF-8)"
    n_vertices = n_faces = 0
    for number, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0] == "v":
            try:
                xyz = [float(w) for w in words[1:4]]
            except ValueError:
                xyz = []
            if len(xyz) != 3:
                return f"line {number}: malformed vertex {line.strip()[:60]!r}"
            if not all(math.isfinite(v) for v in xyz):
                return f"line {number}: non-finite vertex {line.strip()[:60]!r}"
            n_vertices += 1
        elif words[0] == "f":
            try:
                idx = [int(w.split("/")[0]) for w in words[1:]]
            except ValueError:
                idx = []
            if len(idx) < 3 or any(i == 0 or abs(i) > n_vertices for i in idx):
                return f"line {number}: malformed face {line.strip()[:60]!r}"
            n_faces += len(idx) - 2
    if n_vertices == 0:
        return "no vertices"
    return _faces_problem(n_faces)
