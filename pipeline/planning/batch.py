"""Batched collision checks: every configuration of a motion in one numpy call.

``CollisionChecker.is_clear`` answers one configuration per Python call
(``mj_kinematics`` + ``mj_collision``, ~4 us). ``BatchChecker`` answers a whole
array of configurations at once, with the same answer:

1. forward kinematics of all configurations at once, from the checker's own
   MuJoCo model (body offsets, hinge axes and anchors, geom placements), so the
   capsules are where MuJoCo puts them;
2. the geom pairs MuJoCo's collision filter lets through (contype/conaffinity,
   welded and parent/child bodies, ``<exclude>``), each with a cheap lower
   bound on its distance (bounding spheres; exact for the ground plane);
3. exact distances, only where the bound is within the padding: capsule vs
   capsule (closest points of two segments), capsule vs obstacle box (a convex
   piecewise quadratic along the segment, minimised interval by interval);
4. MuJoCo decides the rare configurations it cannot settle: a distance within
   ``TOLERANCE_M`` of the padding, or a pair with only a lower bound (the
   pedestal cylinder, bounded by the capsule around it) that comes that close.

So the batched answer equals the per-configuration answer (tested on random
and near-contact segments); only the work per configuration is different.
"""

from __future__ import annotations

import math
from itertools import pairwise

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import PlanningError
from pipeline.planning.collision import CollisionChecker, coarse_to_fine, reach_terms_m

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
Bools = NDArray[np.bool_]

TOLERANCE_M = 1e-7
"""Distances this close to the padding [m] are left to MuJoCo (float noise between
the two kinematics and distance computations is ~1e-15 m)."""

_STRIDE = 8  # a long motion's every 8th state is checked first
_SHORT_MOTION = 48  # motions of at most this many states go to MuJoCo one by one
_PROBE_STATES = 16  # states MuJoCo checks first on a longer motion, coarse to fine


def _dot(x: F64, y: F64) -> F64:
    """Row-wise dot product over the last axis (length 3); faster than einsum here."""
    out: F64 = x[..., 0] * y[..., 0] + x[..., 1] * y[..., 1] + x[..., 2] * y[..., 2]
    return out


def _dot0(x: F64, y: F64) -> F64:
    """Dot product over the first axis (length 3) of coordinate-first arrays."""
    out: F64 = x[0] * y[0] + x[1] * y[1] + x[2] * y[2]
    return out


def _quat_mat(quat: F64) -> F64:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)


def _hom(rot: F64, pos: F64) -> F64:
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = rot, pos
    return t


def _filtered_out(m: mujoco.MjModel, g1: int, g2: int, excluded: frozenset[int]) -> bool:
    """MuJoCo's broad-phase filter (``engine_collision_driver.c``): is the pair never checked?
    (``excluded``: the model's ``exclude_signature`` values.)"""
    if not (
        (m.geom_contype[g1] & m.geom_conaffinity[g2])
        or (m.geom_contype[g2] & m.geom_conaffinity[g1])
    ):
        return True
    b1, b2 = int(m.geom_bodyid[g1]), int(m.geom_bodyid[g2])
    w1, w2 = int(m.body_weldid[b1]), int(m.body_weldid[b2])
    if w1 == w2:
        return True
    wp1 = int(m.body_weldid[m.body_parentid[w1]])
    wp2 = int(m.body_weldid[m.body_parentid[w2]])
    filter_parent = not (m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_FILTERPARENT)
    if filter_parent and w1 and w2 and (w1 == wp2 or w2 == wp1):
        return True
    lo, hi = min(b1, b2), max(b1, b2)
    return ((lo << 16) + hi) in excluded


