"""Robot spec -> MJCF (MuJoCo XML), with optional plant mismatch and obstacles.

Body i sits at DH frame i, so link inertias from the YAML go in unchanged and
the ``tool0`` site is the DH flange frame. Collision filtering by bit masks:
robot links collide with each other except a joint's parent and child (excluded
explicitly: MuJoCo's own parent/child filter skips the base, welded to the world),
links 2..n with the ground, and every link with obstacles.
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np

from pipeline import transforms as tf
from pipeline.constants import FRICTION_IMPEDANCE, PLANT_INTEGRATOR
from pipeline.errors import ModelError
from pipeline.model.scene import Box
from pipeline.robots.chain import FLANGE, chain
from pipeline.robots.spec import IDENTITY, Pose, RobotSpec, Shape, pose_matrix

ROBOT_BIT, GROUND_BIT, OBSTACLE_BIT = 1, 2, 4
FLOOR_Z_M = -0.4  # the arm stands on a pedestal: UR arms hang below their base plane at q = 0
_COLOURS = ("0.3 0.5 0.8 1", "0.8 0.8 0.8 1", "0.3 0.5 0.8 1", "0.8 0.8 0.8 1", "0.3 0.5 0.8 1")


@dataclass(frozen=True)
class PlantOptions:
    """How the simulated plant differs from the nominal model (all zero = identical).

    Attributes:
        damping: joint viscous damping per joint [N m s/rad].
        frictionloss: joint Coulomb friction per joint [N m].
        armature: rotor armature (reflected inertia) per joint [kg m^2], added to the
            spec's own ``armature`` (which the nominal model has too).
        payload_kg: point-like mass at the flange [kg].
    """

    damping: tuple[float, ...] = ()
    frictionloss: tuple[float, ...] = ()
    armature: tuple[float, ...] = ()
    payload_kg: float = 0.0


BOUND_SUFFIX = "__bound"
"""Name suffix of the capsule enclosing an obstacle box in collision-checking models."""


def bounding_capsule(box: Box) -> tuple[tuple[float, ...], tuple[float, ...], float]:
    """A capsule containing ``box``: (segment start, segment end, radius [m]).

    The segment runs along the box's longest axis between its face centres; every
    point of the box is within the norm of the two other half extents of it.
    """
    half = np.asarray(box.half_size, dtype=np.float64)
    axis = int(np.argmax(half))
    offset = np.zeros(3)
    offset[axis] = half[axis]
    centre = np.asarray(box.center, dtype=np.float64)
    radius = float(np.linalg.norm(np.delete(half, axis)))
    return tuple((centre - offset).tolist()), tuple((centre + offset).tolist()), radius


def _v(xs: Sequence[float] | np.ndarray) -> str:
    return " ".join(repr(float(x)) for x in xs)


def _expand_to_dof(values: tuple[float, ...], dof: int, what: str) -> list[float]:
    if not values:
        return [0.0] * dof
    if len(values) == 1:
        return [values[0]] * dof
    if len(values) != dof:
        raise ModelError(f"plant.{what}: expected 1 or {dof} values, got {len(values)}")
    return list(values)


def _stiff_friction(timestep_s: float) -> str:
    """Joint attributes that make ``frictionloss`` stick.

    MuJoCo's friction loss is a soft constraint: it delivers a fraction d of the force
    that would stop the joint (``solimpfriction``, default 0.9) and relaxes towards rest
    with a time constant (``solreffriction``, default 0.02 s). A joint held below its
    friction torque then creeps at about ``(1 - d) tau / M x timeconst / 2`` (mrad/s on
    the UR5) instead of sticking. d = ``FRICTION_IMPEDANCE`` and the smallest time
    constant MuJoCo keeps stable (2 physics steps) make it stick-slip Coulomb friction:
    creep below 1e-6 rad/s at a 1 ms step, while a sliding joint feels the full
    ``frictionloss`` (+ viscous ``damping``), as before (tests/model/test_friction.py).
    """
    d = FRICTION_IMPEDANCE
    return f' solreffriction="{2 * timestep_s!r} 1" solimpfriction="{d!r} {d!r} 0.001 0.5 2"'


def build_mjcf(
    spec: RobotSpec,
    *,
    timestep_s: float = 0.001,
    plant: PlantOptions | None = None,
    obstacles: Sequence[Box] = (),
    excluded_pairs: Sequence[tuple[str, str]] | None = None,
    obstacle_bounds: bool = False,
    integrator: str = PLANT_INTEGRATOR,
    exclude_adjacent: bool = True,
) -> str:
    """MJCF text for the robot on a pedestal, floor at ``FLOOR_Z_M``.

    The parent and child of every joint (:attr:`RobotSpec.adjacent_pairs`, the base and
    the first link included) are always excluded from collision. Beyond them: the SRDF's
    disabled pairs, else the link pairs that touch in the zero pose (e.g. the two links
    either side of a spherical wrist), as MoveIt Setup Assistant disables "default"
    collisions; pass ``excluded_pairs`` to override those (and ``exclude_adjacent=False``
    for no exclusion at all: the collision matrix's model).

    With ``obstacle_bounds`` (collision checking, not the plant) each box leaves
    MuJoCo's collision pipeline (contype = conaffinity = 0; it stays in the model
    for ``mj_geomDistance``) and a capsule that encloses it takes its place, named
    ``<box>`` + ``BOUND_SUFFIX``: capsule pairs are exact within the margin, while
    MuJoCo's capsule–box collider misses pairs there (google-deepmind/mujoco#1473).

    ``integrator`` is MuJoCo's (``PLANT_INTEGRATOR``: RK4; "Euler" is semi-implicit Euler
    with implicit joint damping).

    A kinematics-only robot gets geometry-derived inertias (density 1000)
    so the model still compiles and steps; simulation code calls
    ``spec.require_dynamics`` first and refuses it.
    """
    plant = plant or PlantOptions()
    links = chain(spec)
    damping = _expand_to_dof(plant.damping, spec.dof, "damping")
    friction = _expand_to_dof(plant.frictionloss, spec.dof, "frictionloss")
    armature = [
        j.armature + extra
        for j, extra in zip(
            spec.joints, _expand_to_dof(plant.armature, spec.dof, "armature"), strict=True
        )
    ]
    out = [
        f"<mujoco model={quoteattr(spec.name)}>",
        '  <compiler angle="radian" autolimits="true" inertiafromgeom="auto"/>',
        f'  <option timestep="{timestep_s!r}" integrator="{integrator}"/>',
        '  <visual><global offwidth="1280" offheight="960"/></visual>',
        "  <worldbody>",
        f'    <geom name="ground" type="plane" pos="0 0 {FLOOR_Z_M!r}" size="3 3 0.05" '
        f'rgba="0.9 0.9 0.9 1" contype="{GROUND_BIT}" conaffinity="0"/>',
        f'    <geom name="pedestal" type="cylinder" fromto="0 0 {FLOOR_Z_M!r} 0 0 -0.02" '
        f'size="0.08" rgba="0.4 0.4 0.4 1" contype="{GROUND_BIT}" conaffinity="0"/>',
    ]
    box_bit = 0 if obstacle_bounds else OBSTACLE_BIT
    for box in obstacles:
        out.append(
            f'    <geom name={quoteattr(box.name)} type="box" pos="{_v(box.center)}" '
            f'size="{_v(box.half_size)}" rgba="0.8 0.3 0.3 0.6" contype="{box_bit}" '
            'conaffinity="0"/>'
        )
        if obstacle_bounds:
            a, b, radius = bounding_capsule(box)
            out.append(
                f'    <geom name={quoteattr(box.name + BOUND_SUFFIX)} type="capsule" '
                f'fromto="{_v(a + b)}" size="{radius!r}" rgba="0 0 0 0" group="5" '
                f'contype="{OBSTACLE_BIT}" conaffinity="0"/>'
            )
    out.append(f"    <body name={quoteattr(spec.base_link)}>")
    meshes: dict[tuple[str, str], str] = {}
    base_geoms = _shape_geoms(spec.base_shapes, spec.base_link, ROBOT_BIT, 0, meshes)
    out.extend(f"      {g}" for g in base_geoms)
    out.extend(_frame_sites(spec, spec.base_link, "      "))
    indent = "    "
    for i, (joint, link) in enumerate(zip(spec.joints, links, strict=True)):
        indent += "  "
        rel = link.pre @ link.post
        quat = tf.quat_wxyz(rel[:3, :3])
        inv_post = tf.inverse(link.post)
        axis = inv_post[:3, :3] @ link.axis
        anchor = inv_post[:3, 3]
        lim = joint.limits
        kind = "slide" if joint.kind == "prismatic" else "hinge"
        out.append(
            f"{indent}<body name={quoteattr(joint.link_name)} "
            f'pos="{_v(rel[:3, 3])}" quat="{_v(quat)}">'
        )
        out.append(
            f'{indent}  <joint name={quoteattr(joint.name)} type="{kind}" pos="{_v(anchor)}" '
            f'axis="{_v(axis)}" range="{lim.lower!r} {lim.upper!r}" '
            f'damping="{damping[i]!r}" frictionloss="{friction[i]!r}" armature="{armature[i]!r}"'
            + (_stiff_friction(timestep_s) if friction[i] > 0 else "")
            + "/>"
        )
        if joint.inertial is not None:
            inn = joint.inertial
            t = inn.inertia
            full = (t[0][0], t[1][1], t[2][2], t[0][1], t[0][2], t[1][2])
            out.append(
                f'{indent}  <inertial pos="{_v(inn.com)}" mass="{inn.mass!r}" '
                f'fullinertia="{_v(full)}"/>'
            )
        affinity = ROBOT_BIT | OBSTACLE_BIT | (GROUND_BIT if i > 0 else 0)
        rgba = _COLOURS[i % len(_COLOURS)]
        if joint.shapes:
            geoms = _shape_geoms(joint.shapes, joint.link_name, ROBOT_BIT, affinity, meshes)
            out.extend(f"{indent}  {g}" for g in geoms)
            out.extend(_frame_sites(spec, joint.link_name, f"{indent}  "))
            continue
        for k, seg in enumerate(link.segments):
            out.append(
                f"{indent}  <geom name={quoteattr(f'{joint.link_name}_c{k}')} "
                'type="capsule" '
                f'fromto="{_v(seg.start + seg.end)}" size="{seg.radius!r}" rgba="{rgba}" '
                f'contype="{ROBOT_BIT}" conaffinity="{affinity}"/>'
            )
        if not link.segments:
            out.append(
                f"{indent}  <geom name={quoteattr(joint.link_name + '_c0')} "
                'type="sphere" '
                f'size="{joint.collision_radius!r}" rgba="{rgba}" contype="{ROBOT_BIT}" '
                f'conaffinity="{affinity}"/>'
            )
        out.extend(_frame_sites(spec, joint.link_name, f"{indent}  "))
    out.append(
        f'{indent}  <site name="{FLANGE}" {_site_pose(spec.flange)} size="0.01" rgba="1 0.5 0 1"/>'
    )
    if plant.payload_kg > 0:
        # a small dense sphere: its own inertia is negligible against the arm's
        r = 0.02
        at_flange = "" if spec.flange == IDENTITY else f" {_site_pose(spec.flange)}"
        i_sph = 0.4 * plant.payload_kg * r * r
        out.append(
            f'{indent}  <body name="payload"{at_flange}><inertial pos="0 0 0" '
            f'mass="{plant.payload_kg!r}" '
            f'diaginertia="{i_sph!r} {i_sph!r} {i_sph!r}"/></body>'
        )
    for _ in spec.joints:
        out.append(f"{indent}</body>")
        indent = indent[:-2]
    out.append("    </body>")
    out.append("  </worldbody>")
    if meshes:
        out.insert(4, "  <asset>")
        out[5:5] = [
            f"    <mesh name={quoteattr(name)} file={quoteattr(file)}{scale}/>"
            for (file, scale), name in meshes.items()
        ] + ["  </asset>"]
    if excluded_pairs is not None:
        chosen: Sequence[tuple[str, str]] = excluded_pairs
    elif spec.disabled_pairs is not None:
        chosen = spec.disabled_pairs
    else:
        chosen = default_collision_pairs(spec)
    # a joint's parent and child never collide: MuJoCo skips them itself (filterparent)
    # except where the parent is welded to the world, as the base is
    adjacent = spec.adjacent_pairs if exclude_adjacent else ()
    pairs = sorted({*(tuple(sorted(p)) for p in chosen), *adjacent})
    if pairs:
        out.append("  <contact>")
        out.extend(f"    <exclude body1={quoteattr(a)} body2={quoteattr(b)}/>" for a, b in pairs)
        out.append("  </contact>")
    out.append("  <actuator>")
    for joint in spec.joints:
        e = joint.limits.effort
        out.append(
            f"    <motor name={quoteattr(joint.name + '_motor')} joint={quoteattr(joint.name)} "
            f'ctrlrange="{-e!r} {e!r}" gear="1"/>'
        )
    out.append("  </actuator>")
    out.append("</mujoco>")
    return "\n".join(out) + "\n"


def _site_pose(pose: Pose) -> str:
    if pose == IDENTITY:
        return 'pos="0 0 0"'
    t = pose_matrix(pose)
    return f'pos="{_v(t[:3, 3])}" quat="{_v(tf.quat_wxyz(t[:3, :3]))}"'


def _frame_sites(spec: RobotSpec, link: str, indent: str) -> list[str]:
    """Sites of the named frames fixed to ``link`` (merged fixed links, TCPs)."""
    return [
        f'{indent}<site name={quoteattr(f.name)} {_site_pose(f.pose)} size="0.005" '
        'rgba="0 0 0 0" group="5"/>'
        for f in spec.frames
        if f.link == link and f.name != FLANGE
    ]


def _shape_geoms(
    shapes: Sequence[Shape],
    link: str,
    contype: int,
    affinity: int,
    meshes: dict[tuple[str, str], str],
) -> list[str]:
    """Geoms of a link's own collision shapes: primitives as primitives, meshes as convex
    meshes (MuJoCo collides a mesh as its convex hull); ``meshes`` gathers the assets."""
    out = []
    for k, shape in enumerate(shapes):
        t = pose_matrix(shape.pose)
        pose = f'pos="{_v(t[:3, 3])}" quat="{_v(tf.quat_wxyz(t[:3, :3]))}"'
        name = quoteattr(f"{link}_c{k}")
        common = f'rgba="0.7 0.7 0.75 1" contype="{contype}" conaffinity="{affinity}"'
        if shape.kind == "mesh":
            scale = "" if shape.size == (1.0, 1.0, 1.0) else f' scale="{_v(shape.size)}"'
            mesh = meshes.setdefault((shape.mesh, scale), f"{link}_m{k}")
            out.append(f'<geom name={name} type="mesh" mesh={quoteattr(mesh)} {pose} {common}/>')
            continue
        out.append(
            f'<geom name={name} type="{shape.kind}" size="{_v(shape.size)}" {pose} {common}/>'
        )
    return out


@functools.lru_cache(maxsize=32)
def default_collision_pairs(spec: RobotSpec) -> tuple[tuple[str, str], ...]:
    """Robot link pairs in contact at q = 0 (always-touching geometry, not a real collision)."""
    model = mujoco.MjModel.from_xml_string(build_mjcf(spec, excluded_pairs=()))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pairs = set()
    for c in data.contact[: data.ncon]:
        b1, b2 = model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]
        if b1 > 0 and b2 > 0 and model.body_parentid[b1] != 0 and model.body_parentid[b2] != 0:
            names = sorted((model.body(b1).name, model.body(b2).name))
            if spec.base_link not in names:
                pairs.add((names[0], names[1]))
    return tuple(sorted(pairs))


def build_mujoco_model(
    spec: RobotSpec,
    *,
    timestep_s: float = 0.001,
    plant: PlantOptions | None = None,
    obstacles: Sequence[Box] = (),
    obstacle_bounds: bool = False,
    integrator: str = PLANT_INTEGRATOR,
) -> mujoco.MjModel:
    """Compile the spec into an ``MjModel`` with auto-reset on divergence disabled
    (``obstacle_bounds``, ``integrator``: see ``build_mjcf``).

    Compiled models are cached per process (``compiled_model``), so the episodes of
    a campaign in one worker compile each plant and checker once; every call gets
    its own copy (~0.2 ms instead of ~8 ms), free to modify.
    """
    return copy.copy(
        compiled_model(
            spec,
            timestep_s=float(timestep_s),
            plant=plant or PlantOptions(),
            obstacles=tuple(obstacles),
            obstacle_bounds=bool(obstacle_bounds),
            integrator=str(integrator),
        )
    )


@functools.lru_cache(maxsize=64)
def compiled_model(
    spec: RobotSpec,
    *,
    timestep_s: float,
    plant: PlantOptions,
    obstacles: tuple[Box, ...],
    obstacle_bounds: bool,
    integrator: str = PLANT_INTEGRATOR,
) -> mujoco.MjModel:
    """The cached compile behind ``build_mujoco_model`` (do not modify the result: copy it)."""
    xml = build_mjcf(
        spec,
        timestep_s=timestep_s,
        plant=plant,
        obstacles=obstacles,
        obstacle_bounds=obstacle_bounds,
        integrator=integrator,
    )
    try:
        model = mujoco.MjModel.from_xml_string(xml)
    except ValueError as err:
        raise ModelError(f"{spec.source}: MuJoCo rejected the generated model: {err}") from err
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    return model
