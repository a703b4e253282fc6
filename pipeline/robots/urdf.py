"""Robot spec -> URDF text and a Pinocchio model built from it.

URDF link i's frame is the frame right after joint i's motion (link frame
i-1 composed with ``pre_i @ motion_i(q_i)``); the model's link frame i (a DH
robot's DH frame i) is ``post_i`` further. That keeps every joint about its own
axis through its frame's origin, as URDF wants, for both DH conventions and for
robots read from a URDF (``post`` = identity). ``tool0`` is the flange frame;
the robot's further named frames are fixed links.
"""

from __future__ import annotations

import functools
import math
from xml.sax.saxutils import quoteattr

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from pipeline import transforms as tf
from pipeline.errors import ModelError
from pipeline.robots.chain import FLANGE, chain
from pipeline.robots.spec import IDENTITY, RobotSpec, pose_matrix


def _v(xs: NDArray[np.float64] | tuple[float, ...]) -> str:
    return " ".join(repr(float(x)) for x in xs)


def _origin(t: NDArray[np.float64]) -> str:
    return f'<origin xyz="{_v(t[:3, 3])}" rpy="{_v(np.array(tf.rpy(t[:3, :3])))}"/>'


def _cylinder_between(
    a: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float]:
    """Origin (z along a->b, at the midpoint) and length of a cylinder joining a and b."""
    d = b - a
    length = float(np.linalg.norm(d))
    z = d / length
    helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    t = np.eye(4)
    t[:3, :3] = np.column_stack([x, y, z])
    t[:3, 3] = (a + b) / 2
    return t, length


def _axis(axis: NDArray[np.float64]) -> str:
    """The ``<axis xyz>`` text: integers as integers (``0 0 1``), anything else exact."""
    return " ".join(str(int(v)) if float(v).is_integer() else repr(float(v)) for v in axis)


def _urdf_type(kind: str) -> str:
    # a continuous joint is written revolute with its (stated) limits: Pinocchio models a
    # continuous joint with two configuration variables (cos, sin), the controllers one
    return "prismatic" if kind == "prismatic" else "revolute"


@functools.lru_cache(maxsize=64)
def build_urdf(spec: RobotSpec) -> str:
    """URDF text of the robot (inertials, visual + collision cylinders, ``tool0``);
    cached per process (an episode needs it twice: controller model, robot description)."""
    links = chain(spec)
    out = [f'<?xml version="1.0"?>\n<robot name={quoteattr(spec.name)}>']
    out.append(f"  <link name={quoteattr(spec.base_link)}/>")
    parent = spec.base_link
    prev_post = np.eye(4)
    urdf_T_link = {spec.base_link: np.eye(4)}
    for joint, link in zip(spec.joints, links, strict=True):
        name = joint.link_name
        urdf_T_link[name] = link.post
        out.append(f"  <link name={quoteattr(name)}>")
        if joint.inertial is not None:
            inn = joint.inertial
            # inertial frame: DH frame i (post) shifted to the centre of mass
            frame = link.post @ tf.trans(*inn.com)
            t = inn.inertia
            out.append(
                f'    <inertial>{_origin(frame)}<mass value="{inn.mass!r}"/>'
                f'<inertia ixx="{t[0][0]!r}" ixy="{t[0][1]!r}" ixz="{t[0][2]!r}" '
                f'iyy="{t[1][1]!r}" iyz="{t[1][2]!r}" izz="{t[2][2]!r}"/></inertial>'
            )
        for seg in link.segments:
            a = (link.post @ np.append(seg.start, 1.0))[:3]
            b = (link.post @ np.append(seg.end, 1.0))[:3]
            origin, length = _cylinder_between(a, b)
            geom = f'<geometry><cylinder radius="{seg.radius!r}" length="{length!r}"/></geometry>'
            out.append(f"    <visual>{_origin(origin)}{geom}</visual>")
            out.append(f"    <collision>{_origin(origin)}{geom}</collision>")
        out.append("  </link>")
        lim = joint.limits
        out.append(
            f"  <joint name={quoteattr(joint.name)} type={quoteattr(_urdf_type(joint.kind))}>"
            f"<parent link={quoteattr(parent)}/><child link={quoteattr(name)}/>"
            f"{_origin(prev_post @ link.pre)}"
            f'<axis xyz="{_axis(link.axis)}"/><limit lower="{lim.lower!r}" upper="{lim.upper!r}" '
            f'effort="{lim.effort!r}" velocity="{lim.velocity!r}"/></joint>'
        )
        parent = name
        prev_post = link.post
    flange = prev_post if spec.flange == IDENTITY else prev_post @ pose_matrix(spec.flange)
    out.append(f'  <link name="{FLANGE}"/>')
    out.append(
        f'  <joint name="{FLANGE}_fixed_joint" type="fixed"><parent link={quoteattr(parent)}/>'
        f'<child link="{FLANGE}"/>{_origin(flange)}</joint>'
    )
    for named in spec.frames:
        if named.name == FLANGE:
            continue
        out.append(f"  <link name={quoteattr(named.name)}/>")
        out.append(
            f'  <joint name={quoteattr(named.name + "_fixed_joint")} type="fixed">'
            f"<parent link={quoteattr(named.link)}/><child link={quoteattr(named.name)}/>"
            f"{_origin(urdf_T_link[named.link] @ pose_matrix(named.pose))}</joint>"
        )
    out.append("</robot>")
    return "\n".join(out) + "\n"


def build_pinocchio_model(spec: RobotSpec) -> pin.Model:
    """Pinocchio model from the URDF text (gravity -9.81 z, frame ``tool0``).

    A copy of a per-process cached build (``pinocchio_model``): ~0.02 ms instead of
    ~2 ms, so the episodes of a campaign in one worker build each robot once.
    """
    return pin.Model(pinocchio_model(spec))


@functools.lru_cache(maxsize=64)
def pinocchio_model(spec: RobotSpec) -> pin.Model:
    """The cached build behind ``build_pinocchio_model`` (do not modify the result: copy it)."""
    try:
        model = pin.buildModelFromXML(build_urdf(spec))
    except (RuntimeError, ValueError) as err:
        raise ModelError(f"{spec.source}: Pinocchio rejected the generated URDF: {err}") from err
    if not math.isclose(model.gravity.linear[2], -9.81):
        model.gravity.linear[:] = (0.0, 0.0, -9.81)
    # URDF has no rotor inertia; Pinocchio adds ``armature`` to M's diagonal (CRBA) and
    # ``armature * qdd`` to RNEA, as MuJoCo does with the MJCF joint armature.
    model.armature[:] = spec.armature
    return model
