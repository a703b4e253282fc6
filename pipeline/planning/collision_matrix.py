"""The disabled-collision matrix of a robot, computed the way MoveIt's Setup Assistant does,
and written as an SRDF.

Link pairs are those of the description's links with collision geometry (a URDF's
``<collision>`` elements MuJoCo reads; links merged into one body keep their own names).
A pair is disabled, in this order, as:

- ``Adjacent``: the parent and child of a joint, where a link without geometry joins its
  neighbours (so the Panda's ``panda_link7`` and ``panda_hand`` are adjacent through
  ``panda_link8``);
- ``Default``: in collision at the default configuration (each joint at 0, or mid-range
  where 0 is outside its limits);
- ``Always``: in collision in at least ``ALWAYS_FRACTION`` of the sampled configurations;
- ``Never``: in collision in none of them.

Configurations are drawn uniformly within the joint limits
(:func:`sample_configurations`). Collisions are MuJoCo's (meshes as their convex hulls,
as the planner and the plant see them) with every robot pair enabled, parent and child
included. Links rigidly joined (fixed or locked joints) never move relative to each
other: their pair is decided at the default configuration alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np
from numpy.typing import NDArray

from pipeline.errors import PipelineError, SpecError
from pipeline.fsutil import atomic_write_bytes
from pipeline.model.mjcf import build_mjcf
from pipeline.robots.link_geometry import link_edges
from pipeline.robots.spec import RobotSpec

__all__ = [
    "ALWAYS_FRACTION",
    "DEFAULT_SAMPLES",
    "CollisionMatrix",
    "DisabledPair",
    "check_out_path",
    "collision_matrix",
    "default_configuration",
    "sample_configurations",
    "srdf_text",
    "write_srdf",
]

DEFAULT_SAMPLES = 10_000  # MoveIt Setup Assistant's default sampling density
ALWAYS_FRACTION = 0.95  # MoveIt's min_collision_fraction for "Always"
Reason = Literal["Adjacent", "Default", "Always", "Never"]
F64 = NDArray[np.float64]


@dataclass(frozen=True)
class DisabledPair:
    """A link pair collision checking skips, and why (MoveIt's ``reason``)."""

    link1: str
    link2: str
    reason: Reason


@dataclass(frozen=True)
class CollisionMatrix:
    """The disabled pairs of a robot's links, and the pairs left checked.

    Attributes:
        robot: the robot's name.
        links: the links with collision geometry, sorted.
        disabled: the disabled pairs, sorted by name (``link1 < link2``).
        checked: the pairs left enabled, sorted.
        samples: configurations sampled; seed: their generator's seed.
        collision_counts: per checked or disabled pair, in how many samples it collided.
    """

    robot: str
    links: tuple[str, ...]
    disabled: tuple[DisabledPair, ...]
    checked: tuple[tuple[str, str], ...]
    samples: int
    seed: int
    collision_counts: tuple[tuple[tuple[str, str], int], ...]

    def count(self, reason: Reason) -> int:
        return sum(p.reason == reason for p in self.disabled)


def default_configuration(spec: RobotSpec) -> F64:
    """MoveIt's default state [rad, m]: 0 per joint, or mid-range where 0 is outside."""
    lower, upper = spec.lower, spec.upper
    inside = (lower <= 0.0) & (upper >= 0.0)
    out: F64 = np.where(inside, 0.0, 0.5 * (lower + upper))
    return out


def sample_configurations(spec: RobotSpec, samples: int, seed: int) -> F64:
    """The configurations the matrix samples: ``samples`` x dof, uniform within the joint
    limits, from ``numpy.random.default_rng(seed)``."""
    rng = np.random.default_rng(seed)
    out: F64 = rng.uniform(spec.lower, spec.upper, size=(samples, spec.dof))
    return out


def adjacent_links(edges: list[tuple[str, str]], links: set[str]) -> set[tuple[str, str]]:
    """Sorted pairs of ``links`` joined by a joint, where a link not in ``links`` (no
    geometry) joins every pair of its neighbours (MoveIt's connection graph)."""
    neighbours: dict[str, set[str]] = {}
    for a, b in edges:
        if a != b:
            neighbours.setdefault(a, set()).add(b)
            neighbours.setdefault(b, set()).add(a)
    for hollow in [n for n in neighbours if n not in links]:
        around = neighbours.pop(hollow)
        for n in around:
            neighbours[n].discard(hollow)
        for n in around:
            neighbours[n].update(around - {n})
    return {(min(a, b), max(a, b)) for a, near in neighbours.items() for b in near if a in links}


def _geom_links(spec: RobotSpec, model: mujoco.MjModel) -> list[str]:
    """Per geom, the description link it belongs to ("" for world geometry)."""
    shapes = {spec.base_link: spec.base_shapes, **{j.link_name: j.shapes for j in spec.joints}}
    out = []
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        if body == 0:
            out.append("")
            continue
        name = model.body(body).name
        own = shapes.get(name, ())
        k = int(model.geom(g).name.rpartition("_c")[2])
        out.append((own[k].link or name) if k < len(own) else name)
    return out


def collision_matrix(
    spec: RobotSpec,
    *,
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> CollisionMatrix:
    """Compute the robot's disabled-collision matrix (module docstring).

    Args:
        spec: the robot (with its own collision shapes).
        samples: configurations to sample (>= 1).
        seed: seed of the sampled configurations.
        progress: called with the number of configurations just checked.

    Raises:
        SpecError: a robot without collision geometry of its own.
    """
    if samples < 1:
        raise PipelineError(f"--samples {samples}: expected at least 1 configuration")
    if not spec.base_shapes and not any(j.shapes for j in spec.joints):
        raise SpecError(
            f"{spec.source}: robot '{spec.name}' has no collision geometry (no <collision> "
            "shape MuJoCo reads: box, sphere, cylinder, .stl or .obj mesh); a collision "
            "matrix needs the robot's own shapes"
        )
    model = mujoco.MjModel.from_xml_string(
        build_mjcf(spec, excluded_pairs=(), exclude_adjacent=False)
    )
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_FILTERPARENT)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_MIDPHASE)
    geom_link = _geom_links(spec, model)
    for g, link in enumerate(geom_link):
        robot = link != ""
        model.geom_contype[g] = 1 if robot else 0
        model.geom_conaffinity[g] = 1 if robot else 0
        model.geom_margin[g] = 0.0
    links = sorted({link for link in geom_link if link})
    index = {name: i for i, name in enumerate(links)}
    n = len(links)
    gid = np.array([index.get(link, -1) for link in geom_link], dtype=np.int64)
    data = mujoco.MjData(model)

    def colliding_codes() -> NDArray[np.int64]:
        """Link-pair codes (a * n + b, a < b) in penetration at the kinematics in data."""
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        ncon = int(data.ncon)
        if ncon == 0:
            return np.empty(0, dtype=np.int64)
        geoms = data.contact.geom[:ncon]
        hit = data.contact.dist[:ncon] < 0.0
        a, b = gid[geoms[hit, 0]], gid[geoms[hit, 1]]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        codes: NDArray[np.int64] = np.unique(lo * n + hi)  # geoms of one body never meet
        return codes

    reasons: dict[tuple[str, str], Reason] = {}
    for pair in sorted(adjacent_links(link_edges(spec), set(links))):
        reasons[pair] = "Adjacent"
    # the default configuration: body pairs from MuJoCo, links sharing a body by distance
    data.qpos[:] = default_configuration(spec)
    default_codes = colliding_codes()
    fromto = np.zeros(6)
    rigid: set[tuple[str, str]] = set()
    body = model.geom_bodyid
    for g1 in range(model.ngeom):
        for g2 in range(g1 + 1, model.ngeom):
            la, lb = geom_link[g1], geom_link[g2]
            if not la or not lb or la == lb or body[g1] != body[g2]:
                continue
            pair = (min(la, lb), max(la, lb))
            rigid.add(pair)
            if mujoco.mj_geomDistance(model, data, g1, g2, 0.01, fromto) < 0.0:
                reasons.setdefault(pair, "Default")
    for code in default_codes.tolist():
        reasons.setdefault((links[code // n], links[code % n]), "Default")
    counts = np.zeros(n * n, dtype=np.int64)
    batch = max(1, samples // 100)
    for k, q in enumerate(sample_configurations(spec, samples, seed)):
        data.qpos[:] = q
        counts[colliding_codes()] += 1
        if progress is not None and ((k + 1) % batch == 0 or k + 1 == samples):
            progress(batch if (k + 1) % batch == 0 else (k + 1) % batch)
    checked: list[tuple[str, str]] = []
    tallies: list[tuple[tuple[str, str], int]] = []
    for a in range(n):
        for b in range(a + 1, n):
            pair = (links[a], links[b])
            hits = int(counts[a * n + b])
            tallies.append((pair, hits))
            if pair in reasons:
                continue
            if pair in rigid:
                reasons[pair] = "Never"  # rigidly joined, apart at the default: always apart
            elif hits >= math.ceil(ALWAYS_FRACTION * samples):
                reasons[pair] = "Always"
            elif hits == 0:
                reasons[pair] = "Never"
            else:
                checked.append(pair)
    return CollisionMatrix(
        robot=spec.name,
        links=tuple(links),
        disabled=tuple(DisabledPair(a, b, r) for (a, b), r in sorted(reasons.items())),
        checked=tuple(checked),
        samples=samples,
        seed=seed,
        collision_counts=tuple(tallies),
    )


def srdf_text(matrix: CollisionMatrix) -> str:
    """The matrix as an SRDF, laid out as MoveIt's Setup Assistant writes one."""
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<!--This does not replace URDF, and is not an extension of URDF.",
        "    This is a format for representing semantic information about the robot structure.",
        "    A URDF file must exist for this robot as well, where the joints and the links "
        "that are referenced are defined",
        "-->",
        f"<robot name={quoteattr(matrix.robot)}>",
        f"    <!--DISABLE COLLISIONS: written by `pipeline robots collision-matrix` from "
        f"{matrix.samples} sampled configurations (seed {matrix.seed}); "
        f"{len(matrix.checked)} link pairs stay checked.-->",
    ]
    out.extend(
        f"    <disable_collisions link1={quoteattr(p.link1)} link2={quoteattr(p.link2)} "
        f'reason="{p.reason}"/>'
        for p in matrix.disabled
    )
    out.append("</robot>")
    return "\n".join(out) + "\n"


def write_srdf(matrix: CollisionMatrix, out: Path, *, force: bool = False) -> None:
    """Write the SRDF atomically (temp file + rename).

    Raises:
        PipelineError: ``out`` exists (without ``force``), or its folder does not.
    """
    check_out_path(out, force=force)
    atomic_write_bytes(out, srdf_text(matrix).encode("utf-8"))


def check_out_path(out: Path, *, force: bool) -> None:
    """Refuse an ``--out`` that cannot be written, before any work (one line)."""
    if out.is_dir():
        raise PipelineError(f"--out {out}: is a folder; expected an .srdf file path")
    if out.exists() and not force:
        raise PipelineError(f"--out {out}: the file exists; pass --force to overwrite it")
    if not out.parent.is_dir():
        raise PipelineError(f"--out {out}: no such folder {out.parent}")
