# long: one format parsed, checked and walked into a spec (links, joints, tree, merge)
"""The URDF loader (+ SRDF, + a small settings sidecar): a URDF robot as a :class:`RobotSpec`.

The controlled joints are the chain from the root link to a tip link: the single leaf chain
by default (with several, ``tip:`` is required and the error lists them). Every other
movable joint (gripper fingers, mimic joints) is locked at a stated configuration (default:
the URDF's zero) and merged, as fixed joints are, into the link it hangs from: its mass
counts, its frame stays addressable (:attr:`RobotSpec.frames`). ``package://NAME/...``
resolves through :func:`pipeline.robots.spec.package_search_path`.

A URDF carries no armature or acceleration limits: they come from the settings sidecar
``<stem>.armlab.yaml`` next to the URDF (or a sidecar loaded as the robot file, naming its
``urdf:``), else documented defaults, and the spec says where each came from
(:attr:`RobotSpec.settings_sources`). Joint friction (viscous ``damping``, Coulomb
``frictionloss``) is the sidecar's where it states it, else the URDF's
``<dynamics damping friction>``, else 0; a scenario's ``plant`` overrides both.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np

from pipeline import transforms as tf
from pipeline.errors import SpecError
from pipeline.robots import caps
from pipeline.robots.link_facts import check_physical, link_capsules, merged_inertial
from pipeline.robots.packages import package_search_path
from pipeline.robots.sidecar import (
    SIDECAR_SUFFIX,
    joint_default,
    per_joint,
    read_sidecar,
    validate_sidecar,
)
from pipeline.robots.spec import (
    Frame,
    JointLimits,
    JointSpec,
    RobotSpec,
    Shape,
    as_pose,
)

__all__ = [
    "load_sidecar",
    "load_urdf",
    "resolve_uri",
    "urdf_geometry",
    "xml_floats",
    "xml_origin",
]

MOVABLE = ("revolute", "continuous", "prismatic")
MESH_SUFFIXES = (".stl", ".obj")  # what MuJoCo reads as a collision mesh
CONTINUOUS_RANGE_RAD = 2 * math.pi
MAX_MIMIC_MULTIPLIER = 1e3
PLACEHOLDER_M2 = 1e-9
"""A link stating less than ``caps.MIN_MASS_KG`` and no inertia entry above this
[kg m^2] is read as a massless frame (a simulator's placeholder mass); one with more
inertia is refused as out of range."""
F64 = np.ndarray


@dataclass
class _Link:
    name: str
    mass: float = 0.0
    com: F64 = field(default_factory=lambda: np.zeros(3))
    inertia: F64 = field(default_factory=lambda: np.zeros((3, 3)))  # about com, link axes
    shapes: list[tuple[str, F64, tuple[float, ...], str]] = field(default_factory=list)
    unphysical: str = ""  # why its inertial is not a rigid body's ("": it is)


@dataclass
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: F64
    axis: tuple[float, float, float]
    limit: dict[str, float] | None
    mimic: tuple[str, float, float] | None
    damping: float | None  # <dynamics damping> [N m s/rad], None: not stated
    friction: float | None  # <dynamics friction> [N m], None: not stated


def xml_floats(text: str | None, n: int, where: str, default: str) -> tuple[float, ...]:
    """``n`` finite numbers from a URDF attribute (``default`` when it is absent).

    Raises:
        SpecError: another count or a non-finite value, naming ``where`` and the text.
    """
    raw = (text if text is not None else default).split()
    try:
        values = tuple(float(v) for v in raw)
    except ValueError:
        values = ()
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise SpecError(f"{where}: expected {n} finite numbers, got {text!r}")
    return values


def xml_origin(el: ElementTree.Element | None, where: str) -> F64:
    """A URDF ``<origin xyz rpy>`` as a 4x4 transform (identity when absent).

    Raises:
        SpecError: a malformed ``xyz`` or ``rpy`` (as :func:`xml_floats`).
    """
    if el is None:
        return np.eye(4)
    x, y, z = xml_floats(el.get("xyz"), 3, f"{where}.origin.xyz", "0 0 0")
    caps.check_origin((x, y, z), f"{where}.origin.xyz: {el.get('xyz')!r}")
    r, p, yaw = xml_floats(el.get("rpy"), 3, f"{where}.origin.rpy", "0 0 0")
    out = np.eye(4)
    out[:3, :3] = tf.rpy_to_matrix(r, p, yaw)
    out[:3, 3] = (x, y, z)
    return out


def resolve_uri(uri: str, *, base: Path, where: str, package_path: tuple[str, ...]) -> Path:
    """A URDF file reference as a path: ``package://NAME/rest`` through the search path,
    ``file://`` and relative paths from ``base`` (the URDF's folder).

    A ``package://`` path that leaves its package through ``..`` is refused: a robot file
    names files of its own package, never others on the machine.

    Raises:
        SpecError: an unresolved package (named, with the folders searched), or a path
            leaving its package.
    """
    if uri.startswith("package://"):
        package, _, rest = uri.removeprefix("package://").partition("/")
        inside = os.path.normpath(rest or ".")
        if os.path.isabs(rest) or inside == ".." or inside.startswith("../"):
            raise SpecError(f"{where}: {uri!r} leaves the package '{package}'")
        folders = package_search_path(package_path)
        for folder in folders:
            for root in (folder / package, folder if folder.name == package else None):
                if root is not None and root.is_dir():
                    return root / rest
        searched = ", ".join(str(f) for f in folders) or "no folders"
        if package == "example-robot-data":
            raise SpecError(
                f"{where}: unresolved package 'example-robot-data' in {uri!r}: install it "
                "(pip install example-robot-data, or the test extra) or add its share folder "
                "with --package-path"
            )
        raise SpecError(
            f"{where}: unresolved package '{package}' in {uri!r} (searched {searched}; add its "
            "parent folder with --package-path or ROS_PACKAGE_PATH)"
        )
    path = Path(uri.removeprefix("file://")).expanduser()
    return path if path.is_absolute() else base / path


def _inertia(el: ElementTree.Element, where: str) -> F64:
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    v = {k: xml_floats(el.get(k), 1, f"{where}.inertia.{k}", "0")[0] for k in keys}
    return np.array(
        [
            [v["ixx"], v["ixy"], v["ixz"]],
            [v["ixy"], v["iyy"], v["iyz"]],
            [v["ixz"], v["iyz"], v["izz"]],
        ]
    )


def _parse_links(
    root: ElementTree.Element, source: str, base: Path, package_path: tuple[str, ...]
) -> dict[str, _Link]:
    links: dict[str, _Link] = {}
    elements = root.findall("link")
    caps.check_count(len(elements), caps.MAX_LINKS, "links", source)
    for el in elements:
        name = el.get("name")
        if not name:
            raise SpecError(f"{source}: a <link> without a name")
        if name in links:
            raise SpecError(f"{source}: duplicate link name '{name}'")
        where = f"{source}: link '{name}'"
        link = _Link(name)
        inertial = el.find("inertial")
        if inertial is not None:
            mass_el = inertial.find("mass")
            mass = xml_floats(mass_el.get("value") if mass_el is not None else None, 1,
                           f"{where}.mass", "0")[0]  # fmt: skip
            frame = xml_origin(inertial.find("origin"), where)
            inertia_el = inertial.find("inertia")
            tensor = _inertia(inertia_el, where) if inertia_el is not None else np.zeros((3, 3))
            if 0.0 < mass < caps.MIN_MASS_KG and float(np.abs(tensor).max()) <= PLACEHOLDER_M2:
                # Gazebo wants every link to have mass, so a frame link often says 1e-9 kg
                # (SO-101's gripper_frame_link): a massless frame, not a body to simulate
                mass, tensor = 0.0, np.zeros((3, 3))
            caps.check_mass(mass, where)
            caps.check_inertia(tensor, where)
            try:
                check_physical(mass, tensor, where)
            except SpecError as err:  # refused in load_urdf if the link moves with the arm
                link.unphysical = str(err)
            rot = frame[:3, :3]
            link.mass, link.com, link.inertia = mass, frame[:3, 3].copy(), rot @ tensor @ rot.T
        # visuals are not read here: kinematics, dynamics and planning never need them, and
        # the views that draw them (.rrd, teach) resolve them on their own, falling back to
        # the collision shapes (link_geometry), so a missing visual mesh stops nothing
        for k, geo in enumerate(el.findall("collision")):
            shape = _shape(geo, f"{where}.collision[{k}]", base, package_path)
            if shape is not None:
                if shape[0] == "mesh" and Path(shape[3]).suffix.lower() in MESH_SUFFIXES:
                    caps.check_mesh(Path(shape[3]), f"{where}.collision[{k}]")
                link.shapes.append(shape)
        links[name] = link
    return links


def urdf_geometry(
    g: ElementTree.Element, where: str, *, base: Path, package_path: tuple[str, ...]
) -> tuple[str, tuple[float, ...], str] | None:
    """A ``<geometry>``'s shape element in URDF's own terms: ``(kind, size, mesh path)``
    with size = mesh scale, box full extents, sphere ``(radius,)`` or cylinder
    ``(radius, length)`` [m]; the mesh's absolute path ("" for a primitive). None for an
    element URDF does not define.

    Raises:
        SpecError: an unresolved ``package://``, a missing mesh or a bad number (one line).
    """
    if g.tag == "mesh":
        uri = g.get("filename") or ""
        path = resolve_uri(uri, base=base, where=where, package_path=package_path)
        if not uri.startswith("package://"):
            caps.check_inside_robot_folder(uri, path, base, where)
        if not path.is_file():
            raise SpecError(f"{where}: missing mesh {uri!r} ({path})")
        scale = xml_floats(g.get("scale"), 3, f"{where}.mesh.scale", "1 1 1")
        return ("mesh", scale, str(path.resolve()))
    if g.tag == "box":
        return ("box", xml_floats(g.get("size"), 3, f"{where}.box.size", ""), "")
    if g.tag == "sphere":
        return ("sphere", xml_floats(g.get("radius"), 1, f"{where}.sphere.radius", ""), "")
    if g.tag == "cylinder":
        r = xml_floats(g.get("radius"), 1, f"{where}.cylinder.radius", "")[0]
        length = xml_floats(g.get("length"), 1, f"{where}.cylinder.length", "")[0]
        return ("cylinder", (r, length), "")
    return None


def _shape(
    el: ElementTree.Element, where: str, base: Path, package_path: tuple[str, ...]
) -> tuple[str, F64, tuple[float, ...], str] | None:
    """A collision element as the model builders take it: box and cylinder by half sizes."""
    geometry = el.find("geometry")
    pose = xml_origin(el.find("origin"), where)
    if geometry is None or len(geometry) == 0:
        raise SpecError(f"{where}: no <geometry>")
    parsed = urdf_geometry(geometry[0], where, base=base, package_path=package_path)
    if parsed is None:
        raise SpecError(f"{where}: unknown geometry <{geometry[0].tag}>")
    kind, size, mesh = parsed
    if kind == "box":
        size = tuple(0.5 * s for s in size)
    elif kind == "cylinder":
        size = (size[0], 0.5 * size[1])
    return (kind, pose, size, mesh)


def _parse_joints(root: ElementTree.Element, source: str, links: dict[str, _Link]) -> list[_Joint]:
    joints: list[_Joint] = []
    elements = root.findall("joint")
    movable = sum(el.get("type") in MOVABLE for el in elements)
    caps.check_count(movable, caps.MAX_JOINTS, "movable joints", source)
    seen: set[str] = set()
    for el in elements:
        name = el.get("name") or "?"
        where = f"{source}: joint '{name}'"
        if name in seen:
            raise SpecError(f"{source}: duplicate joint name '{name}'")
        seen.add(name)
        kind = el.get("type") or ""
        if kind in ("floating", "planar"):
            raise SpecError(f"{where}: type '{kind}' (a floating base): only fixed-base arms")
        if kind not in (*MOVABLE, "fixed"):
            raise SpecError(f"{where}: unknown type {kind!r}; valid: {', '.join(MOVABLE)}, fixed")
        parent_el, child_el = el.find("parent"), el.find("child")
        parent = parent_el.get("link") if parent_el is not None else None
        child = child_el.get("link") if child_el is not None else None
        for role, link in (("parent", parent), ("child", child)):
            if link not in links:
                raise SpecError(f"{where}: {role} link {link!r} is not a <link> of the file")
        assert parent is not None and child is not None
        axis_el = el.find("axis")
        ax = xml_floats(axis_el.get("xyz") if axis_el is not None else None, 3, f"{where}.axis",
                     "1 0 0")  # fmt: skip
        norm = math.sqrt(sum(a * a for a in ax))
        if kind in MOVABLE and norm == 0.0:
            raise SpecError(f"{where}: axis (0 0 0)")
        axis = (ax[0] / norm, ax[1] / norm, ax[2] / norm) if norm else (1.0, 0.0, 0.0)
        limit_el = el.find("limit") if kind in MOVABLE else None  # (a fixed joint's: unused)
        limit = None
        if limit_el is not None:
            limit = {
                k: xml_floats(limit_el.get(k), 1, f"{where}.limit.{k}", "nan")[0]
                if limit_el.get(k) is not None
                else math.nan
                for k in ("lower", "upper", "velocity", "effort")
            }
            # the range here; speed and effort where they are used, on the arm's joints
            # (a locked head's "velocity=10000", Baxter's, moves nothing)
            caps.check_limit(limit, kind, where, keys=("lower", "upper"))
        mimic_el = el.find("mimic")
        mimic = None
        if mimic_el is not None:
            mimic = (
                mimic_el.get("joint") or "",
                xml_floats(mimic_el.get("multiplier"), 1, f"{where}.mimic.multiplier", "1")[0],
                xml_floats(mimic_el.get("offset"), 1, f"{where}.mimic.offset", "0")[0],
            )
            if abs(mimic[1]) > MAX_MIMIC_MULTIPLIER or abs(mimic[2]) > caps.MAX_ORIGIN_M:
                raise SpecError(
                    f"{where}.mimic: multiplier {mimic[1]!r} or offset {mimic[2]!r} out of "
                    f"range, expected |multiplier| <= {MAX_MIMIC_MULTIPLIER:g} and |offset| <= "
                    f"{caps.MAX_ORIGIN_M:g}"
                )
        dynamics_el = el.find("dynamics")
        stated = {}
        for key in ("damping", "friction"):
            text = dynamics_el.get(key) if dynamics_el is not None else None
            if text is not None:
                stated[key] = xml_floats(text, 1, f"{where}.dynamics.{key}", "")[0]
                if stated[key] < 0:
                    raise SpecError(f"{where}: dynamics {key} {stated[key]} must be >= 0")
        origin = xml_origin(el.find("origin"), where)
        joints.append(
            _Joint(
                name,
                kind,
                parent,
                child,
                origin,
                axis,
                limit,
                mimic,
                damping=stated.get("damping"),
                friction=stated.get("friction"),
            )
        )
    return joints


def _tree(
    source: str, links: dict[str, _Link], joints: list[_Joint]
) -> tuple[str, dict[str, _Joint], dict[str, list[_Joint]]]:
    """Root link, parent joint per link, child joints per link; refuses loops and forests."""
    parent_of: dict[str, _Joint] = {}
    children: dict[str, list[_Joint]] = {name: [] for name in links}
    for j in joints:
        if j.child in parent_of:
            raise SpecError(
                f"{source}: closed loop: link '{j.child}' is the child of joints "
                f"'{parent_of[j.child].name}' and '{j.name}'"
            )
        parent_of[j.child] = j
        children[j.parent].append(j)
    roots = [name for name in links if name not in parent_of]
    if len(roots) != 1:
        what = ", ".join(roots) if roots else "none (every link has a parent: a closed loop)"
        raise SpecError(f"{source}: expected one root link, found {what}")
    seen, stack = set(), [roots[0]]
    while stack:
        name = stack.pop()
        seen.add(name)
        stack.extend(j.child for j in children[name])
    if len(seen) != len(links):
        stray = sorted(set(links) - seen)
        raise SpecError(f"{source}: closed loop through links {', '.join(stray)}")
    return roots[0], parent_of, children


def _path(link: str, parent_of: dict[str, _Joint]) -> list[_Joint]:
    out = []
    while link in parent_of:
        out.append(parent_of[link])
        link = parent_of[link].parent
    return out[::-1]


def _choose_tip(
    source: str,
    tip: str | None,
    links: dict[str, _Link],
    parent_of: dict[str, _Joint],
    children: dict[str, list[_Joint]],
    locked: dict[str, float],
) -> str:
    if tip is not None:
        if tip not in links:
            raise SpecError(f"{source}: tip: no link '{tip}'; links: {', '.join(links)}")
        return tip
    ends = []
    for leaf in (name for name, kids in children.items() if not kids):
        movable = [
            j for j in _path(leaf, parent_of)
            if j.kind in MOVABLE and j.mimic is None and j.name not in locked
        ]  # fmt: skip
        if movable and movable[-1].child not in ends:
            ends.append(movable[-1].child)
    if len(ends) != 1:
        raise SpecError(
            f"{source}: several leaf chains end at links {', '.join(ends) or 'none'}: set "
            "tip: (one of them) in the sidecar, or lock the others' joints (locked:)"
        )
    return ends[0]


URDF_DYNAMICS = "URDF <dynamics>"


def load_urdf(
    path: Path, *, package_path: tuple[str, ...] = (), settings: dict[str, Any] | None = None,
    settings_source: str | None = None,
) -> RobotSpec:  # fmt: skip
    """Load a URDF (with its sidecar ``<stem>.armlab.yaml`` if there is one).

    Raises:
        SpecError: one line naming the file, the element and the value at fault.
    """
    source = str(path)
    if settings is None:
        sidecar = path.with_name(path.stem + SIDECAR_SUFFIX)
        if sidecar.is_file():
            settings_source = str(sidecar)
            settings = read_sidecar(sidecar)
    opts = validate_sidecar(settings or {}, settings_source or source)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise SpecError(f"{source}: cannot read URDF ({err})") from err
    try:
        caps.check_xml_depth(text, source)
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as err:
        raise SpecError(f"{source}: not well-formed XML ({err})") from err
    if root.tag != "robot":
        raise SpecError(f"{source}: root element <{root.tag}>, expected <robot>")
    base = path.parent
    links = _parse_links(root, source, base, package_path)
    joints = _parse_joints(root, source, links)
    root_link, parent_of, children = _tree(source, links, joints)
    if (
        root_link == "world"
        and len(children["world"]) == 1
        and children["world"][0].kind == "fixed"
    ):
        # ROS's fixed "world" link only places the robot (and MuJoCo reserves the name): the
        # base is its child, in that child's own frame
        mount = children["world"][0]
        del parent_of[mount.child]
        root_link = mount.child
    by_name = {j.name: j for j in joints}
    caps.check_mimics(source, {n: j.mimic[0] if j.mimic else None for n, j in by_name.items()})
    for name in opts.locked:
        if name not in by_name:
            raise SpecError(f"{settings_source}: locked: no joint '{name}' in {source}")
    tip = _choose_tip(source, opts.tip, links, parent_of, children, opts.locked)
    chain = [j for j in _path(tip, parent_of) if j.kind in MOVABLE]
    for j in chain:
        if j.mimic is not None:
            raise SpecError(f"{source}: joint '{j.name}' on the arm chain mimics '{j.mimic[0]}'")
    chain_names = {j.name for j in chain}

    def locked_q(j: _Joint) -> float:
        if j.mimic is not None:
            master = by_name.get(j.mimic[0])
            if master is None or master.name in chain_names:
                raise SpecError(
                    f"{source}: joint '{j.name}' mimics {j.mimic[0]!r}, not a locked joint"
                )
            return j.mimic[1] * locked_q(master) + j.mimic[2]
        return float(opts.locked.get(j.name, 0.0))

    # walk the tree: each link is rigid on an owner (the base or a chain joint's link)
    owner: dict[str, tuple[str, F64]] = {root_link: (root_link, np.eye(4))}
    chain_origin: dict[str, F64] = {}
    stack = [root_link]
    while stack:
        name = stack.pop()
        own, own_T = owner[name]
        for j in children[name]:
            if j.name in chain_names:
                chain_origin[j.name] = own_T @ j.origin
                owner[j.child] = (j.child, np.eye(4))
            else:
                motion = tf.motion(j.kind, j.axis, locked_q(j)) if j.kind in MOVABLE else np.eye(4)
                owner[j.child] = (own, own_T @ j.origin @ motion)
            stack.append(j.child)

    # merged inertials, shapes and frames per owner
    names = [j.name for j in chain]
    radius = opts.collision_radius
    mass: dict[str, list[tuple[float, F64, F64]]] = {}
    shapes: dict[str, list[Shape]] = {}
    frames = []
    for link_name, (own, own_T) in owner.items():
        link = links[link_name]
        rot = own_T[:3, :3]
        if link.unphysical and own != root_link:
            raise SpecError(link.unphysical)
        # (one rigid on the fixed base, TIAGo's antennas, never moves: its inertial acts on
        # nothing the plant simulates, and the base's mass is not used)
        if link.mass > 0 and not link.unphysical:
            com = (own_T @ np.append(link.com, 1.0))[:3]
            mass.setdefault(own, []).append((link.mass, com, rot @ link.inertia @ rot.T))
        for kind, pose, size, mesh in link.shapes:
            if kind == "mesh" and Path(mesh).suffix.lower() not in MESH_SUFFIXES:
                continue  # MuJoCo cannot read it: the link keeps its capsules
            shapes.setdefault(own, []).append(
                Shape(
                    kind=kind,  # type: ignore[arg-type]
                    pose=as_pose(own_T @ pose),
                    size=size,
                    mesh=mesh,
                    link=link_name,
                )
            )
        if own != link_name:
            frames.append(Frame(name=link_name, link=own, pose=as_pose(own_T)))
    # a tip fixed to the last chain link (SO-101's gripper_frame_link) is part of that
    # link's body, and is where the arm ends unless a flange is named: its frame
    tip_body = owner[tip][0]
    flange_name = opts.flange or (tip if tip_body != tip else None)
    if flange_name is None and any(f.name == "tool0" for f in frames):
        flange_name = "tool0"
    flange = np.eye(4)
    if flange_name is not None:
        match = [f for f in frames if f.name == flange_name and f.link == tip_body]
        if not match and flange_name != tip_body:
            raise SpecError(f"{settings_source or source}: flange: '{flange_name}' is not a "
                            f"frame fixed to the tip link '{tip_body}'")  # fmt: skip
        if match:
            flange = np.array(match[0].pose)
    frames = [f for f in frames if f.name != "tool0"]

    acceleration = per_joint(opts.acceleration, names, "acceleration", source)
    velocity = (
        None if opts.velocity is None else per_joint(opts.velocity, names, "velocity", source)
    )
    armature = per_joint(opts.armature, names, "armature", source)
    sidecar_name = settings_source or "defaults"
    damping, damping_from = joint_default(
        opts, "damping", [j.damping for j in chain], sidecar=sidecar_name, stated=URDF_DYNAMICS
    )
    friction, friction_from = joint_default(
        opts, "frictionloss", [j.friction for j in chain], sidecar=sidecar_name,
        stated=URDF_DYNAMICS,
    )  # fmt: skip
    out = []
    for i, j in enumerate(chain):
        where = f"{source}: joint '{j.name}'"
        lim = j.limit
        if lim is None or (j.kind != "continuous" and not (
            math.isfinite(lim["lower"]) and math.isfinite(lim["upper"]))):  # fmt: skip
            raise SpecError(f"{where}: a {j.kind} joint needs <limit lower upper velocity effort>")
        lower, upper = (
            (-CONTINUOUS_RANGE_RAD, CONTINUOUS_RANGE_RAD)
            if j.kind == "continuous"
            else (lim["lower"], lim["upper"])
        )
        if not lower < upper:
            raise SpecError(f"{where}: limit lower {lower} must be < upper {upper}")
        if velocity is not None:  # the sidecar's, over the URDF's
            lim = {**lim, "velocity": velocity[i]}
        caps.check_limit(lim, j.kind, where, keys=("velocity", "effort"))
        for k in ("velocity", "effort"):
            if not (math.isfinite(lim[k]) and lim[k] > 0):
                raise SpecError(f"{where}: limit {k} {lim[k]} must be > 0")
        inertial = merged_inertial(
            mass.get(j.child, []), f"{source}: link '{j.child}' (moved by '{j.name}')"
        )
        nxt = chain_origin[chain[i + 1].name] if i + 1 < len(chain) else flange
        end = nxt[:3, 3]
        out.append(
            JointSpec(
                name=j.name,
                limits=JointLimits(lower, upper, lim["velocity"], acceleration[i], lim["effort"]),
                inertial=inertial,
                collision_radius=radius,
                armature=armature[i],
                origin=as_pose(chain_origin[j.name]),
                axis=j.axis,
                kind=j.kind,  # type: ignore[arg-type]
                link=j.child,
                capsules=link_capsules(end, radius),
                shapes=tuple(shapes.get(j.child, ())),
                # reach: the joint's own offset from the previous one, the flange's on the last
                length_m=float(np.linalg.norm(chain_origin[j.name][:3, 3]))
                + (float(np.linalg.norm(flange[:3, 3])) if i + 1 == len(chain) else 0.0),
                armature_source=opts.armature_source or sidecar_name,
                damping_nm_s_rad=damping[i],
                frictionloss_nm=friction[i],
            )
        )
    if not out:
        raise SpecError(f"{source}: no movable joint between the root '{root_link}' and '{tip}'")
    spec = RobotSpec(
        name=root.get("name") or path.stem,
        convention=None,
        joints=tuple(out),
        source=source,
        base_link=root_link,
        flange=as_pose(flange),
        frames=tuple(frames),
        format="urdf",
        description=text,
        base_shapes=tuple(shapes.get(root_link, ())),
        armature_source=opts.armature_source or sidecar_name,
        settings_sources=(
            ("armature", opts.armature_source or opts.source_of("armature", sidecar_name)),
            ("acceleration", opts.source_of("acceleration", sidecar_name)),
            *((("velocity", sidecar_name),) if velocity is not None else ()),
            ("damping", damping_from),
            ("frictionloss", friction_from),
        ),
    )
    srdf = opts.srdf
    if srdf is None:
        for guess in (path.with_suffix(".srdf"), base.parent / "srdf" / (path.stem + ".srdf")):
            if guess.is_file():
                srdf = str(guess.resolve())  # (relative to the cwd, not to ``base``)
                break
    if srdf is not None:
        from pipeline.robots.srdf import apply_srdf

        srdf_path = resolve_uri(srdf, base=Path(settings_source).parent if settings_source
                                else base, where=f"{settings_source}: srdf",
                                package_path=package_path)  # fmt: skip
        spec = apply_srdf(spec, srdf_path, {n: o for n, (o, _) in owner.items()})
        pairs = f"SRDF {srdf_path}"
    else:
        # said once: the spec is loaded once per process, and the recording keeps it
        pairs = "no SRDF: adjacent links and links touching at q = 0 are not checked"
    return dataclasses.replace(
        spec, settings_sources=(*spec.settings_sources, ("collision_pairs", pairs))
    )


def load_sidecar(path: Path, *, package_path: tuple[str, ...] = ()) -> RobotSpec:
    """A settings sidecar loaded as the robot file: its ``urdf:`` with its settings."""
    data = read_sidecar(path)
    opts = validate_sidecar(data, str(path))
    if opts.urdf is None:
        raise SpecError(f"{path}: urdf: required (the URDF this sidecar describes)")
    urdf = resolve_uri(opts.urdf, base=path.parent, where=f"{path}: urdf",
                       package_path=package_path)  # fmt: skip
    if not urdf.is_file():
        raise SpecError(f"{path}: urdf: no such file {urdf}")
    return load_urdf(urdf, package_path=package_path, settings=data, settings_source=str(path))
