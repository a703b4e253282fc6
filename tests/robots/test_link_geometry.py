"""A robot's link geometry and link graph come from its format's registry entry
(:data:`pipeline.robots.loaders.GEOMETRY`), not from a test of the format's name: a new
format with meshes is its loader and one entry, and every viewer and the collision
matrix follow."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.report.rrd_meshes import link_meshes
from pipeline.robots import load_spec
from pipeline.robots.link_geometry import (
    LinkGeometry,
    has_link_geometry,
    link_edges,
    link_geometry,
)
from pipeline.robots.loaders import GEOMETRY
from tests.stages.test_urdf_robot_e2e import pytestmark as needs_panda


def _key(g: LinkGeometry) -> tuple[object, ...]:
    return (g.link, g.owner, g.shape, g.size, g.mesh, g.rgba, g.owner_T_geometry.tobytes())


@needs_panda
def test_a_new_format_with_meshes_is_drawn_once_registered(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    panda = load_spec("panda")
    other = dataclasses.replace(panda, format="other-mesh-format")
    q = np.zeros((2, panda.dof))
    # unregistered: no link geometry anywhere (capsules), the joints' bodies as the graph
    assert not has_link_geometry(other)
    assert link_geometry(other, "collision") == ()
    assert link_meshes(other, q) is None
    assert link_edges(other) == list(panda.adjacent_pairs)
    monkeypatch.setitem(GEOMETRY, "other-mesh-format", GEOMETRY["urdf"])
    assert has_link_geometry(other)
    for kind in ("visual", "collision"):
        drawn = [_key(g) for g in link_geometry(other, kind)]
        assert drawn and drawn == [_key(g) for g in link_geometry(panda, kind)], kind
    # the URDF's own graph: its fixed joints (hand, fingers' mount) included
    assert link_edges(other) == link_edges(panda)
    assert len(link_edges(panda)) > len(panda.adjacent_pairs)


def test_formats_without_link_geometry_are_drawn_as_capsules() -> None:
    ur5 = load_spec("ur5")
    assert ur5.format not in GEOMETRY
    assert not has_link_geometry(ur5)
    assert link_geometry(ur5, "visual") == ()
    assert link_edges(ur5) == list(ur5.adjacent_pairs)
