"""Link transforms in URDF terms, as ``/tf`` publishes them (parent -> child)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.robots.chain import FLANGE, chain, joint_motion
from pipeline.robots.spec import IDENTITY, RobotSpec, pose_matrix


@dataclass(frozen=True)
class TfEdge:
    """One parent -> child transform of the URDF tree."""

    parent: str
    child: str
    parent_T_child: NDArray[np.float64]


def tf_edges(spec: RobotSpec, q: ArrayLike) -> list[TfEdge]:
    """URDF tree transforms at joint positions ``q`` (base link ... tool0), as in
    :func:`pipeline.robots.urdf.build_urdf` (named frames left out).

    Composing them gives the same flange pose as forward kinematics.
    """
    qs = np.asarray(q, dtype=float).reshape(-1)
    links = chain(spec)
    edges = []
    parent = spec.base_link
    prev_post = np.eye(4)
    for joint, link, qi in zip(spec.joints, links, qs, strict=True):
        child = joint.link_name
        edges.append(TfEdge(parent, child, prev_post @ link.pre @ joint_motion(joint, float(qi))))
        parent = child
        prev_post = link.post
    flange = prev_post if spec.flange == IDENTITY else prev_post @ pose_matrix(spec.flange)
    edges.append(TfEdge(parent, FLANGE, flange))
    return edges
