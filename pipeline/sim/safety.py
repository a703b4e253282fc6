"""Execution safety, post hoc: contacts and clearance along an episode's true states.

The control loop stays untouched; afterwards every (or every ``every``-th)
true joint state of the plant goes through the planner's ``CollisionChecker``
(MuJoCo's collision with the plant's own contype/conaffinity filtering and
excluded pairs), padded by ``padding_m`` so that near misses are measured
too. Per touching pair (robot–obstacle, robot–self, robot–floor/pedestal) the
result says when it first and last penetrated, in how many checked samples,
and how deep [m]; over the whole episode, the smallest clearance and where.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import SimulationError
from pipeline.model.scene import Box
from pipeline.planning.collision import CollisionChecker, reach_bound_m
from pipeline.robots.spec import RobotSpec
from pipeline.settings import KINDS, Clearance, ContactKind, ContactSpan, ExecutionSafety

FLOOR_GEOMS = ("ground", "pedestal")
"""World geometry of the scene besides obstacles (names from ``pipeline.model.mjcf``)."""
DEFAULT_PADDING_M = 0.05
SKIP_WITHIN_M = 5e-4
"""The record stage's ``skip_within_m``: clearances exact to 0.5 mm, contacts exact."""


def _kind(
    pair: tuple[str, str], obstacle_names: frozenset[str]
) -> tuple[ContactKind, tuple[str, str]]:
    """The pair's kind, and the pair ordered (robot link, world geom) unless self."""
    kind: ContactKind
    if obstacle_names.intersection(pair):
        kind, world = "obstacle", obstacle_names
    elif set(FLOOR_GEOMS).intersection(pair):
        kind, world = "floor", frozenset(FLOOR_GEOMS)
    else:
        return "self", pair
    return kind, ((pair[1], pair[0]) if pair[0] in world else pair)


