"""Closed-form IK for UR-type arms (the paper's eqs. 4-11; Hawkins 2013).

Geometry that fits: standard DH, 6 joints, alpha = [pi/2, 0, 0, pi/2, -pi/2, 0],
a = [0, a2, a3, 0, 0, 0] with a2, a3 != 0, any d (d2 + d3 + d4 act as one
shoulder offset) and any theta offsets. Joints 2-4 are parallel, so the wrist
centre (frame 5 origin) fixes theta1 (two shoulder branches), the tool z axis
fixes theta5 (two wrist branches) and theta6, and a planar 2R arm gives theta2,
theta3 (two elbow branches) and theta4: up to 8 solutions.

Derivation, with R = [n o a], p the target and s1 = sin(theta1) etc. (angles
here are DH angles, theta = q + theta_offset):

- wrist centre p5 = p - d6 a; r sin(theta1 - phi) = D with phi = atan2(p5y, p5x),
  r = |p5_xy|, D = d2 + d3 + d4 (eqs. 4-6: theta1 = phi + pi/2 +- acos(D / r)).
- the last row of R16 = R01^T R is (s5 c6, -s5 s6, c5): c5 = s1 ax - c1 ay,
  |s5| = |(s1 nx - c1 ny, s1 ox - c1 oy)| (eq. 7 with the sign branch),
  theta6 = atan2(-(s1 ox - c1 oy) / s5, (s1 nx - c1 ny) / s5) (eq. 8).
- frame 4 origin p4 = p + d5 (s6 n + c6 o) - d6 a; in frame 1 its xy is the 2R
  arm's tip: c3 = (x^2 + y^2 - a2^2 - a3^2) / (2 a2 a3), theta2 = atan2(y, x)
  - atan2(a3 s3, a2 + a3 c3) (eqs. 9-10), and theta2 + theta3 + theta4 =
  atan2(vz, c1 vx + s1 vy) with v = c5 (c6 n - s6 o) - s5 a (eq. 11).

Wrist singularity (|s5| < 1e-9: joint 6 parallel to joints 2-4): only
theta2 + theta3 + theta4 + theta6 is determined. We fix theta6 to the seed's
joint-6 value (the middle of its range without a seed) and put the rest in
theta4, with theta5 = 0 or pi exactly. That shoulder branch's two wrist branches
coincide and are returned once (the other shoulder branch is usually regular).
Branches whose +- coincide (|s3| or the shoulder acos below 1e-9) are returned
once too.

Each angle is brought to its 2 pi representative nearest the seed that lies
within the joint limits; solutions with a joint that has no such representative
are dropped. The single call orders solutions by distance to the seed when one
is given (branch order otherwise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import KinematicsError
from pipeline.kinematics.ik import (
    IKOptions,
    IKResult,
    as_pose,
    format_reason,
    pose_rows,
    seed_or_middle,
)
from pipeline.kinematics.limits import TWO_PI, wrap_to_limits
from pipeline.robots.spec import RobotSpec

Array = NDArray[np.float64]

UR_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
SINGULAR_S5 = 1e-9
"""|sin(theta5)| below this is treated as the wrist singularity."""
DEGENERATE = 1e-9
"""A +- branch whose angle is within this of 0 (or pi) is returned once [rad]."""
REACH_SLACK = 1e-9
"""Cosines up to 1 + this are clamped (targets on the workspace boundary)."""
_GEOMETRY_TOL = 1e-9
_INV_TWO_PI = 1.0 / (2.0 * math.pi)


@dataclass(frozen=True)
class URGeometry:
    """The numbers the closed form needs [m, rad]."""

    d1: float
    a2: float
    a3: float
    shoulder_offset: float  # d2 + d3 + d4
    d5: float
    d6: float
    theta_offsets: tuple[float, ...]


def ur_geometry(spec: RobotSpec) -> URGeometry:
    """Extract UR-type geometry or raise KinematicsError saying what does not fit."""
    problems: list[str] = []
    given = spec.dh_rows
    if given is None:
        problems.append(f"it is given as {spec.format}, not DH rows (needs standard DH)")
    elif spec.convention != "standard":
        problems.append(f"convention is '{spec.convention}' (needs standard DH)")
    if spec.dof != 6:
        problems.append(f"it has {spec.dof} joints (needs 6)")
    elif given is not None:
        rows = list(given)
        for i, (row, want) in enumerate(zip(rows, UR_ALPHA, strict=True)):
            if abs(row.alpha - want) > _GEOMETRY_TOL:
                problems.append(f"alpha{i + 1} = {row.alpha:.6g} rad (needs {want:.6g})")
        for i in (0, 3, 4, 5):
            if abs(rows[i].a) > _GEOMETRY_TOL:
                problems.append(f"a{i + 1} = {rows[i].a:.6g} m (needs 0)")
        for i in (1, 2):
            if abs(rows[i].a) <= _GEOMETRY_TOL:
                problems.append(f"a{i + 1} = 0 (needs a non-zero link length)")
    if problems:
        raise KinematicsError(
            f"analytic IK does not fit robot '{spec.name}' ({spec.source}): "
            + "; ".join(problems)
            + ". It needs UR-type geometry: standard DH, alpha = [pi/2, 0, 0, pi/2, -pi/2, 0], "
            "a = [0, a2, a3, 0, 0, 0]; use --solver numeric for other arms"
        )
    rows = list(given or ())
    return URGeometry(
        d1=rows[0].d,
        a2=rows[1].a,
        a3=rows[2].a,
        shoulder_offset=rows[1].d + rows[2].d + rows[3].d,
        d5=rows[4].d,
        d6=rows[5].d,
        theta_offsets=tuple(r.theta_offset for r in rows),
    )


class BatchSolutions(NamedTuple):
    """All 8 branches for N targets.

    Branch b = 4 * shoulder + 2 * wrist + elbow (each bit: 0 = "+", 1 = "-" sign
    of the acos in theta1, theta5, theta3).

    Attributes:
        q: (N, 8, 6) joint angles [rad]; NaN where not valid.
        valid: (N, 8) True where the branch exists (reachable, not a duplicate of
            a coinciding branch, within joint limits).
    """

    q: Array
    valid: NDArray[np.bool_]


class AnalyticURSolver:
    """Closed-form IK for UR-type arms: every solution within the joint limits."""

    def __init__(self, spec: RobotSpec, options: IKOptions | None = None) -> None:
        self._spec = spec
        self._geom = ur_geometry(spec)
        self._options = options or IKOptions()
        self._lower = spec.lower
        self._upper = spec.upper
        self._offsets = np.array(self._geom.theta_offsets)
        self._has_offsets = bool(np.any(self._offsets != 0.0))
        self._middle = 0.5 * (spec.lower + spec.upper)
        # with every range at least 2 pi wide, one 2 pi shift always lands in range
        self._wide = bool(np.all(self._upper - self._lower >= TWO_PI))
        self._bounds = list(
            zip(
                self._lower.tolist(),
                (self._lower + math.pi).tolist(),
                (self._upper - math.pi).tolist(),
                self._upper.tolist(),
                strict=True,
            )
        )
        self._middle_is_safe = self._rounding_seed(self._middle) is self._middle

    def _rounding_seed(self, seed: Array) -> Array | None:
        """The seed clamped into [lower + pi, upper - pi] (``seed`` itself if already
        there); None if the seed is outside the limits or a range is under 2 pi."""
        clamped = []
        moved = False
        for (lo, safe_lo, safe_hi, hi), s in zip(self._bounds, seed.tolist(), strict=True):
            if not lo <= s <= hi:
                return None
            if s < safe_lo or s > safe_hi:
                moved = True
                s = safe_lo if s < safe_lo else safe_hi
            clamped.append(s)
        if not moved:
            return seed
        return np.array(clamped) if self._wide else None

    @property
    def name(self) -> str:
        return "analytic"

    @property
    def spec(self) -> RobotSpec:
        return self._spec

    @property
    def geometry(self) -> URGeometry:
        return self._geom

    def solve(self, base_T_flange: ArrayLike, *, seed_q: ArrayLike | None = None) -> IKResult:
        """All solutions [rad] within limits (see module doc).

        With ``seed_q`` they are ordered by Euclidean joint distance to it, nearest
        first; without, in branch order (shoulder, wrist, elbow: + before -).
        """
        _, rows = pose_rows(base_T_flange)
        seed = self._middle if seed_q is None else seed_or_middle(self._spec, seed_q)
        thetas, why = _solve_dh(self._geom, rows, float(seed[5]) + self._geom.theta_offsets[5])
        if thetas:
            q = np.array(thetas)
            if self._has_offsets:
                q -= self._offsets
            # Representatives nearest a seed that is >= pi inside every limit are in range.
            # With ranges >= 2 pi, rounding towards the seed clamped into that safe band
            # gives the in-range representative nearest the seed itself.
            if seed_q is None and self._middle_is_safe:
                toward: Array | None = seed
            else:
                toward = self._rounding_seed(seed)
            if toward is not None:
                q -= TWO_PI * np.rint((q - toward) * _INV_TWO_PI)
            else:
                q, ok = wrap_to_limits(q, self._lower, self._upper, seed)
                q = q[ok]
                if q.shape[0] == 0:
                    why = f"all {len(thetas)} closed-form solutions are outside the joint limits"
            if seed_q is not None and q.shape[0] > 1:
                d = q - seed
                q = q.take((d * d).sum(axis=1).argsort(kind="stable"), axis=0)
            if q.shape[0]:
                return IKResult(q)
        target = as_pose(base_T_flange)
        return IKResult(np.empty((0, 6)), reason=format_reason(self._spec, target, why))

    def solve_batch(
        self, base_T_flange: ArrayLike, *, seed_q: ArrayLike | None = None, chunk: int = 2048
    ) -> BatchSolutions:
        """Vectorized closed form for N targets (N, 4, 4) -> :class:`BatchSolutions`.

        ``seed_q`` is one seed (6,) or one per target (N, 6) [rad]; it picks the
        2 pi representatives and theta6 at the wrist singularity. Targets are
        processed ``chunk`` at a time so the temporaries stay in cache. For
        throughput they are not validated one by one (the single call is):
        pass rotations, or expect garbage for those rows.
        """
        t = np.asarray(base_T_flange, dtype=float)
        if t.ndim != 3 or t.shape[1:] != (4, 4):
            raise KinematicsError(f"solve_batch needs targets of shape (N, 4, 4), got {t.shape}")
        n = t.shape[0]
        seed = self._middle if seed_q is None else np.asarray(seed_q, dtype=float)
        if seed.shape not in ((6,), (n, 6)) or not np.all(np.isfinite(seed)):
            raise KinematicsError(
                f"solve_batch seeds must be finite with shape (6,) or ({n}, 6), got {seed.shape}"
            )
        per_target = seed.ndim == 2
        lo = self._lower[:, None, None]
        hi = self._upper[:, None, None]
        off = self._offsets[:, None, None]
        wide = self._wide and bool(np.all(seed >= self._lower) and np.all(seed <= self._upper))
        q_out = np.empty((n, 8, 6))
        valid_out = np.empty((n, 8), dtype=bool)
        for i in range(0, n, chunk):
            j = min(n, i + chunk)
            m = j - i
            comps = t[i:j, :3, :].reshape(m, 12).T
            s = seed[i:j].T[:, None, :] if per_target else seed[:, None, None]
            th6 = np.broadcast_to(s[5, 0] + self._geom.theta_offsets[5], (m,))
            theta, ok = _solve_dh_batch(self._geom, np.ascontiguousarray(comps), th6)
            q = theta.reshape(6, 8, m)
            ok8 = ok.reshape(8, m)
            if self._has_offsets:
                q -= off
            q -= TWO_PI * np.rint((q - s) * _INV_TWO_PI)
            if wide:
                np.subtract(q, TWO_PI, out=q, where=q > hi)
                np.add(q, TWO_PI, out=q, where=q < lo)
            else:
                q, in_limits = wrap_to_limits(q, lo, hi, s, joint_axis=0)
                ok8 &= in_limits
            if not ok8.all():
                q[:, ~ok8] = np.nan
            q_out[i:j] = q.transpose(2, 1, 0)
            valid_out[i:j] = ok8.T
        return BatchSolutions(q_out, valid_out)


def _solve_dh(
    g: URGeometry, rows: list[list[float]], theta6_singular: float
) -> tuple[list[list[float]], str]:
    """Scalar closed form: DH angles of every distinct branch, or ([], why)."""
    (nx, ox, ax, px), (ny, oy, ay, py), (nz, oz, az, pz) = rows
    d1, a2, a3, dsh, d5, d6 = g.d1, g.a2, g.a3, g.shoulder_offset, g.d5, g.d6
    sqrt, atan2 = math.sqrt, math.atan2
    p5x = px - d6 * ax
    p5y = py - d6 * ay
    r = math.hypot(p5x, p5y)
    if r * (1.0 + REACH_SLACK) < abs(dsh) or r == 0.0:
        return [], (
            f"the wrist centre is {r:.4g} m from the base axis, closer than the shoulder "
            f"offset {abs(dsh):.4g} m"
        )
    cphi, sphi = p5x / r, p5y / r
    cpsi = max(-1.0, min(1.0, dsh / r))
    spsi = sqrt(1.0 - cpsi * cpsi)
    # theta1 = phi + pi/2 +- psi, so s1 = cos(phi +- psi), c1 = -sin(phi +- psi)
    shoulders = [(cphi * cpsi - sphi * spsi, -(sphi * cpsi + cphi * spsi))]
    if spsi >= DEGENERATE:
        shoulders.append((cphi * cpsi + sphi * spsi, -(sphi * cpsi - cphi * spsi)))
    out: list[list[float]] = []
    den = 2.0 * a2 * a3
    rest = a2 * a2 + a3 * a3
    why = ""
    p4x0, p4y0, p4z0 = px - d6 * ax, py - d6 * ay, pz - d6 * az - d1
    for s1, c1 in shoulders:
        t1 = atan2(s1, c1)
        c5 = s1 * ax - c1 * ay
        u = s1 * nx - c1 * ny  # s5 c6
        w = s1 * ox - c1 * oy  # -s5 s6
        s5 = math.hypot(u, w)
        if s5 < SINGULAR_S5:
            c5 = 1.0 if c5 >= 0.0 else -1.0
            wrists = [(0.0 if c5 > 0.0 else math.pi, 0.0, math.cos(theta6_singular),
                       math.sin(theta6_singular), theta6_singular)]  # fmt: skip
        else:
            t5 = atan2(s5, c5)
            c6, s6 = u / s5, -w / s5
            t6 = atan2(s6, c6)
            wrists = [(t5, s5, c6, s6, t6), (-t5, -s5, -c6, -s6, t6 + math.pi)]
        for t5, s5, c6, s6, t6 in wrists:
            vx = c5 * (c6 * nx - s6 * ox) - s5 * ax
            vy = c5 * (c6 * ny - s6 * oy) - s5 * ay
            vz = c5 * (c6 * nz - s6 * oz) - s5 * az
            t234 = atan2(vz, c1 * vx + s1 * vy)
            x = c1 * (p4x0 + d5 * (s6 * nx + c6 * ox)) + s1 * (p4y0 + d5 * (s6 * ny + c6 * oy))
            y = p4z0 + d5 * (s6 * nz + c6 * oz)
            c3 = (x * x + y * y - rest) / den
            if abs(c3) > 1.0 + REACH_SLACK:
                why = (
                    f"the elbow cannot reach: joints 2 to 4 would be {sqrt(x * x + y * y):.4g} m "
                    f"apart, the links span [{abs(abs(a2) - abs(a3)):.4g}, "
                    f"{abs(a2) + abs(a3):.4g}] m"
                )
                continue
            c3 = max(-1.0, min(1.0, c3))
            s3 = sqrt(1.0 - c3 * c3)
            t3 = atan2(s3, c3)
            base = atan2(y, x)
            gamma = atan2(a3 * s3, a2 + a3 * c3)
            t2 = base - gamma
            out.append([t1, t2, t3, t234 - t2 - t3, t5, t6])
            if s3 >= DEGENERATE:
                t2 = base + gamma
                out.append([t1, t2, -t3, t234 - t2 + t3, t5, t6])
    return out, why


def _solve_dh_batch(
    g: URGeometry, comps: Array, theta6_singular: Array
) -> tuple[Array, NDArray[np.bool_]]:
    """Vectorized closed form for M targets.

    Args:
        comps: (12, M) rows of the targets' top 3x4 block, row-major
            (nx ox ax px ny oy ay py nz oz az pz).
        theta6_singular: (M,) DH theta6 [rad] used at the wrist singularity.

    Returns:
        DH angles (6, 2, 2, 2, M) indexed [joint, shoulder, wrist, elbow, target]
        and validity (2, 2, 2, M): reachable and not a duplicate of a coinciding branch.
    """
    nx, ox, ax, px, ny, oy, ay, py, nz, oz, az, pz = comps
    m = comps.shape[1]
    d1, a2, a3, dsh, d5, d6 = g.d1, g.a2, g.a3, g.shoulder_offset, g.d5, g.d6

    # shoulder branches: (2, M)
    p5x = px - d6 * ax
    p5y = py - d6 * ay
    r2 = p5x * p5x + p5y * p5y
    reach1 = (r2 * (1.0 + REACH_SLACK) ** 2 >= dsh * dsh) & (r2 > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_r = 1.0 / np.sqrt(r2)
    cphi = p5x * inv_r
    sphi = p5y * inv_r
    cpsi = np.clip(dsh * inv_r, -1.0, 1.0)
    spsi = np.sqrt(1.0 - cpsi * cpsi)
    a, b = cphi * cpsi, sphi * spsi
    c, d = sphi * cpsi, cphi * spsi
    s1 = np.stack((a - b, a + b))
    c1 = np.stack((-(c + d), d - c))
    t1 = np.arctan2(s1, c1)
    ok1 = np.stack((reach1, reach1 & (spsi >= DEGENERATE)))

    # wrist: "+" branch per shoulder (2, M); "-" has s5, c6, s6 negated and theta6 + pi
    c5 = s1 * ax - c1 * ay
    u = s1 * nx - c1 * ny
    w = s1 * ox - c1 * oy
    s5 = np.hypot(u, w)
    sing = s5 < SINGULAR_S5
    with np.errstate(divide="ignore", invalid="ignore"):
        c6 = u / s5
        s6 = -w / s5
    t5 = np.arctan2(s5, c5)
    t6 = np.arctan2(s6, c6)
    if sing.any():
        c5 = np.where(sing, np.where(c5 >= 0.0, 1.0, -1.0), c5)
        t5 = np.where(sing, np.where(c5 > 0.0, 0.0, math.pi), t5)
        s5 = np.where(sing, 0.0, s5)
        t6 = np.where(sing, theta6_singular, t6)
        c6 = np.where(sing, np.cos(theta6_singular), c6)
        s6 = np.where(sing, np.sin(theta6_singular), s6)
    ok5 = np.stack((ok1, ok1 & ~sing), axis=1)  # (2, 2, M)

    # v (eq. 11) flips sign with the wrist branch, so theta234 moves by pi
    vx = c5 * (c6 * nx - s6 * ox) - s5 * ax
    vy = c5 * (c6 * ny - s6 * oy) - s5 * ay
    vz = c5 * (c6 * nz - s6 * oz) - s5 * az
    t234p = np.arctan2(vz, c1 * vx + s1 * vy)
    t234 = np.stack((t234p, t234p + math.pi), axis=1)
    # frame 4 origin: base part and the wrist-sign part d5 (s6 n + c6 o)
    qx = d5 * (s6 * nx + c6 * ox)
    qy = d5 * (s6 * ny + c6 * oy)
    qz = d5 * (s6 * nz + c6 * oz)
    bx = px - d6 * ax
    by = py - d6 * ay
    x0 = c1 * bx + s1 * by
    xq = c1 * qx + s1 * qy
    x = np.stack((x0 + xq, x0 - xq), axis=1)
    y0 = pz - d6 * az - d1
    y = np.stack((y0 + qz, y0 - qz), axis=1)
    c3 = (x * x + y * y - (a2 * a2 + a3 * a3)) * (1.0 / (2.0 * a2 * a3))
    reach3 = np.abs(c3) <= 1.0 + REACH_SLACK
    np.clip(c3, -1.0, 1.0, out=c3)
    s3 = np.sqrt(1.0 - c3 * c3)
    t3 = np.arctan2(s3, c3)
    base = np.arctan2(y, x)
    gamma = np.arctan2(a3 * s3, a2 + a3 * c3)

    out = np.empty((6, 2, 2, 2, m))
    out[0] = t1[:, None, None, :]
    out[1, :, :, 0] = base - gamma
    out[1, :, :, 1] = base + gamma
    out[2, :, :, 0] = t3
    out[2, :, :, 1] = -t3
    out[3] = t234[:, :, None, :] - out[1] - out[2]
    out[4, :, 0] = t5[:, None, :]
    out[4, :, 1] = -t5[:, None, :]
    out[5, :, 0] = t6[:, None, :]
    out[5, :, 1] = t6[:, None, :] + math.pi
    ok = np.empty((2, 2, 2, m), dtype=bool)
    ok[:, :, 0] = ok5 & reach3
    ok[:, :, 1] = ok[:, :, 0] & (s3 >= DEGENERATE)
    return out, ok


__all__ = ["AnalyticURSolver", "BatchSolutions", "URGeometry", "ur_geometry"]
