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
from collections.abc import Mapping
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
    "check_count",
    "check_inertia",
    "check_inside_robot_folder",
    "check_limit",
    "check_mass",
    "check_mesh",
    "check_mimics",
    "check_origin",
    "check_xml_depth",
    "robot_folder",
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
MAX_JOINT_RAD = 4 * math.pi
"""|lower|, |upper| of a revolute joint: two turns each way [rad]."""
MAX_VELOCITY_RAD_S = 100.0
"""A joint's velocity limit [rad/s or m/s]."""
MAX_EFFORT_NM = 1e5
"""A joint's effort limit [N m or N]."""
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


def check_count(n: int, cap: int, what: str, where: str) -> None:
    """Refuse more than ``cap`` of ``what`` (naming ``where``)."""
    if n > cap:
        raise SpecError(f"{where}: {n} {what}, more than the cap of {cap}")


def check_origin(xyz: tuple[float, ...], where: str) -> None:
    """Refuse an origin farther than :data:`MAX_ORIGIN_M` on any axis (``where`` names it)."""
    if max(abs(v) for v in xyz) > MAX_ORIGIN_M:
        raise SpecError(f"{where} is out of range, expected |value| <= {MAX_ORIGIN_M:g} m")


def check_mass(mass_kg: float, where: str) -> None:
    """Refuse a mass outside 0 or [:data:`MIN_MASS_KG`, :data:`MAX_MASS_KG`]."""
    if mass_kg != 0 and not MIN_MASS_KG <= mass_kg <= MAX_MASS_KG:
        raise SpecError(
            f"{where}: mass {mass_kg:g} kg is out of range, expected 0 or "
            f"[{MIN_MASS_KG:g}, {MAX_MASS_KG:g}] kg"
        )


def check_inertia(tensor: np.ndarray[Any, Any], where: str) -> None:
    """Refuse an inertia entry beyond :data:`MAX_INERTIA_KG_M2`."""
    worst = float(np.abs(tensor).max())
    if worst > MAX_INERTIA_KG_M2:
        raise SpecError(
            f"{where}: inertia entry {worst:g} kg m^2 is out of range, expected |value| <= "
            f"{MAX_INERTIA_KG_M2:g}"
        )


def check_limit(
    limit: Mapping[str, float],
    kind: str,
    where: str,
    keys: tuple[str, ...] = ("lower", "upper", "velocity", "effort"),
) -> None:
    """Refuse limits (``keys`` of them) beyond :mod:`~pipeline.robots.caps` magnitudes
    (NaN: not stated)."""
    position = (MAX_ORIGIN_M, "m") if kind == "prismatic" else (MAX_JOINT_RAD, "rad")
    if kind == "continuous":
        position = (math.inf, "rad")  # a continuous joint's lower and upper are ignored
    bounds = {"lower": position, "upper": position,
              "velocity": (MAX_VELOCITY_RAD_S, "rad/s or m/s"),
              "effort": (MAX_EFFORT_NM, "N m or N")}  # fmt: skip
    for key in keys:
        bound, unit = bounds[key]
        if abs(limit[key]) > bound:
            raise SpecError(
                f"{where}.limit.{key}: {limit[key]!r} is out of range, expected |value| <= "
                f'{bound:.6g} {unit} (a joint without limits is type="continuous")'
            )


def check_mimics(source: str, masters: Mapping[str, str | None]) -> None:
    """Refuse a mimic cycle or a chain longer than :data:`MAX_MIMIC_CHAIN` (``masters``:
    the joint each joint mimics, None for none)."""
    for start in masters:
        seen = [start]
        name = masters[start]
        while name is not None and name in masters:
            if name in seen:
                raise SpecError(f"{source}: mimic cycle: {' -> '.join([*seen, name])}")
            seen.append(name)
            if len(seen) > MAX_MIMIC_CHAIN:
                raise SpecError(
                    f"{source}: joint '{start}' mimics through more than {MAX_MIMIC_CHAIN} joints"
                )
            name = masters[name]


def robot_folder(base: Path) -> Path:
    """The folder a URDF's file paths must stay in: its own folder, or its parent when it
    sits in a ``urdf/`` folder (a ROS description package: ``urdf/`` next to ``meshes/``)."""
    return base.parent if base.name == "urdf" else base


def check_inside_robot_folder(uri: str, path: Path, base: Path, where: str) -> None:
    root = os.path.normpath(os.path.abspath(robot_folder(base)))
    target = os.path.normpath(os.path.abspath(path))
    if os.path.commonpath([root, target]) != root:
        raise SpecError(
            f"{where}: mesh {uri!r} lies outside the robot's folder {root}: keep meshes "
            "there, or name them package://NAME/... with --package-path"
        )


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
