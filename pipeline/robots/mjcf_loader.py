"""The MJCF loader: a serial arm of hinge and slide joints from a MuJoCo XML file.

MuJoCo parses the file (``mujoco.MjModel.from_xml_path``: includes, defaults, ``<frame>``s
and angle units resolved), and the compiled bodies become the robot's links: each body's
joint, its pose in its parent, its inertial, joint range, armature, damping and
frictionloss. The controlled joints are the chain from the world to a tip body, as for a
URDF (:mod:`pipeline.robots.urdf_loader`): the single leaf chain by default, ``tip:`` in
the sidecar ``<stem>.armlab.yaml`` otherwise. Bodies without a joint, and jointed bodies
off the chain (locked at the sidecar's ``locked:`` value, else at ``qpos0``), merge into
the link they hang from; their names, and the sites, stay addressable frames.

Refused, in one line naming the file and element: a free or ball joint, a body with
several joints, an equality constraint (a closed loop or coupled joints), several leaf
chains without ``tip:``, a slide joint without a range, a joint with no stated effort
limit (``actuatorfrcrange``, or a joint actuator's ``forcerange``).

MJCF states no velocity limits: they are the sidecar's ``velocity`` or
:data:`DEFAULT_VELOCITY`, named in :attr:`RobotSpec.settings_sources` as every fact's
source is. Collision geometry: the collision boxes, spheres and cylinders; links with
meshes or capsules keep the chain's capsules for planning.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree

import mujoco
import numpy as np

from pipeline import transforms as tf
from pipeline.errors import SpecError
from pipeline.robots import caps
from pipeline.robots.link_facts import link_capsules, merged_inertial
from pipeline.robots.sidecar import (
    SIDECAR_SUFFIX,
    Sidecar,
    joint_default,
    per_joint,
    read_sidecar,
    validate_sidecar,
)
from pipeline.robots.spec import (
    Frame,
    JointKind,
    JointLimits,
    JointSpec,
    RobotSpec,
    Shape,
    as_pose,
)

__all__ = ["DEFAULT_VELOCITY", "load_mjcf"]

DEFAULT_VELOCITY = 2.0
"""Joint velocity limit where neither file nor sidecar states one [rad/s or m/s]."""
CONTINUOUS_RANGE_RAD = 2 * math.pi
NO_SRDF = "no SRDF: adjacent links and links touching at q = 0 are not checked"
BASE_LINK = "base_link"  # MuJoCo reserves "world"
F64 = np.ndarray
FREE, BALL, SLIDE = (int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL),
                     int(mujoco.mjtJoint.mjJNT_SLIDE))  # fmt: skip
_SHAPES = {
    int(mujoco.mjtGeom.mjGEOM_BOX): "box",
    int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
}


def _pose(pos: F64, quat: F64) -> F64:
    out = np.eye(4)
    out[:3, :3] = tf.quat_to_matrix(np.asarray(quat, dtype=np.float64))
    out[:3, 3] = pos
    return out


def _name(model: mujoco.MjModel, obj: mujoco.mjtObj, i: int, fallback: str) -> str:
    return mujoco.mj_id2name(model, obj, i) or f"{fallback}{i}"


def _motion(model: mujoco.MjModel, j: int, q: float) -> F64:
    """``body_T_body(q)`` of joint ``j``: a hinge turns about its axis through ``jnt_pos``."""
    axis, pos = model.jnt_axis[j], model.jnt_pos[j]
    if int(model.jnt_type[j]) == SLIDE:
        return tf.trans(*(q * axis))
    return tf.trans(*pos) @ tf.rot_axis(axis, q) @ tf.trans(*(-pos))


def _check_supported(model: mujoco.MjModel, source: str) -> None:
    if model.neq:
        name = _name(model, mujoco.mjtObj.mjOBJ_EQUALITY, 0, "#")
        kind = mujoco.mjtEq(model.eq_type[0]).name.removeprefix("mjEQ_").lower()
        raise SpecError(
            f"{source}: <equality> '{name}' ({kind}): a closed loop or coupled joints; only "
            "open serial chains load (remove it, or lock the joints it couples)"
        )
    for j in range(model.njnt):
        kind = int(model.jnt_type[j])
        if kind in (FREE, BALL):
            what = "free (a floating base)" if kind == FREE else "ball"
            raise SpecError(
                f"{source}: joint '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j, 'joint')}' is "
                f"{what}: only fixed-base arms of hinge and slide joints"
            )
        ref = float(model.qpos0[model.jnt_qposadr[j]])
        if ref != 0.0:
            raise SpecError(
                f"{source}: joint '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j, 'joint')}' has "
                f"ref {ref:g}: only joints whose reference is 0 load (turn the body's pose by "
                "ref instead)"
            )
    for b in range(1, model.nbody):
        if model.body_jntnum[b] > 1:
            raise SpecError(
                f"{source}: body '{_name(model, mujoco.mjtObj.mjOBJ_BODY, b, 'body')}' has "
                f"{model.body_jntnum[b]} joints: one joint per body"
            )


def _effort(model: mujoco.MjModel, j: int, where: str) -> float:
    """A joint's effort limit: its ``actuatorfrcrange``, else its actuators' ``forcerange``
    (or a motor's ``ctrlrange`` x gain) times the gear [N m or N]."""
    if model.jnt_actfrclimited[j]:
        return float(np.abs(model.jnt_actfrcrange[j]).max())
    found = []
    for a in range(model.nu):
        if not (
            int(model.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)
            and model.actuator_trnid[a, 0] == j
        ):
            continue
        gear = abs(float(model.actuator_gear[a, 0]))
        if model.actuator_forcelimited[a]:
            found.append(gear * float(np.abs(model.actuator_forcerange[a]).max()))
        elif (  # a motor: force = gain x ctrl, limited by its ctrlrange
            model.actuator_ctrllimited[a]
            and int(model.actuator_gaintype[a]) == int(mujoco.mjtGain.mjGAIN_FIXED)
            and int(model.actuator_biastype[a]) == int(mujoco.mjtBias.mjBIAS_NONE)
        ):
            gain = abs(float(model.actuator_gainprm[a, 0]))
            found.append(gear * gain * float(np.abs(model.actuator_ctrlrange[a]).max()))
    if not found or max(found) <= 0:
        raise SpecError(
            f"{where}: no effort limit: give the joint actuatorfrcrange (or its actuator "
            "forcerange)"
        )
    return sum(found)


def _choose_tip(
    model: mujoco.MjModel, source: str, opts: Sidecar, names: list[str], moving: set[int]
) -> int:
    """The tip body: the sidecar's ``tip:``, else the one body ending the leaf chains."""
    if opts.tip is not None:
        if opts.tip not in names:
            raise SpecError(f"{source}: tip: no body '{opts.tip}'; bodies: {', '.join(names[1:])}")
        return names.index(opts.tip)
    has_child = {int(model.body_parentid[b]) for b in range(1, model.nbody)}
    ends: list[int] = []
    for leaf in (b for b in range(1, model.nbody) if b not in has_child):
        b = leaf
        while b and b not in moving:
            b = int(model.body_parentid[b])
        if b and b not in ends:
            ends.append(b)
    if len(ends) != 1:
        listed = ", ".join(names[b] for b in ends) or "none"
        raise SpecError(
            f"{source}: several leaf chains end at bodies {listed}: set tip: (one of them) in "
            f"{Path(source).stem}{SIDECAR_SUFFIX}, or lock the others' joints (locked:)"
        )
    return ends[0]


def _check_root(path: Path) -> None:
    """Refuse an ``.xml`` that is not MJCF (a URDF saved as ``.xml`` would be imported by
    MuJoCo's own URDF parser, silently unlike our URDF loader)."""
    try:
        _, first = next(ElementTree.iterparse(path, events=("start",)))
    except (ElementTree.ParseError, StopIteration):
        return  # MuJoCo's parser names the fault
    except OSError as err:
        raise SpecError(f"{path}: cannot read it ({err.strerror or err})") from err
    if first.tag != "mujoco":
        hint = " (a URDF: name it .urdf)" if first.tag == "robot" else ""
        raise SpecError(f"{path}: root element <{first.tag}>, expected <mujoco> (MJCF){hint}")


MAX_MJCF_DEPTH = 2 * caps.MAX_JOINTS + 16
"""Element nesting of an MJCF file (one level per body of the chain, and some)."""


def _check_before_compiling(path: Path) -> None:
    """The stated caps (:mod:`pipeline.robots.caps`) on the file as written, before MuJoCo
    compiles it: nesting, joint and body counts, every ``range`` ordered (MuJoCo makes a
    joint whose lower is above its upper an unlimited one), collision meshes readable."""
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise SpecError(f"{source}: cannot read it ({err})") from err
    caps.check_xml_depth(text, source, max_depth=MAX_MJCF_DEPTH)
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError:
        return  # MuJoCo's parser names the fault
    joints = root.findall(".//worldbody//joint")
    caps.check_count(len(joints), caps.MAX_JOINTS, "joints", source)
    caps.check_count(len(root.findall(".//worldbody//body")), caps.MAX_LINKS, "bodies", source)
    for k, el in enumerate(root.iter("joint")):
        text_range = el.get("range")
        if text_range is None:
            continue
        try:
            lower, upper = (float(v) for v in text_range.split())
        except ValueError:
            continue  # MuJoCo's parser names the fault
        if lower > upper:
            name = el.get("name") or f"joint[{k}]"
            raise SpecError(
                f"{source}: joint '{name}': range lower {lower:g} is above upper {upper:g}"
            )
    compiler = root.find("compiler")
    folder = path.parent
    if compiler is not None:
        folder = folder / (compiler.get("meshdir") or compiler.get("assetdir") or "")
    for el in root.iter("mesh"):
        file = el.get("file")
        if file and (folder / file).is_file() and Path(file).suffix.lower() in (".stl", ".obj"):
            caps.check_mesh(folder / file, f"{source}: mesh '{el.get('name') or file}'")


def _check_magnitudes(model: mujoco.MjModel, source: str) -> None:
    """The compiled bodies' origins and masses, and the joints' ranges, within the caps."""
    for b in range(1, model.nbody):
        where = f"{source}: body '{_name(model, mujoco.mjtObj.mjOBJ_BODY, b, 'body')}'"
        if float(np.abs(model.body_pos[b]).max()) > caps.MAX_ORIGIN_M:
            raise SpecError(
                f"{where}: pos {model.body_pos[b].tolist()} is out of range, expected |value| "
                f"<= {caps.MAX_ORIGIN_M:g} m"
            )
        caps.check_mass(float(model.body_mass[b]), where)
    for j in range(model.njnt):
        bound = caps.MAX_ORIGIN_M if int(model.jnt_type[j]) == SLIDE else caps.MAX_JOINT_RAD
        if model.jnt_limited[j] and float(np.abs(model.jnt_range[j]).max()) > bound:
            name = _name(model, mujoco.mjtObj.mjOBJ_JOINT, j, "joint")
            raise SpecError(
                f"{source}: joint '{name}': range {model.jnt_range[j].tolist()} is out of "
                f"range, expected |value| <= {bound:.6g}"
            )


def load_mjcf(path: Path, *, package_path: tuple[str, ...] = ()) -> RobotSpec:
    """Load a serial arm from an MJCF file (with its sidecar ``<stem>.armlab.yaml`` if any).

    Args:
        package_path: unused (MJCF names files relative to itself); the loader signature.

    Raises:
        SpecError: one line naming the file and the element at fault.
    """
    source = str(path)
    sidecar_path = path.with_name(path.stem + SIDECAR_SUFFIX)
    has_sidecar = sidecar_path.is_file()
    sidecar = str(sidecar_path) if has_sidecar else "defaults"
    opts = validate_sidecar(read_sidecar(sidecar_path) if has_sidecar else {}, sidecar)
    _check_root(path)
    _check_before_compiling(path)
    try:
        model = mujoco.MjModel.from_xml_path(source)
    except ValueError as err:
        message = " ".join(str(err).split())
        raise SpecError(f"{source}: MuJoCo cannot load it ({message})") from err
    _check_supported(model, source)
    _check_magnitudes(model, source)
    names = [_name(model, mujoco.mjtObj.mjOBJ_BODY, b, "body") for b in range(model.nbody)]
    joint_of = {int(model.jnt_bodyid[j]): j for j in range(model.njnt)}
    joint_names = {
        j: _name(model, mujoco.mjtObj.mjOBJ_JOINT, j, "joint") for j in joint_of.values()
    }
    for name in opts.locked:
        if name not in joint_names.values():
            raise SpecError(f"{sidecar}: locked: no joint '{name}' in {source}")
    moving = {b for b, j in joint_of.items() if joint_names[j] not in opts.locked}
    tip = _choose_tip(model, source, opts, names, moving)
    path_bodies = []
    b = tip
    while b:
        path_bodies.append(b)
        b = int(model.body_parentid[b])
    chain = [b for b in reversed(path_bodies) if b in moving]
    if not chain:
        raise SpecError(f"{source}: no joint between the world and the tip body '{names[tip]}'")

    # the base: the world's one jointless child on the chain's path, else the world
    first = path_bodies[-1]
    root = first if first not in moving else 0
    base = names[root] if root else BASE_LINK

    # walk the tree: each body is rigid on an owner (the base or a chain body)
    owner: dict[int, tuple[int, F64]] = {root: (root, np.eye(4))}
    origin: dict[int, F64] = {}
    post: dict[int, F64] = {}
    stack = [root]
    while stack:
        parent = stack.pop()
        own, own_T = owner[parent]
        for c in (c for c in range(1, model.nbody) if model.body_parentid[c] == parent):
            parent_T_body = _pose(model.body_pos[c], model.body_quat[c])
            if c in chain:
                j = joint_of[c]
                pos = model.jnt_pos[j]
                origin[c] = own_T @ parent_T_body @ tf.trans(*pos)
                post[c] = tf.trans(*(-pos))
                owner[c] = (c, np.eye(4))
            elif c in joint_of:
                j = joint_of[c]
                q = opts.locked.get(joint_names[j], float(model.qpos0[model.jnt_qposadr[j]]))
                owner[c] = (own, own_T @ parent_T_body @ _motion(model, j, q))
            else:
                owner[c] = (own, own_T @ parent_T_body)
            stack.append(c)

    # merged inertials, collision shapes and frames per owner
    mass: dict[int, list[tuple[float, F64, F64]]] = {}
    shapes: dict[int, list[Shape]] = {}
    frames: list[Frame] = []
    for b, (own, own_T) in owner.items():
        if b and model.body_mass[b] > 0:
            inertial_T = own_T @ _pose(model.body_ipos[b], model.body_iquat[b])
            rot = inertial_T[:3, :3]
            tensor = rot @ np.diag(model.body_inertia[b]) @ rot.T
            mass.setdefault(own, []).append((float(model.body_mass[b]), inertial_T[:3, 3], tensor))
        for g in range(model.body_geomadr[b], model.body_geomadr[b] + model.body_geomnum[b]):
            kind = _SHAPES.get(int(model.geom_type[g]))
            if kind is None or not (model.geom_contype[g] or model.geom_conaffinity[g]):
                continue  # meshes, capsules, planes; visual-only geoms
            size = model.geom_size[g]
            dims = {"box": size[:3], "sphere": size[:1], "cylinder": size[:2]}[kind]
            pose = own_T @ _pose(model.geom_pos[g], model.geom_quat[g])
            shapes.setdefault(own, []).append(
                Shape(kind=kind, pose=as_pose(pose), size=tuple(float(x) for x in dims))  # type: ignore[arg-type]
            )
        if b != own and b:
            frames.append(Frame(name=names[b], link=names[own], pose=as_pose(own_T)))
    for s in range(model.nsite):
        b = int(model.site_bodyid[s])
        if b in owner:
            own, own_T = owner[b]
            pose = own_T @ _pose(model.site_pos[s], model.site_quat[s])
            site = _name(model, mujoco.mjtObj.mjOBJ_SITE, s, "site")
            frames.append(Frame(name=site, link=names[own], pose=as_pose(pose)))

    last = names[chain[-1]]
    flange_name = opts.flange or ("tool0" if any(f.name == "tool0" for f in frames) else None)
    flange = np.eye(4)
    if flange_name is not None and flange_name != last:
        match = [f for f in frames if f.name == flange_name and f.link == last]
        if not match:
            raise SpecError(
                f"{sidecar}: flange: '{flange_name}' is not a frame fixed to the last link "
                f"'{last}' of {source}"
            )
        flange = np.array(match[0].pose)
    frames = [f for f in frames if f.name != "tool0"]

    joints = [joint_of[b] for b in chain]
    jnames = [joint_names[j] for j in joints]
    dofs = [int(model.jnt_dofadr[j]) for j in joints]
    acceleration = per_joint(opts.acceleration, jnames, "acceleration", sidecar)
    velocity = per_joint(
        opts.velocity if opts.velocity is not None else DEFAULT_VELOCITY, jnames, "velocity",
        sidecar,
    )  # fmt: skip
    facts = {}
    for key, field in (("armature", "dof_armature"), ("damping", "dof_damping"),
                       ("frictionloss", "dof_frictionloss")):  # fmt: skip
        # the compiled model cannot tell a stated 0 from none: 0 is "not stated"
        stated = [float(getattr(model, field)[d]) or None for d in dofs]
        facts[key] = joint_default(opts, key, stated, sidecar=sidecar, stated=f"MJCF <joint {key}>")
    armature_source = opts.armature_source or facts["armature"][1]
    radius = opts.collision_radius
    out = []
    for i, (b, j) in enumerate(zip(chain, joints, strict=True)):
        where = f"{source}: joint '{jnames[i]}'"
        slide = int(model.jnt_type[j]) == SLIDE
        if model.jnt_limited[j]:
            lower, upper = (float(x) for x in model.jnt_range[j])
            if not lower < upper:
                raise SpecError(f"{where}: range lower {lower} must be < upper {upper}")
        elif slide:
            raise SpecError(f"{where}: a slide joint needs a range")
        else:
            lower, upper = -CONTINUOUS_RANGE_RAD, CONTINUOUS_RANGE_RAD
        nxt = origin[chain[i + 1]] if i + 1 < len(chain) else flange
        end = nxt[:3, 3]  # the next joint (or the flange) in this body's frame
        # reach: from the previous joint's point to this one's, the flange's on the last
        here = origin[b][:3, 3] - (model.jnt_pos[joints[i - 1]] if i else 0.0)
        length_m = float(np.linalg.norm(here)) + (
            float(np.linalg.norm(end - model.jnt_pos[j])) if i + 1 == len(chain) else 0.0
        )
        effort = _effort(model, j, where)
        joint_kind: JointKind = (
            "prismatic" if slide else ("revolute" if model.jnt_limited[j] else "continuous")
        )
        out.append(
            JointSpec(
                name=jnames[i],
                limits=JointLimits(lower, upper, velocity[i], acceleration[i], effort),
                inertial=merged_inertial(mass.get(b, []), f"{source}: body '{names[b]}'"),
                collision_radius=radius,
                armature=facts["armature"][0][i],
                origin=as_pose(origin[b]),
                axis=tuple(float(x) for x in model.jnt_axis[j]),  # type: ignore[arg-type]
                post=as_pose(post[b]),
                kind=joint_kind,
                link=names[b],
                capsules=link_capsules(end, radius),
                shapes=tuple(shapes.get(b, ())),
                length_m=length_m,
                armature_source=armature_source,
                damping_nm_s_rad=facts["damping"][0][i],
                frictionloss_nm=facts["frictionloss"][0][i],
            )
        )
    model_name = bytes(model.names).split(b"\0", 1)[0].decode("utf-8", "replace")
    return RobotSpec(
        name=model_name or path.stem,
        convention=None,
        joints=tuple(out),
        source=source,
        base_link=base,
        flange=as_pose(flange),
        frames=tuple(frames),
        format="mjcf",
        base_shapes=tuple(shapes.get(root, ())),
        armature_source=armature_source,
        settings_sources=(
            ("armature", armature_source),
            ("acceleration", opts.source_of("acceleration", sidecar)),
            ("velocity", sidecar if opts.velocity is not None else f"default {DEFAULT_VELOCITY:g}"),
            ("damping", facts["damping"][1]),
            ("frictionloss", facts["frictionloss"][1]),
            (
                "collision_pairs",
                "no SRDF: adjacent links and links touching at q = 0 are not checked",
            ),
        ),
    )
