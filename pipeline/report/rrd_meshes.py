"""A URDF robot's arm in recording.rrd, drawn from its meshes: each link frame an entity
posed over time by FK of the recorded joints, each link's geometry logged once under it
(:func:`drawn_geometry`: the visual geometry, its COLLADA meshes converted to glTF in
their own colours, else the link's collision geometry, with the reason). DH robots keep
their capsules (:mod:`pipeline.report.rrd_scene`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from pipeline.errors import SpecError
from pipeline.model.dh import link_frames
from pipeline.report import entities as ent
from pipeline.robots import RobotSpec
from pipeline.robots.link_geometry import (
    RERUN_MESH_SUFFIXES,
    LinkGeometry,
    has_link_geometry,
    link_geometry,
    rerun_geometry,
)
from pipeline.robots.mesh_glb import GLB_MEDIA_TYPE, mesh_glb

__all__ = ["LinkMeshes", "drawn_geometry", "link_meshes", "send_link_meshes"]


@dataclass(frozen=True)
class LinkMeshes:
    """What an episode's mesh arm draws.

    Attributes:
        geometry: each link's drawn geometry, on its owner's link frame.
        links: the owners' link names: the base first, then each joint's link.
        base_T_link: the joints' link frames per drawn frame, (F, n, 4, 4) [m].
        note: why some links show their collision geometry, or (no geometry) why none is
            drawn ("" when every link shows its visual geometry).
    """

    geometry: tuple[LinkGeometry, ...]
    links: tuple[str, ...]
    base_T_link: NDArray[np.float64]
    note: str = ""


def _rerun_reads(g: LinkGeometry) -> bool:
    return g.shape != "mesh" or Path(g.mesh).suffix.lower() in RERUN_MESH_SUFFIXES


def drawn_geometry(spec: RobotSpec) -> tuple[tuple[LinkGeometry, ...], str]:
    """What the ``.rrd`` draws of a URDF robot, and why some links fall back ("" if none).

    Each link's visual geometry; meshes Rerun cannot load (COLLADA) are converted to
    glTF (:func:`mesh_glb`). A link with a mesh that cannot be converted shows its
    collision geometry instead (:func:`rerun_geometry`'s fallback).

    Raises:
        SpecError: an unresolved ``package://`` or a missing mesh file (one line).
    """
    visual = link_geometry(spec, "visual")
    failed: dict[str, str] = {}
    for g in visual:
        if not _rerun_reads(g) and g.link not in failed:
            try:
                mesh_glb(g.mesh)
            except SpecError as err:
                failed[g.link] = str(err)
    if not failed:
        return visual, ""
    kept = [g for g in visual if g.link not in failed]
    fallback = [g for g in rerun_geometry(spec) if g.link in failed]
    first = next(iter(failed.values()))
    note = (
        f"{len(failed)} link(s) drawn from their collision geometry ({', '.join(failed)}): {first}"
    )
    return (*kept, *fallback), note


def link_meshes(spec: RobotSpec, q: NDArray[np.float64]) -> LinkMeshes | None:
    """The mesh arm at each row of ``q``; None for a robot whose format describes no link
    geometry (:func:`pipeline.robots.link_geometry.has_link_geometry`). A robot whose
    geometry cannot be drawn (a mesh file not on this machine: the bag carries the robot,
    its meshes by path only) gets no geometry and a note saying why: capsules then, with
    the note."""
    if not has_link_geometry(spec):
        return None
    links = (spec.base_link, *(j.link for j in spec.joints))
    try:
        geometry, note = drawn_geometry(spec)
    except SpecError as err:
        empty = np.zeros((q.shape[0], spec.dof, 4, 4))
        return LinkMeshes((), links, empty, f"link meshes not drawn (capsules instead): {err}")
    if not geometry:
        return None
    frames = np.array([link_frames(spec, qf) for qf in q]).reshape(q.shape[0], spec.dof, 4, 4)
    return LinkMeshes(geometry, links, frames, note)


def send_link_meshes(
    stream: rr.RecordingStream,
    episode: str,
    t: NDArray[np.float64],
    meshes: LinkMeshes,
    color: tuple[int, int, int],
) -> None:
    """Log the link frames over time and each geometry once (static) under its link (and
    the fallback's reason, if any, as a text document beside them)."""
    owners = sorted({g.owner for g in meshes.geometry})
    for owner in owners:
        path = ent.arm_link_path(episode, meshes.links[owner + 1])
        if owner < 0:  # the base: the episode's root frame
            stream.log(path, rr.Transform3D(translation=[0.0, 0.0, 0.0]), static=True)
            continue
        frames = meshes.base_T_link[:, owner]
        stream.send_columns(
            path,
            indexes=[rr.TimeColumn(ent.TIMELINE, duration=t)],
            columns=rr.Transform3D.columns(translation=frames[:, :3, 3], mat3x3=frames[:, :3, :3]),
        )
    rgba = [*color, 255]
    for k, g in enumerate(meshes.geometry):
        path = f"{ent.arm_link_path(episode, meshes.links[g.owner + 1])}/{k}_{ent.part(g.link)}"
        rot = g.owner_T_geometry[:3, :3]
        scale = np.diag(g.size) if g.shape == "mesh" else np.eye(3)
        stream.log(
            path,
            rr.Transform3D(translation=g.owner_T_geometry[:3, 3], mat3x3=rot @ scale),
            static=True,
        )
        stream.log(path, _archetype(g, rgba), static=True)
    if meshes.note:
        stream.log(f"{ent.arm_path(episode)}/mesh_note", rr.TextDocument(meshes.note), static=True)


def _archetype(g: LinkGeometry, rgba: list[int]) -> rr.AsArchetype:
    if g.shape == "mesh" and not _rerun_reads(g):  # converted: in its own colours
        return rr.Asset3D(contents=mesh_glb(g.mesh), media_type=GLB_MEDIA_TYPE)
    if g.shape == "mesh":
        return rr.Asset3D(path=g.mesh, albedo_factor=rgba)
    if g.shape == "box":
        return rr.Boxes3D(half_sizes=[[0.5 * s for s in g.size]], colors=[rgba],
                          fill_mode="solid")  # fmt: skip
    if g.shape == "sphere":
        return rr.Ellipsoids3D(half_sizes=[[g.size[0]] * 3], colors=[rgba], fill_mode="solid")
    # a URDF cylinder is centred on its origin, along z; Rerun's too
    return rr.Cylinders3D(lengths=[g.size[1]], radii=[g.size[0]], colors=[rgba],
                          fill_mode="solid")  # fmt: skip