def _check_inputs(
    spec: RobotSpec, q: ArrayLike, stamp_ns: ArrayLike, padding_m: float, every: int
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    qs = np.asarray(q, dtype=np.float64)
    stamps = np.asarray(stamp_ns)
    if qs.ndim != 2 or qs.shape[1] != spec.dof:
        raise SimulationError(
            f"q: expected (N, {spec.dof}) joint positions of {spec.name}, got shape {qs.shape}"
        )
    if stamps.shape != (qs.shape[0],) or not np.issubdtype(stamps.dtype, np.integer):
        raise SimulationError(
            f"stamp_ns: expected {qs.shape[0]} integer stamps [ns], got "
            f"shape {stamps.shape} of {stamps.dtype}"
        )
    if not np.isfinite(qs).all():
        row = int(np.argmax(~np.isfinite(qs).all(axis=1)))
        raise SimulationError(f"q: row {row} is not finite: {qs[row].tolist()}")
    number = isinstance(padding_m, int | float | np.integer | np.floating)
    if not (
        number and not isinstance(padding_m, bool) and math.isfinite(padding_m) and padding_m >= 0
    ):
        raise SimulationError(f"padding_m: expected a finite distance >= 0 [m], got {padding_m!r}")
    if not (isinstance(every, int | np.integer) and not isinstance(every, bool) and every >= 1):
        raise SimulationError(f"every: expected an integer >= 1, got {every!r}")
    return qs, stamps.astype(np.int64)


def assess_execution(
    spec: RobotSpec,
    *,
    q: ArrayLike,
    stamp_ns: ArrayLike,
    obstacles: Sequence[Box],
    padding_m: float = DEFAULT_PADDING_M,
    every: int = 1,
    skip_within_m: float = 0.0,
) -> ExecutionSafety:
    """Contacts and the minimum clearance along true joint states.

    Args:
        spec: the robot.
        q: (N, n) true joint positions of the plant [rad] (``EpisodeResult.q_true``).
        stamp_ns: (N,) their stamps [ns].
        obstacles: the boxes the episode ran with.
        padding_m: measure clearances below this [m]; farther pairs cost nothing.
        every: check every ``every``-th row (the last row is always checked).
        skip_within_m: skip rows that provably differ from the last checked row by less
            than this in every pair's distance [m] (0: check them all). Along the rows
            no point of the arm moves more than ``reach_bound_m`` times the joint-space
            path length, so a row is skipped only while that bound stays below
            ``min(skip_within_m, d)``, ``d`` being the checked row's smallest distance:
            a skipped row is contact-free, every contact row is checked (so contact
            spans, sample counts and depths are exact), and the clearances are exact
            to within ``skip_within_m``. Settled phases (pre-roll, hold) then cost a
            few checks instead of one per row.

    Raises:
        SimulationError: shapes, non-finite positions, a bad padding or step.
    """
    qs, stamps = _check_inputs(spec, q, stamp_ns, padding_m, every)
    if not (
        isinstance(skip_within_m, int | float | np.floating)
        and math.isfinite(skip_within_m)
        and skip_within_m >= 0
    ):
        raise SimulationError(
            f"skip_within_m: expected a finite distance >= 0 [m], got {skip_within_m!r}"
        )
    checker = CollisionChecker(spec, obstacles=obstacles, padding_m=float(padding_m))
    rows = np.arange(0, len(qs), every)
    if len(qs) and rows[-1] != len(qs) - 1:
        rows = np.append(rows, len(qs) - 1)
    rows, row_of, geom_pairs, dists = _collide_rows(
        checker, qs, rows, skip_within_m=float(skip_within_m), reach_m_per_rad=reach_bound_m(spec)
    )
    labels = checker.geom_labels
    obstacle_names = frozenset(b.name for b in obstacles)
    # one id per unordered pair of labels (robot links are labelled by body, so a
    # link's several capsules make one pair); a link pair's kind and name, once
    names = sorted(set(labels))
    lab = np.array([names.index(name) for name in labels], dtype=np.int64)
    la, lb = lab[geom_pairs[:, 0]], lab[geom_pairs[:, 1]]
    lo, hi = np.minimum(la, lb), np.maximum(la, lb)
    pair_id = lo * len(names) + hi
    unique_ids, first = np.unique(pair_id, return_index=True)
    kind_of = {
        pid: _kind((names[lo[i]], names[hi[i]]), obstacle_names)
        for pid, i in zip(unique_ids.tolist(), first.tolist(), strict=True)
    }

    spans = []
    inside = np.flatnonzero(dists < 0.0)
    for pid in np.unique(pair_id[inside]).tolist():
        idx = inside[pair_id[inside] == pid]
        deepest = idx[int(np.argmin(dists[idx]))]
        hit_rows = np.unique(row_of[idx])  # a pair may have several contacts per row
        kind, bodies = kind_of[pid]
        spans.append(
            ContactSpan(
                bodies=bodies,
                kind=kind,
                first_ns=int(stamps[hit_rows[0]]),
                last_ns=int(stamps[hit_rows[-1]]),
                samples=len(hit_rows),
                max_depth_m=float(-dists[deepest]),
                deepest_ns=int(stamps[row_of[deepest]]),
            )
        )
    spans.sort(key=lambda s: (s.first_ns, s.bodies))

    clearances = []
    for kind in KINDS:
        ids = [pid for pid, (k, _) in kind_of.items() if k == kind]
        idx = np.flatnonzero(np.isin(pair_id, ids) & (dists < padding_m))
        if len(idx):
            i = int(idx[np.argmin(dists[idx])])
            clearances.append(
                Clearance(
                    kind=kind,
                    bodies=kind_of[int(pair_id[i])][1],
                    distance_m=float(dists[i]),
                    stamp_ns=int(stamps[row_of[i]]),
                )
            )
    return ExecutionSafety(
        padding_m=float(padding_m),
        every=int(every),
        skip_within_m=float(skip_within_m),
        samples_checked=len(rows),
        clearances=tuple(clearances),
        contacts=tuple(spans),
    )


def _collide_rows(
    checker: CollisionChecker,
    qs: NDArray[np.float64],
    rows: NDArray[np.int64],
    *,
    skip_within_m: float,
    reach_m_per_rad: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """The rows checked (a subset of ``rows`` when ``skip_within_m`` > 0, see
    ``assess_execution``; the last one always) and every pair within the padding at
    them: (rows checked, row, (geom1, geom2), distance).

    ``mj_collision`` with the checker's margins gives robot–robot and robot–floor
    pairs (capsule–capsule and capsule–plane distances are exact) and, for
    obstacles, contacts with each box's enclosing capsule: only those rows get
    one more ``mj_kinematics`` and ``CollisionChecker.resolve_bounds`` (the exact
    robot–box distance; see ``pipeline.planning.collision``).
    """
    data = checker.data
    bounds = checker.box_of >= 0
    qpos = data.qpos
    collide = checker.collide_current
    padding = checker.padding_m
    skipping = skip_within_m > 0.0 and len(rows) > 2
    if skipping:
        # path length along the rows [rad] bounds the joint distance between any two
        chords = np.linalg.norm(np.diff(qs[rows], axis=0), axis=1)
        length = np.concatenate([[0.0], np.cumsum(chords)]).tolist()
        per_m = 1.0 / reach_m_per_rad
    # each checked row's contacts, copied out of MjData (a row is a few contacts: lists of
    # small arrays joined once cost less than filling preallocated buffers row by row)
    contact_rows: list[int] = []
    contact_geoms: list[NDArray[np.int64]] = []
    contact_dists: list[NDArray[np.float64]] = []
    row_list = rows.tolist()
    last = len(row_list) - 1
    checked: list[int] = []
    pos = 0
    while pos <= last:
        k = row_list[pos]
        checked.append(k)
        qpos[:] = qs[k]
        ncon = collide()
        nearest = padding
        if ncon:
            contact = data.contact  # the ncon contacts just found
            dist = contact.dist.copy()
            contact_rows.append(k)
            contact_geoms.append(contact.geom.copy())
            contact_dists.append(dist)
            if skipping:
                # capsules around boxes are nearer than the boxes: a lower bound too
                nearest = min(dist.tolist())
        if not skipping:
            pos += 1
            continue
        threshold = min(skip_within_m, nearest)
        if threshold <= 0.0 or pos >= last - 1:
            pos += 1
            continue
        # skip the rows within threshold / reach of joint path length (the last row stays)
        target = length[pos] + threshold * per_m
        pos = min(max(pos + 1, bisect_left(length, target, pos + 1)), last)
    counts = [len(d) for d in contact_dists]
    row_of = np.repeat(np.array(contact_rows, dtype=np.int64), counts)
    geom_pairs = (
        np.concatenate(contact_geoms).astype(np.int64, copy=False)
        if contact_geoms
        else np.empty((0, 2), dtype=np.int64)
    )
    dists = np.concatenate(contact_dists) if contact_dists else np.empty(0)
    candidate = bounds[geom_pairs].any(axis=1)
    found = [(row_of[~candidate], geom_pairs[~candidate], dists[~candidate])]
    at = np.flatnonzero(candidate)  # in row order, as the rows were checked
    rows_at, first = np.unique(row_of[at], return_index=True)
    groups = np.split(at, first[1:]) if len(at) else []
    for k, group in zip(rows_at.tolist(), groups, strict=True):
        qpos[:] = qs[k]
        mujoco.mj_kinematics(checker.model, data)
        pairs, near = checker.resolve_bounds(geom_pairs[group], dists[group])
        found.append((np.full(len(near), k, dtype=np.int64), pairs, near))
    row_of, geom_pairs, dists = (np.concatenate(parts) for parts in zip(*found, strict=True))
    inside = dists < checker.padding_m
    return np.array(checked, dtype=np.int64), row_of[inside], geom_pairs[inside], dists[inside]
