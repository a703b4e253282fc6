"""A robot's link geometry (visual or collision) on the arm's link frames, for the
viewers (``teach``'s viser scene, the report's ``.rrd``), and its link graph, for the
collision matrix: what a robot file format describes beyond the :class:`RobotSpec`.

A format that describes link geometry registers a :class:`FormatGeometry` in
:data:`pipeline.robots.loaders.GEOMETRY` (keyed by :attr:`RobotSpec.format`); nothing
outside this module and the loaders asks which format a robot came from. A format
without an entry (DH YAML, MJCF) has no link geometry: the viewers draw capsules, the
collision matrix takes the joints' bodies as the link graph.

URDF (:data:`URDF_GEOMETRY`): each ``<visual>``/``<collision>`` of the robot's URDF
(:attr:`RobotSpec.description`) is placed on the link frame that carries it: the base
(owner -1) or the link moved by joint ``i`` (owner ``i``, the frame
:func:`pipeline.model.dh.link_frames` poses). Links merged into another (fixed joints,
locked fingers) are carried by their owner through their :attr:`RobotSpec.frames` pose.
``package://`` resolves as the loader resolves it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal
from xml.etree import ElementTree

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import SpecError
from pipeline.robots.spec import RobotSpec, pose_matrix
from pipeline.robots.urdf_loader import urdf_geometry, xml_floats, xml_origin

__all__ = [
    "RERUN_MESH_SUFFIXES",
    "URDF_GEOMETRY",
    "FormatGeometry",
    "GeometryKind",
    "LinkGeometry",
    "format_geometry",
    "has_link_geometry",
    "link_edges",
    "link_geometry",
    "rerun_geometry",
]

GeometryKind = Literal["visual", "collision"]
# What rr.Asset3D reads (Rerun 0.41); COLLADA (.dae), common in URDFs, is not among them.
RERUN_MESH_SUFFIXES = (".stl", ".obj", ".gltf", ".glb")


@dataclass(frozen=True)
class LinkGeometry:
    """One ``<visual>`` or ``<collision>`` element, on its owner's link frame.

    Attributes:
        link: the URDF link it belongs to.
        owner: -1 for the base, else the index of the joint whose link frame carries it.
        owner_T_geometry: its pose in the owner's link frame (4x4) [m].
        shape: ``mesh``, ``box``, ``sphere`` or ``cylinder``.
        size: mesh: scale (x, y, z); box: full extents [m]; sphere: (radius,) [m];
            cylinder: (radius, length) [m].
        mesh: absolute path of the mesh file ("" for a primitive).
        rgba: the URDF's material colour, when it gives one inline (0..1).
    """

    link: str
    owner: int
    owner_T_geometry: NDArray[np.float64]
    shape: str
    size: tuple[float, ...]
    mesh: str = ""
    rgba: tuple[float, float, float, float] | None = None


def _owners(spec: RobotSpec) -> dict[str, tuple[int, NDArray[np.float64]]]:
    """URDF link name -> (owner index, owner_T_link)."""
    out: dict[str, tuple[int, NDArray[np.float64]]] = {spec.base_link: (-1, np.eye(4))}
    index = {spec.base_link: -1}
    for i, joint in enumerate(spec.joints):
        out[joint.link] = (i, np.eye(4))
        index[joint.link] = i
    for frame in spec.frames:
        if frame.link in index and frame.name not in out:
            out[frame.name] = (index[frame.link], pose_matrix(frame.pose))
    return out


@dataclass(frozen=True)
class FormatGeometry:
    """What a robot file format describes beyond the :class:`RobotSpec`, registered in
    :data:`pipeline.robots.loaders.GEOMETRY` under the format's :attr:`RobotSpec.format`.

    Attributes:
        links: ``(spec, kind, package_path)`` -> every ``kind`` element (visual or
            collision) of the robot's links, on the arm's link frames (() if none).
            Raises :class:`SpecError` (one line) for geometry it cannot resolve.
        edges: ``spec`` -> the parent-child link pairs of every joint of the description
            (fixed ones included); None: the description does not give them (then the
            joints' bodies, :attr:`RobotSpec.adjacent_pairs`).
    """

    links: Callable[[RobotSpec, GeometryKind, tuple[str, ...]], tuple[LinkGeometry, ...]]
    edges: Callable[[RobotSpec], list[tuple[str, str]] | None]


def format_geometry(spec: RobotSpec) -> FormatGeometry | None:
    """The registered geometry of ``spec``'s file format; None for a format without
    (:data:`pipeline.robots.loaders.GEOMETRY`)."""
    from pipeline.robots.loaders import GEOMETRY

    entry = GEOMETRY.get(spec.format)
    if entry is None:
        return None
    module, name = entry.split(":")
    found = getattr(importlib.import_module(module), name)
    if not isinstance(found, FormatGeometry):
        raise TypeError(f"pipeline.robots.loaders.GEOMETRY: {entry} is not a FormatGeometry")
    return found


def has_link_geometry(spec: RobotSpec) -> bool:
    """Whether ``spec``'s file format describes link geometry (the viewers then draw its
    links' meshes and primitives instead of capsules)."""
    return format_geometry(spec) is not None


def link_geometry(
    spec: RobotSpec, kind: GeometryKind, *, package_path: tuple[str, ...] = ()
) -> tuple[LinkGeometry, ...]:
    """Every ``<kind>`` element of the robot's links, on the arm's link frames; () for a
    robot whose format describes no link geometry.

    Raises:
        SpecError: an unresolved ``package://`` or a missing mesh file (one line).
    """
    geometry = format_geometry(spec)
    return () if geometry is None else geometry.links(spec, kind, package_path)


def link_edges(spec: RobotSpec) -> list[tuple[str, str]]:
    """Parent-child link pairs of every joint: the description's own (fixed joints
    included) where its format gives them, else the bodies' chain."""
    geometry = format_geometry(spec)
    edges = None if geometry is None else geometry.edges(spec)
    return list(spec.adjacent_pairs) if edges is None else edges


def _urdf_links(
    spec: RobotSpec, kind: GeometryKind, package_path: tuple[str, ...]
) -> tuple[LinkGeometry, ...]:
    """Every ``<kind>`` element of a URDF robot's links (() without its URDF text)."""
    if not spec.description:
        return ()
    source = spec.source
    try:
        root = ElementTree.fromstring(spec.description)
    except ElementTree.ParseError as err:
        raise SpecError(f"{source}: not well-formed XML ({err})") from err
    owners = _owners(spec)
    base = Path(source).parent
    out = []
    for link in root.findall("link"):
        name = link.get("name") or ""
        if name not in owners:
            continue  # the ROS "world" mount or a dropped tool0: nothing the arm carries
        owner, owner_T_link = owners[name]
        for k, el in enumerate(link.findall(kind)):
            where = f"{source}: link '{name}'.{kind}[{k}]"
            geometry = el.find("geometry")
            if geometry is None or len(geometry) == 0:
                continue
            pose = owner_T_link @ xml_origin(el.find("origin"), where)
            rgba = _colour(el, where)
            parsed = urdf_geometry(geometry[0], where, base=base, package_path=package_path)
            if parsed is not None:
                kind_of, size, mesh = parsed
                out.append(LinkGeometry(name, owner, pose, kind_of, size, mesh, rgba))
    return tuple(out)


def _urdf_edges(spec: RobotSpec) -> list[tuple[str, str]] | None:
    """The URDF's own parent-child links of every joint (fixed joints included)."""
    if not spec.description:
        return None
    root = ElementTree.fromstring(spec.description)
    edges = []
    for el in root.findall("joint"):
        parent, child = el.find("parent"), el.find("child")
        if parent is not None and child is not None:
            edges.append((parent.get("link") or "", child.get("link") or ""))
    return edges


URDF_GEOMETRY = FormatGeometry(links=_urdf_links, edges=_urdf_edges)
"""A URDF's ``<visual>``/``<collision>`` elements and joint graph."""


def _colour(el: ElementTree.Element, where: str) -> tuple[float, float, float, float] | None:
    colour = el.find("material/color")
    if colour is None:
        return None
    r, g, b, a = xml_floats(colour.get("rgba"), 4, f"{where}.material.color.rgba", "")
    return (r, g, b, a)


def rerun_geometry(
    spec: RobotSpec, *, package_path: tuple[str, ...] = ()
) -> tuple[LinkGeometry, ...]:
    """What the ``.rrd`` draws of a robot: each link's visual geometry where Rerun loads
    all of its meshes (:data:`RERUN_MESH_SUFFIXES`), else that link's collision geometry
    (its meshes Rerun cannot load left out); () for a robot whose format describes no
    link geometry.

    Raises:
        SpecError: an unresolved ``package://`` or a missing mesh file (one line).
    """
    visual = link_geometry(spec, "visual", package_path=package_path)
    collision = link_geometry(spec, "collision", package_path=package_path)

    def loadable(g: LinkGeometry) -> bool:
        return g.shape != "mesh" or Path(g.mesh).suffix.lower() in RERUN_MESH_SUFFIXES

    fallback = {g.link for g in visual if not loadable(g)}
    drawn = [g for g in visual if g.link not in fallback]
    drawn += [g for g in collision if g.link in fallback and loadable(g)]
    return tuple(drawn)