def segment_distance_m(p1: F64, q1: F64, p2: F64, q2: F64) -> F64:
    """Distance [m] between segments ``p1 q1`` and ``p2 q2`` (arrays (..., 3));
    a segment may be a point (Ericson, Real-Time Collision Detection, 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f, c, b = _dot(d1, d1), _dot(d2, d2), _dot(d2, r), _dot(d1, r), _dot(d1, d2)
    a_ok, e_ok = a > 1e-18, e > 1e-18
    a_s, e_s = np.where(a_ok, a, 1.0), np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    general = denom > 1e-12 * a_s * e_s
    s = np.where(general, np.clip((b * f - c * e) / np.where(general, denom, 1.0), 0.0, 1.0), 0.0)
    s = np.where(e_ok, s, np.clip(-c / a_s, 0.0, 1.0))
    t = np.where(e_ok, (b * s + f) / e_s, 0.0)
    s = np.where(
        t < 0.0, np.clip(-c / a_s, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / a_s, 0.0, 1.0), s)
    )
    s = np.where(a_ok, s, 0.0)
    t = np.clip(t, 0.0, 1.0)
    gap = (p1 + d1 * s[..., None]) - (p2 + d2 * t[..., None])
    out: F64 = np.sqrt(_dot(gap, gap))
    return out


def segment_box_distance_m(p: F64, q: F64, half: F64) -> F64:
    """Distance [m] from segments ``p q`` (arrays (..., 3), in the box frame) to the box
    ``|x_k| <= half_k`` (0 when they meet).

    The squared distance along the segment is a convex piecewise quadratic whose
    pieces end where a coordinate crosses a face plane; each piece's minimum is
    found in closed form and the smallest is kept.
    """
    d = q - p
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = np.concatenate([(-half - p) / d, (half - p) / d], axis=-1)
    cross = np.where(np.isfinite(cross), np.clip(cross, 0.0, 1.0), 0.0)
    ends = np.zeros((*p.shape[:-1], 2))
    ends[..., 1] = 1.0
    knots = np.sort(np.concatenate([ends, cross], axis=-1), axis=-1)  # (..., 8)
    lo, hi = knots[..., :-1], knots[..., 1:]  # (..., 7) pieces
    pe, de, he = p[..., None, :], d[..., None, :], half[..., None, :]
    mid = pe + ((lo + hi) * 0.5)[..., None] * de  # (..., 7, 3)
    bound = np.where(mid < -he, -he, np.where(mid > he, he, np.nan))
    active = ~np.isnan(bound)
    off = np.where(active, pe - np.nan_to_num(bound), 0.0)
    dd = np.where(active, de, 0.0)
    curv, slope = _dot(dd, dd), _dot(off, dd)
    t = np.where(curv > 0.0, -slope / np.where(curv > 0.0, curv, 1.0), lo)
    t = np.clip(t, lo, hi)
    x = pe + t[..., None] * de
    excess = np.maximum(np.abs(x) - he, 0.0)
    out: F64 = np.sqrt(_dot(excess, excess)).min(axis=-1)
    return out


class BatchChecker:
    """``CollisionChecker.is_clear`` for many configurations per call (same answers).

    Reads the checker's model and ``padding_m`` (at each call), and asks the
    checker itself about configurations it cannot settle.

    Args:
        checker: the per-configuration checker (MuJoCo model with obstacle bounds).

    Raises:
        PlanningError: a model this checker does not cover (a robot geom that is not a
            capsule or sphere, a joint that is not a hinge, world geometry other than
            planes, cylinders, capsules, spheres and obstacle boxes).
    """

    def __init__(self, checker: CollisionChecker) -> None:
        self.checker = checker
        m = checker.model
        data = checker.data  # (every check sets its own qpos: borrowing it is harmless)
        data.qpos[:] = 0.0
        mujoco.mj_kinematics(m, data)
        dof = checker.spec.dof
        where = checker.spec.source
        # per joint j: the body it moves, as parent_T_body(q) = c0 + cos(q) cc + sin(q) cs
        bodies = [int(m.jnt_bodyid[j]) for j in range(dof)]
        if any(int(m.jnt_type[j]) != mujoco.mjtJoint.mjJNT_HINGE for j in range(dof)) or any(
            int(m.body_jntnum[b]) != 1 for b in bodies
        ):
            raise PlanningError(f"{where}: batched checks need one hinge joint per moving body")
        if any(int(m.body_parentid[bodies[j]]) != bodies[j - 1] for j in range(1, dof)):
            raise PlanningError(f"{where}: batched checks need a serial chain of joints")
        root = int(m.body_parentid[bodies[0]])
        self._world_T_root = _hom(data.xmat[root].reshape(3, 3), data.xpos[root].copy())
        terms = np.zeros((3, dof, 4, 4))
        for j, b in enumerate(bodies):
            u = m.jnt_axis[j] / np.linalg.norm(m.jnt_axis[j])
            anchor = m.jnt_pos[j]
            uu = np.outer(u, u)
            ux = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
            offset = _hom(_quat_mat(m.body_quat[b]), m.body_pos[b])
            j0 = _hom(uu, anchor - uu @ anchor)
            jc = np.zeros((4, 4))
            jc[:3, :3], jc[:3, 3] = np.eye(3) - uu, -(np.eye(3) - uu) @ anchor
            js = np.zeros((4, 4))
            js[:3, :3], js[:3, 3] = ux, -ux @ anchor
            terms[0, j], terms[1, j], terms[2, j] = offset @ j0, offset @ jc, offset @ js
        self._terms = terms
        frame_of = {body: j for j, body in enumerate(bodies)}

        # geoms as segments: robot geoms in their body frame, world geoms in the world
        moving: dict[int, int] = {}  # geom -> index among robot geoms
        frames: list[int] = []
        local: list[tuple[F64, F64]] = []
        radius: list[float] = []
        static: dict[int, tuple[F64, F64, float]] = {}
        for g in range(m.ngeom):
            body = int(m.geom_bodyid[g])
            gtype = int(m.geom_type[g])
            on_robot = int(m.body_weldid[body]) != 0
            if on_robot:
                if body not in frame_of or gtype not in (
                    mujoco.mjtGeom.mjGEOM_CAPSULE,
                    mujoco.mjtGeom.mjGEOM_SPHERE,
                ):
                    raise PlanningError(
                        f"{where}: geom {m.geom(g).name!r}: batched checks need capsules or "
                        "spheres on the moving bodies"
                    )
                half = float(m.geom_size[g][1]) if gtype == mujoco.mjtGeom.mjGEOM_CAPSULE else 0.0
                axis = _quat_mat(m.geom_quat[g])[:, 2] * half
                moving[g] = len(frames)
                frames.append(frame_of[body])
                local.append((m.geom_pos[g] - axis, m.geom_pos[g] + axis))
                radius.append(float(m.geom_size[g][0]))
            elif gtype in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_SPHERE):
                half = 0.0 if gtype == mujoco.mjtGeom.mjGEOM_SPHERE else float(m.geom_size[g][1])
                axis = data.geom_xmat[g].reshape(3, 3)[:, 2] * half
                pos = data.geom_xpos[g]
                static[g] = (pos - axis, pos + axis, float(m.geom_size[g][0]))
        self._frames: I64 = np.array(frames, dtype=np.int64)
        self._local_a = np.array([a for a, _ in local]).reshape(-1, 3)
        self._local_b = np.array([b for _, b in local]).reshape(-1, 3)
        self._radius = np.array(radius)

        # the pairs MuJoCo checks, by kind
        seg1: list[int] = []  # robot geom index
        seg2: list[int] = []  # robot geom index, or -1 - static index
        seg_exact: list[bool] = []
        static_a: list[F64] = []
        static_b: list[F64] = []
        static_r: list[float] = []
        plane_geom: list[int] = []
        plane_normal: list[F64] = []
        plane_offset: list[float] = []
        cyl_geom: list[int] = []
        cyl_centre: list[F64] = []
        cyl_axis: list[F64] = []
        cyl_size: list[F64] = []
        box_geom: list[int] = []
        box_rot: list[F64] = []
        box_centre: list[F64] = []
        box_half: list[F64] = []
        self._box_ids: list[tuple[int, int]] = []  # (robot geom, box geom) for MuJoCo
        excluded = frozenset(int(s) for s in m.exclude_signature)
        for g1 in range(m.ngeom):
            for g2 in range(g1 + 1, m.ngeom):
                if _filtered_out(m, g1, g2, excluded):
                    continue
                if g1 in moving and g2 in moving:
                    seg1.append(moving[g1])
                    seg2.append(moving[g2])
                    seg_exact.append(True)
                    continue
                robot, other = (g1, g2) if g1 in moving else (g2, g1)
                if robot not in moving or other in moving:
                    continue  # world vs world: MuJoCo skips it too (same weld)
                otype = int(m.geom_type[other])
                box = int(checker.box_of[other])
                if box >= 0:
                    box_geom.append(moving[robot])
                    box_rot.append(data.geom_xmat[box].reshape(3, 3).copy())
                    box_centre.append(data.geom_xpos[box].copy())
                    box_half.append(m.geom_size[box].copy())
                    self._box_ids.append((robot, box))
                elif otype == mujoco.mjtGeom.mjGEOM_PLANE:
                    normal = data.geom_xmat[other].reshape(3, 3)[:, 2].copy()
                    plane_geom.append(moving[robot])
                    plane_normal.append(normal)
                    plane_offset.append(float(normal @ data.geom_xpos[other]))
                elif otype == mujoco.mjtGeom.mjGEOM_CYLINDER:
                    cyl_geom.append(moving[robot])
                    cyl_centre.append(data.geom_xpos[other].copy())
                    cyl_axis.append(data.geom_xmat[other].reshape(3, 3)[:, 2].copy())
                    cyl_size.append(m.geom_size[other][:2].copy())
                elif other in static:
                    end_a, end_b, end_r = static[other]
                    seg1.append(moving[robot])
                    seg2.append(-1 - len(static_a))
                    seg_exact.append(True)
                    static_a.append(end_a)
                    static_b.append(end_b)
                    static_r.append(end_r)
                else:
                    raise PlanningError(
                        f"{where}: geom {m.geom(other).name!r}: batched checks do not cover "
                        f"geom type {otype}"
                    )
        self._half = 0.5 * np.linalg.norm(self._local_b - self._local_a, axis=1)
        self._seg1 = np.array(seg1, dtype=np.int64)
        second = np.array(seg2, dtype=np.int64)
        self._seg_moving = second >= 0
        self._seg_other = np.where(self._seg_moving, second, 0)
        fixed = np.where(self._seg_moving, 0, -1 - second)
        static_a_arr = np.array([*static_a, np.zeros(3)]).reshape(-1, 3)
        static_b_arr = np.array([*static_b, np.zeros(3)]).reshape(-1, 3)
        static_r_arr = np.array([*static_r, 0.0])
        self._seg_fixed_a = np.where(self._seg_moving[:, None], 0.0, static_a_arr[fixed])
        self._seg_fixed_b = np.where(self._seg_moving[:, None], 0.0, static_b_arr[fixed])
        r2 = np.where(self._seg_moving, self._radius[self._seg_other], static_r_arr[fixed])
        h2 = np.where(
            self._seg_moving,
            self._half[self._seg_other],
            0.5 * np.linalg.norm(static_b_arr[fixed] - static_a_arr[fixed], axis=1),
        )
        self._seg_radii = self._radius[self._seg1] + r2
        self._seg_reach = self._seg_radii + self._half[self._seg1] + h2
        self._seg_exact = np.array(seg_exact, dtype=bool)
        self._plane_geom = np.array(plane_geom, dtype=np.int64)
        self._plane_normal = np.array(plane_normal).reshape(-1, 3)
        self._plane_offset = np.array(plane_offset)
        self._cyl_geom = np.array(cyl_geom, dtype=np.int64)
        self._cyl_centre = np.array(cyl_centre).reshape(-1, 3)
        self._cyl_axis = np.array(cyl_axis).reshape(-1, 3)
        self._cyl_size = np.array(cyl_size).reshape(-1, 2)
        self._box_geom = np.array(box_geom, dtype=np.int64)
        self._box_rot = np.array(box_rot).reshape(-1, 3, 3)
        self._box_centre = np.array(box_centre).reshape(-1, 3)
        self._box_half = np.array(box_half).reshape(-1, 3)
        self._box_rot_t = np.moveaxis(self._box_rot, 0, -1).transpose(1, 0, 2)  # [k, i, box]
        # per pair: how fast its distance can change [m/rad] (Lipschitz in q): only the
        # joints between the two bodies move one relative to the other, joint k moving
        # the geometry beyond it by at most R_k per radian (see reach_bound_m)
        reach_sq = np.cumsum(np.square([0.0, *reach_terms_m(checker.spec)]))
        frame = self._frames

        def rate(inner: I64, outer: I64) -> F64:
            out: F64 = np.sqrt(reach_sq[outer + 1] - reach_sq[inner + 1])
            return out

        f1, f2 = frame[self._seg1], frame[self._seg_other]
        inner = np.where(self._seg_moving, np.minimum(f1, f2), -1)
        outer = np.where(self._seg_moving, np.maximum(f1, f2), f1)
        self._seg_rate = rate(inner, outer)
        self._plane_rate = rate(np.full(len(self._plane_geom), -1), frame[self._plane_geom])
        self._cyl_rate = rate(np.full(len(self._cyl_geom), -1), frame[self._cyl_geom])
        self._box_rate = rate(np.full(len(self._box_geom), -1), frame[self._box_geom])
        self.states_checked = 0  # configurations answered, for benchmarks

    def segments(self, qs: F64) -> tuple[F64, F64]:
        """World endpoints of the robot geoms at configurations ``qs`` (m, n):
        (3, m, G) each, coordinates first (each coordinate a contiguous array)."""
        c, s = np.cos(qs), np.sin(qs)
        steps = (
            self._terms[0]
            + c[:, :, None, None] * self._terms[1]
            + s[:, :, None, None] * self._terms[2]
        )  # (m, n, 4, 4): parent_T_body per joint
        frames = np.empty_like(steps)
        t = np.broadcast_to(self._world_T_root, steps[:, 0].shape)
        for j in range(steps.shape[1]):
            t = frames[:, j] = t @ steps[:, j]
        f = np.moveaxis(frames[:, self._frames, :3], (2, 3), (0, 1))  # (3, 4, m, G)
        la, lb = self._local_a.T, self._local_b.T  # (3, G)
        a = f[:, 0] * la[0] + f[:, 1] * la[1] + f[:, 2] * la[2] + f[:, 3]
        b = f[:, 0] * lb[0] + f[:, 1] * lb[1] + f[:, 2] * lb[2] + f[:, 3]
        return a, b

    def clear(self, qs: ArrayLike) -> Bools:
        """Per configuration of ``qs`` (m, n) [rad]: nothing within ``padding_m``?
        (``CollisionChecker.is_clear`` for each row; limits not checked.)"""
        out: Bools = self.clear_radius_rad(qs) >= 0.0
        return out

    def clear_radius_rad(self, qs: ArrayLike) -> F64:
        """Per configuration of ``qs`` (m, n) [rad]: a joint-space radius [rad] within
        which every configuration is clear (each pair's distance above the padding, less
        its rate of change times the distance in q); >= 0 exactly when ``is_clear`` (0
        when MuJoCo had to decide), ``-inf`` when not clear."""
        q = np.asarray(qs, dtype=np.float64).reshape(-1, self.checker.spec.dof)
        self.states_checked += len(q)
        padding = self.checker.padding_m
        near = padding + TOLERANCE_M
        far_below = padding - TOLERANCE_M
        a, b = self.segments(q)  # (3, m, G)
        centre = 0.5 * (a + b)
        radius = np.full(len(q), np.inf)
        bad = np.zeros(len(q), dtype=bool)
        unsure = np.zeros(len(q), dtype=bool)

        # capsules and spheres: bounding spheres first, closest points where they are near
        if len(self._seg1):
            moving = self._seg_moving
            sa = np.where(moving, a[:, :, self._seg_other], self._seg_fixed_a.T[:, None])
            sb = np.where(moving, b[:, :, self._seg_other], self._seg_fixed_b.T[:, None])
            gap = centre[:, :, self._seg1] - 0.5 * (sa + sb)
            lower = np.sqrt(_dot0(gap, gap)) - self._seg_reach  # (m, P)
            rows, cols = np.nonzero(lower <= near)
            if len(rows):
                g = self._seg1[cols]
                dist = segment_distance_m(
                    a[:, rows, g].T, b[:, rows, g].T, sa[:, rows, cols].T, sb[:, rows, cols].T
                )
                dist -= self._seg_radii[cols]
                exact = self._seg_exact[cols]
                sure_bad = exact & (dist < far_below)
                bad[rows[sure_bad]] = True
                unsure[rows[(dist <= near) & ~sure_bad]] = True
                lower[rows, cols] = dist
            radius = np.minimum(radius, ((lower - near) / self._seg_rate).min(axis=1))

        # the ground: exact from the endpoints' heights
        if len(self._plane_geom):
            g = self._plane_geom
            normal = self._plane_normal.T[:, None]  # (3, 1, P)
            height = np.minimum(_dot0(a[:, :, g], normal), _dot0(b[:, :, g], normal))
            dist = height - self._plane_offset - self._radius[g]
            bad |= (dist < far_below).any(axis=1)
            unsure |= ((dist >= far_below) & (dist <= near)).any(axis=1)
            radius = np.minimum(radius, ((dist - near) / self._plane_rate).min(axis=1))

        # cylinders (the pedestal): a lower bound only, the larger of the distances to
        # the slab between its caps and to its infinite side; MuJoCo decides when near
        if len(self._cyl_geom):
            g, axis = self._cyl_geom, self._cyl_axis.T[:, None]
            ctr = self._cyl_centre.T[:, None]
            pa, pb = a[:, :, g] - ctr, b[:, :, g] - ctr
            za, zb = _dot0(pa, axis), _dot0(pb, axis)
            half_len, cyl_r = self._cyl_size[:, 1], self._cyl_size[:, 0]
            slab = np.maximum(np.minimum(za, zb) - half_len, -half_len - np.maximum(za, zb))
            ra = pa - za * axis
            rd = (pb - zb * axis) - ra
            rdd = _dot0(rd, rd)
            t = np.clip(-_dot0(ra, rd) / np.where(rdd > 0.0, rdd, 1.0), 0.0, 1.0)
            nearest = ra + t * rd
            side = np.sqrt(_dot0(nearest, nearest)) - cyl_r
            lower = np.maximum(slab, side) - self._radius[g]
            unsure |= (lower <= near).any(axis=1)
            radius = np.minimum(radius, ((lower - near) / self._cyl_rate).min(axis=1))

        # obstacle boxes: per box axis, how far the capsule axis stays outside the box's
        # slab (the root of their squares is a lower bound), then the exact capsule-box
        # distance where that is near
        if len(self._box_geom):
            g = self._box_geom
            rot, ctr = self._box_rot_t, self._box_centre.T[:, None]  # (3, 3, B), (3, 1, B)
            pa, pb = a[:, :, g] - ctr, b[:, :, g] - ctr
            gap_sq = np.zeros(pa.shape[1:])
            for k in range(3):
                ua = rot[k, 0] * pa[0] + rot[k, 1] * pa[1] + rot[k, 2] * pa[2]
                ub = rot[k, 0] * pb[0] + rot[k, 1] * pb[1] + rot[k, 2] * pb[2]
                h = self._box_half[:, k]
                gap = np.maximum(np.maximum(np.minimum(ua, ub) - h, -h - np.maximum(ua, ub)), 0.0)
                gap_sq += gap * gap
            lower = np.sqrt(gap_sq) - self._radius[g]
            rows, cols = np.nonzero(lower <= near)
            if len(rows):
                gg = g[cols]
                rot, ctr = self._box_rot[cols], self._box_centre[cols]
                pa = (rot * (a[:, rows, gg].T - ctr)[:, :, None]).sum(axis=1)  # box frame
                pb = (rot * (b[:, rows, gg].T - ctr)[:, :, None]).sum(axis=1)
                dist = segment_box_distance_m(pa, pb, self._box_half[cols]) - self._radius[gg]
                bad[rows[dist < far_below]] = True
                unsure[rows[(dist >= far_below) & (dist <= near)]] = True
                lower[rows, cols] = dist
            radius = np.minimum(radius, ((lower - near) / self._box_rate).min(axis=1))

        radius[bad] = -np.inf
        for row in np.nonzero(unsure & ~bad)[0].tolist():
            radius[row] = 0.0 if self.checker.is_clear(q[row]) else -np.inf
        return radius

    def motion_clear(self, qa: F64, qb: F64, *, step_rad: float) -> bool:
        """``CollisionChecker.motion_clear`` (same states, same answer), in batches.

        A few states coarse to fine first, one by one in MuJoCo (most invalid motions
        end there); then every ``_STRIDE``-th state in one batch, whose clear radii
        (``clear_radius_rad``) certify their neighbours; then, in a last batch, the
        states no neighbour certifies.
        """
        delta = qb - qa
        length = math.sqrt(float(np.dot(delta, delta)))
        n_steps = math.ceil(length / step_rad)
        if n_steps <= _SHORT_MOTION:
            return self.checker.motion_clear(qa, qb, step_rad=step_rad)
        is_clear = self.checker.is_clear
        for i in coarse_to_fine(n_steps)[:_PROBE_STATES]:
            if not is_clear(qa + (i / n_steps) * delta):
                return False
        k = np.arange(0, n_steps + 1)
        coarse = k[::_STRIDE] if n_steps % _STRIDE == 0 else np.append(k[::_STRIDE], n_steps)
        radius = self.clear_radius_rad(qa + np.outer(coarse / n_steps, delta))
        if (radius[1:] < 0.0).any():
            return False
        radius[0] = max(radius[0], 0.0)  # qa is checked by the caller
        dq = length / n_steps
        j = np.minimum(k // _STRIDE, len(coarse) - 2)  # the coarse states either side
        certified = np.maximum(
            radius[j] - (k - coarse[j]) * dq, radius[j + 1] - (coarse[j + 1] - k) * dq
        )
        unchecked = np.ones(n_steps + 1, dtype=bool)
        unchecked[coarse] = False
        rest = k[(certified <= 0.0) & unchecked]
        if not len(rest):
            return True
        return bool((self.clear_radius_rad(qa + np.outer(rest / n_steps, delta)) >= 0.0).all())

    def first_invalid(self, path: F64, *, step_rad: float) -> F64 | None:
        """``CollisionChecker.first_invalid`` (the same states, the same answer) in one batch."""
        parts = []
        for qa, qb in pairwise(path):
            n_steps = max(1, math.ceil(float(np.linalg.norm(qb - qa)) / step_rad))
            parts.append(qa + np.outer(np.arange(n_steps) / n_steps, qb - qa))
        qs = np.concatenate([*parts, path[-1:]])
        lower, upper = self.checker.spec.lower, self.checker.spec.upper
        ok = np.all((qs >= lower) & (qs <= upper), axis=1)
        ok[ok] = self.clear(qs[ok])
        bad = np.flatnonzero(~ok)
        if not len(bad):
            return None
        first: F64 = qs[bad[0]]
        return first
