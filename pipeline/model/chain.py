"""The robot's joints as fixed transforms around each joint motion, in arrays.

Every format factors as ``link_i = link_{i-1} @ pre_i @ motion_i(q_i) @ post_i``
(:class:`pipeline.robots.spec.JointSpec`: ``pre`` is the joint origin, ``post`` is identity
for a URDF joint and the DH frame past the rotation for a DH row). MJCF puts one body at
each link frame (the joint axis expressed through ``post``); URDF puts each link frame right
after the motion and carries ``post`` in the next joint's origin.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.model import transforms as tf
from pipeline.robots.spec import IDENTITY, JointSpec, RobotSpec, Segment, pose_matrix

__all__ = ["BASE_LINK", "FLANGE", "ChainLink", "Segment", "chain", "joint_motion", "link_name"]


@dataclass(frozen=True)
class ChainLink:
    """Fixed transforms and geometry of link i.

    Attributes:
        pre: joint origin, before the motion (in link frame i-1).
        post: transform after the motion (joint frame -> link frame i).
        axis: unit motion axis in the joint frame.
        segments: link capsules in link frame i.
    """

    pre: NDArray[np.float64]
    post: NDArray[np.float64]
    axis: NDArray[np.float64]
    segments: tuple[Segment, ...]


def chain(spec: RobotSpec) -> tuple[ChainLink, ...]:
    """Per-link fixed transforms and collision capsules (link-frame coordinates)."""
    return tuple(
        ChainLink(
            pre=pose_matrix(j.origin),
            post=pose_matrix(j.post),
            axis=np.array(j.axis, dtype=np.float64),
            segments=j.capsules,
        )
        for j in spec.joints
    )


@functools.lru_cache(maxsize=64)
def chain_arrays(
    spec: RobotSpec,
) -> tuple[tuple[NDArray[np.float64], NDArray[np.float64], bool, bool], ...]:
    """Per joint ``(pre, post, pre is identity, post is identity)``, cached per robot (FK's
    inner loop)."""
    return tuple(
        (pose_matrix(j.origin), pose_matrix(j.post), j.origin == IDENTITY, j.post == IDENTITY)
        for j in spec.joints
    )


def joint_motion(joint: JointSpec, q: float) -> NDArray[np.float64]:
    """The joint's motion at ``q``: a rotation about (revolute, continuous) or a translation
    along (prismatic) its axis [rad or m]."""
    if joint.kind == "prismatic":
        return tf.trans(*(q * np.array(joint.axis)))
    if joint.axis == (0.0, 0.0, 1.0):
        return tf.rot_z(q)
    return tf.rot_axis(np.array(joint.axis), q)


def is_identity(pose: object) -> bool:
    """Whether a :data:`~pipeline.robots.spec.Pose` is exactly the identity."""
    return pose == IDENTITY


def link_name(joint_name: str) -> str:
    """URDF / tf link name for the link a DH joint moves: ``elbow_joint`` -> ``elbow_link``."""
    return f"{joint_name.removesuffix('_joint')}_link"


BASE_LINK = "base_link"
FLANGE = "tool0"
