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

from pipeline import transforms as tf
from pipeline.robots.spec import IDENTITY, JointSpec, RobotSpec, Segment, pose_matrix

__all__ = [
    "BASE_LINK",
    "FLANGE",
    "ChainLink",
    "Segment",
    "chain",
    "joint_motion",
    "joint_motions",
    "link_name",
    "then_joint_motions",
]


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
    along (prismatic) its axis [rad or m]. :func:`joint_motions` is the same for many ``q``."""
    return tf.motion(joint.kind, joint.axis, q)


def joint_motions(
    joint: JointSpec, q: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`joint_motion` at each of the N values ``q`` [rad or m]: rotations (N, 3, 3) and
    translations (N, 3) (identity and zero for the part the joint's kind does not move)."""
    qs = np.asarray(q, dtype=float).reshape(-1)
    n = qs.shape[0]
    axis = np.array(joint.axis, dtype=float)
    if joint.kind == "prismatic":
        return np.broadcast_to(np.eye(3), (n, 3, 3)).copy(), qs[:, None] * axis
    c, s = np.cos(qs)[:, None, None], np.sin(qs)[:, None, None]
    if joint.axis == (0.0, 0.0, 1.0):
        rot = np.zeros((n, 3, 3))
        rot[:, 0, 0], rot[:, 0, 1] = c[:, 0, 0], -s[:, 0, 0]
        rot[:, 1, 0], rot[:, 1, 1] = s[:, 0, 0], c[:, 0, 0]
        rot[:, 2, 2] = 1.0
        return rot, np.zeros((n, 3))
    x, y, z = joint.axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + s * k + (1.0 - c) * (k @ k), np.zeros((n, 3))


def then_joint_motions(
    fixed: NDArray[np.float64], joint: JointSpec, q: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``fixed @ joint_motion(joint, q_k)`` for each of the N values ``q`` as translations
    (N, 3) [m] and unit quaternions (N, 4) (w, x, y, z): the quaternion of a rotation by
    ``q`` about the unit axis ``u`` is (cos(q/2), u sin(q/2)), composed with ``fixed``'s
    (Hamilton product); a prismatic joint moves the translation along ``fixed``'s
    rotation of its axis."""
    qs = np.asarray(q, dtype=float).reshape(-1)
    n = qs.shape[0]
    w1, x1, y1, z1 = tf.quat_wxyz(fixed[:3, :3])
    quat = np.empty((n, 4))
    translation = np.broadcast_to(fixed[:3, 3], (n, 3)).copy()
    if joint.kind == "prismatic":
        translation += qs[:, None] * (fixed[:3, :3] @ np.array(joint.axis, dtype=float))
        quat[:] = (w1, x1, y1, z1)
        return translation, quat
    c, s = np.cos(0.5 * qs), np.sin(0.5 * qs)
    if joint.axis == (0.0, 0.0, 1.0):  # the common case, in fewer operations
        quat[:, 0], quat[:, 1] = w1 * c - z1 * s, x1 * c + y1 * s
        quat[:, 2], quat[:, 3] = y1 * c - x1 * s, z1 * c + w1 * s
        return translation, quat
    a, b, d = (u * s for u in joint.axis)
    quat[:, 0] = w1 * c - x1 * a - y1 * b - z1 * d
    quat[:, 1] = w1 * a + x1 * c + y1 * d - z1 * b
    quat[:, 2] = w1 * b - x1 * d + y1 * c + z1 * a
    quat[:, 3] = w1 * d + x1 * b - y1 * a + z1 * c
    return translation, quat


def is_identity(pose: object) -> bool:
    """Whether a :data:`~pipeline.robots.spec.Pose` is exactly the identity."""
    return pose == IDENTITY


def link_name(joint_name: str) -> str:
    """URDF / tf link name for the link a DH joint moves: ``elbow_joint`` -> ``elbow_link``."""
    return f"{joint_name.removesuffix('_joint')}_link"


BASE_LINK = "base_link"
FLANGE = "tool0"
