"""The DH chain as fixed transforms around each joint rotation.

Both conventions factor as ``frame_i = frame_{i-1} @ pre_i @ Rz(q_i) @ post_i``:

- standard:  pre = I,                          post = Rz(off) Tz(d) Tx(a) Rx(alpha)
- modified:  pre = Rx(alpha) Tx(a) Tz(d) Rz(off), post = I

MJCF puts one body at each DH frame (joint axis expressed through ``post``);
URDF puts each link frame right after the rotation and carries ``post`` in the
next joint's origin. The link geometry follows the translations of ``post_i``
(moves with link i) and of ``pre_{i+1}`` (also rigid on link i).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from pipeline.model import transforms as tf
from pipeline.robots.spec import JointSpec, RobotSpec

Op = tuple[str, float]
MIN_SEGMENT_M = 1e-6


def _ops(joint: JointSpec, convention: str) -> tuple[list[Op], list[Op]]:
    r = joint.dh
    if convention == "standard":
        return [], [("rz", r.theta_offset), ("tz", r.d), ("tx", r.a), ("rx", r.alpha)]
    return [("rx", r.alpha), ("tx", r.a), ("tz", r.d), ("rz", r.theta_offset)], []


def _compose(ops: list[Op]) -> tuple[NDArray[np.float64], list[NDArray[np.float64]]]:
    """Matrix of a sequence of elementary ops, and the polyline its translations trace."""
    t = np.eye(4)
    points = [t[:3, 3].copy()]
    for kind, v in ops:
        step = {
            "rz": lambda x: tf.rot_z(x),
            "rx": lambda x: tf.rot_x(x),
            "tz": lambda x: tf.trans(0, 0, x),
            "tx": lambda x: tf.trans(x, 0, 0),
        }[kind](v)
        t = t @ step
        if kind.startswith("t") and v != 0.0:
            points.append(t[:3, 3].copy())
    return t, points


@dataclass(frozen=True)
class Segment:
    """A straight piece of link geometry, endpoints in the frame it is given in [m]."""

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class ChainLink:
    """Fixed transforms and geometry of link i.

    Attributes:
        pre: transform before the joint rotation (in frame i-1).
        post: transform after the rotation (G_i -> DH frame i).
        segments_dh: link geometry in DH frame i.
    """

    pre: NDArray[np.float64]
    post: NDArray[np.float64]
    segments_dh: tuple[Segment, ...]


def _segments(
    points: list[NDArray[np.float64]], to_frame: NDArray[np.float64], radius: float
) -> list[Segment]:
    out = []
    pts = [(to_frame @ np.append(p, 1.0))[:3] for p in points]
    for a, b in pairwise(pts):
        # MuJoCo refuses a capsule shorter than 1e-6 m ("fromto points too close"); a
        # sub-micron DH offset draws no geometry
        if np.linalg.norm(b - a) > MIN_SEGMENT_M:
            out.append(Segment((a[0], a[1], a[2]), (b[0], b[1], b[2]), radius))
    return out


def chain(spec: RobotSpec) -> tuple[ChainLink, ...]:
    """Per-link fixed transforms and collision segments (DH-frame coordinates)."""
    decomposed = [_ops(j, spec.convention) for j in spec.joints]
    links = []
    for i, joint in enumerate(spec.joints):
        pre, _ = _compose(decomposed[i][0])
        post, post_pts = _compose(decomposed[i][1])
        # post's polyline is traced from G_i: map to DH frame i with inv(post).
        segs = _segments(post_pts, tf.inverse(post), joint.collision_radius)
        if i + 1 < len(spec.joints):
            _, next_pre_pts = _compose(decomposed[i + 1][0])
            segs += _segments(next_pre_pts, np.eye(4), joint.collision_radius)
        links.append(ChainLink(pre=pre, post=post, segments_dh=tuple(segs)))
    return tuple(links)


def link_name(joint_name: str) -> str:
    """URDF / tf link name for the link a joint moves: ``elbow_joint`` -> ``elbow_link``."""
    return f"{joint_name.removesuffix('_joint')}_link"


BASE_LINK = "base_link"
FLANGE = "tool0"
