"""Link transforms in URDF terms, as ``/tf`` publishes them (parent -> child)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.model import transforms as tf
from pipeline.model.chain import BASE_LINK, FLANGE, chain, link_name
from pipeline.robots.spec import RobotSpec


@dataclass(frozen=True)
class TfEdge:
    """One parent -> child transform of the URDF tree."""

    parent: str
    child: str
    parent_T_child: NDArray[np.float64]


def tf_edges(spec: RobotSpec, q: ArrayLike) -> list[TfEdge]:
    """URDF tree transforms at joint positions ``q`` (base_link ... tool0).

    Composing them gives the same flange pose as DH forward kinematics.
    """
    qs = np.asarray(q, dtype=float).reshape(-1)
    links = chain(spec)
    edges = []
    parent = BASE_LINK
    prev_post = np.eye(4)
    for joint, link, qi in zip(spec.joints, links, qs, strict=True):
        child = link_name(joint.name)
        edges.append(TfEdge(parent, child, prev_post @ link.pre @ tf.rot_z(float(qi))))
        parent = child
        prev_post = link.post
    edges.append(TfEdge(parent, FLANGE, prev_post))
    return edges
