"""Time parameterization: TOPP-RA under velocity/acceleration limits, then a jerk-limiting
moving-average filter of the path parameter.

The reference is ``q(t) = path(s_f(t))``:

- ``path(s)``: the geometric path, arc-length (chord) parameterized [rad]. A
  natural cubic spline through the waypoints (a straight line for two
  waypoints); if that curve leaves the joint limits or collides, the waypoints
  are densified so the spline hugs the polyline, and as a last resort the
  polyline itself is used with a stop at every vertex ("stop_and_go").
- ``s(t)``: TOPP-RA's time-optimal profile for the scaled joint velocity and
  acceleration limits (piecewise constant path acceleration, so bang-bang,
  discontinuous joint acceleration), rebuilt exactly from its grid.
- ``s_f(t) = (1/w) * integral of s over [t - w, t]``: a moving average of
  width ``w = smoothing_window_s``. It is a convex combination of admissible
  states, so on straight pieces it keeps the velocity and acceleration limits
  exactly; it makes the path acceleration continuous (jerk <= 2 a_max / w), starts
  and ends at rest with zero acceleration, and lengthens the motion by ``w``.
  The configuration stays exactly on ``path``, so the collision check of the
  path holds for the timed trajectory.

On curved paths the filter and TOPP-RA's grid may overshoot a limit slightly:
the result is checked on a dense time grid and re-run with proportionally
lower limits until it complies.
"""

from __future__ import annotations

import importlib
import logging
import math
import sys
import types
from bisect import bisect_right
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import PlanningError
from pipeline.model.scene import Box
from pipeline.planning.collision import CollisionChecker, motion_check_step_rad
from pipeline.planning.planner import PlannedPath
from pipeline.robots.spec import RobotSpec
from pipeline.trajectory import TrajectorySamples


class _DeferredModule(types.ModuleType):
    """A module that imports the real one at its first attribute read."""

    def __getattr__(self, name: str) -> object:
        return getattr(importlib.import_module(self.__name__), name)


def _import_toppra_without_pyplot() -> None:
    """Import toppra without the ``matplotlib.pyplot`` it imports for debug plots only
    (0.5-2 s of a ``pipeline record`` start, issue 31): while toppra loads, matplotlib and
    its pyplot are stand-ins that import the real ones when toppra first plots."""
    if "toppra" in sys.modules or "matplotlib" in sys.modules:
        return
    mpl, pyplot = _DeferredModule("matplotlib"), _DeferredModule("matplotlib.pyplot")
    mpl.pyplot = pyplot  # type: ignore[attr-defined]
    sys.modules["matplotlib"], sys.modules["matplotlib.pyplot"] = mpl, pyplot
    try:
        import toppra  # noqa: F401
    finally:
        for name, stand_in in (("matplotlib", mpl), ("matplotlib.pyplot", pyplot)):
            if sys.modules.get(name) is stand_in:
                del sys.modules[name]


_import_toppra_without_pyplot()
import toppra  # noqa: E402
import toppra.algorithm as toppra_algo  # noqa: E402
import toppra.constraint as toppra_constraint  # noqa: E402

F64 = NDArray[np.float64]
Interpolation = Literal["spline", "stop_and_go"]

DEFAULT_SMOOTHING_WINDOW_S = 0.05
LIMIT_TOLERANCE = 1e-6  # relative overshoot accepted after the re-timing loop
_MAX_RETIME = 8
_DENSIFY_FACTORS = (2, 4, 8)
_CHECK_DT_S = 1e-4


class StateChecker(Protocol):
    """Anything that says whether a configuration is allowed (e.g. ``CollisionChecker``)."""

    def is_valid(self, q: ArrayLike) -> bool: ...


@dataclass(frozen=True, eq=False)
class TimedTrajectory:
    """A C2 joint reference ``q(t) = path(s_f(t))``; implements ``pipeline.sim.result.Reference``.

    Before 0 it holds the start, after ``duration_s`` the goal, with zero
    velocity and acceleration.

    Attributes:
        joint_names: joint order.
        waypoints: (K, n) vertices of the interpolated geometric path [rad].
        interpolation: "spline" (smooth curve through ``waypoints``) or
            "stop_and_go" (the polyline, at rest at every vertex).
        duration_s: motion time [s].
        velocity_limits: scaled limits the trajectory respects [rad/s].
        acceleration_limits: scaled limits the trajectory respects [rad/s^2].
        smoothing_window_s: moving-average width ``w`` [s].
        time_breaks_s: (M+1,) breakpoints of ``s_f(t)`` [s].
        s_coeffs: (M, 4) cubic coefficients of ``s_f`` per interval, increasing powers
            of ``t - time_breaks_s[k]``.
        path_breaks: (P+1,) breakpoints of ``path(s)`` [rad].
        path_coeffs: (P, 4, n) cubic coefficients of ``path`` per piece, increasing powers.
    """

    joint_names: tuple[str, ...]
    waypoints: F64
    interpolation: Interpolation
    duration_s: float
    velocity_limits: F64
    acceleration_limits: F64
    smoothing_window_s: float
    time_breaks_s: F64
    s_coeffs: F64
    path_breaks: F64
    path_coeffs: F64
    _tb: list[float] = field(init=False, repr=False)
    _sc: list[tuple[float, ...]] = field(init=False, repr=False)
    _sb: list[float] = field(init=False, repr=False)
    _qc: list[F64] = field(init=False, repr=False)
    _start: F64 = field(init=False, repr=False)
    _goal: F64 = field(init=False, repr=False)
    _zeros: F64 = field(init=False, repr=False)

    def __post_init__(self) -> None:
        # plain-Python copies for the 1 kHz ``sample`` hot path (bisect on lists,
        # float arithmetic on tuples is several times faster than numpy scalars)
        n = len(self.joint_names)
        cache = {
            "_tb": [float(x) for x in self.time_breaks_s],
            "_sc": [tuple(float(v) for v in row) for row in self.s_coeffs],
            "_sb": [float(x) for x in self.path_breaks],
            "_qc": [np.ascontiguousarray(c) for c in self.path_coeffs],
            "_start": self.waypoints[0].copy(),
            "_goal": self.waypoints[-1].copy(),
            "_zeros": np.zeros(n),
        }
        for k, v in cache.items():
            object.__setattr__(self, k, v)

    @property
    def start(self) -> F64:
        return self._start

    @property
    def goal(self) -> F64:
        return self._goal

    def sample(self, t_s: float) -> tuple[F64, F64, F64]:
        """Position [rad], velocity [rad/s], acceleration [rad/s^2] at ``t_s`` [s]."""
        if t_s <= 0.0:
            return self._start.copy(), self._zeros.copy(), self._zeros.copy()
        if t_s >= self.duration_s:
            return self._goal.copy(), self._zeros.copy(), self._zeros.copy()
        tb = self._tb
        k = bisect_right(tb, t_s) - 1
        if k >= len(tb) - 1:
            k = len(tb) - 2
        x = t_s - tb[k]
        c0, c1, c2, c3 = self._sc[k]
        s = c0 + x * (c1 + x * (c2 + x * c3))
        sd = c1 + x * (2.0 * c2 + 3.0 * x * c3)
        sdd = 2.0 * c2 + 6.0 * x * c3
        sb = self._sb
        j = bisect_right(sb, s) - 1
        if j < 0:
            j = 0
        elif j >= len(sb) - 1:
            j = len(sb) - 2
        y = s - sb[j]
        y2 = y * y
        sd2 = sd * sd
        # rows: q = path(s), qd = path'(s) sd, qdd = path'(s) sdd + path''(s) sd^2
        basis = np.array(
            (
                (1.0, y, y2, y2 * y),
                (0.0, sd, 2.0 * y * sd, 3.0 * y2 * sd),
                (0.0, sdd, 2.0 * y * sdd + 2.0 * sd2, 3.0 * y2 * sdd + 6.0 * y * sd2),
            )
        )
        out: F64 = basis @ self._qc[j]
        return out[0], out[1], out[2]

    def _path_parameter(self, t: F64) -> tuple[F64, F64, F64]:
        """s_f, its first and second time derivatives at times ``t`` (inside [0, T])."""
        m = len(self.time_breaks_s) - 1
        k = np.clip(np.searchsorted(self.time_breaks_s, t, side="right") - 1, 0, m - 1)
        x = t - self.time_breaks_s[k]
        c = self.s_coeffs[k]
        s = c[:, 0] + x * (c[:, 1] + x * (c[:, 2] + x * c[:, 3]))
        sd = c[:, 1] + x * (2.0 * c[:, 2] + 3.0 * x * c[:, 3])
        sdd = 2.0 * c[:, 2] + 6.0 * x * c[:, 3]
        return s, sd, sdd

    def sample_many(self, times_s: ArrayLike) -> tuple[F64, F64, F64]:
        """Vectorized ``sample``: (K,) times [s] -> three (K, n) arrays."""
        t = np.asarray(times_s, dtype=np.float64)
        s, sd, sdd = self._path_parameter(np.clip(t, 0.0, self.duration_s))
        p = len(self.path_breaks) - 1
        j = np.clip(np.searchsorted(self.path_breaks, s, side="right") - 1, 0, p - 1)
        y = (s - self.path_breaks[j])[:, None]
        a = self.path_coeffs[j]  # (K, 4, n)
        q = a[:, 0] + y * (a[:, 1] + y * (a[:, 2] + y * a[:, 3]))
        dq = a[:, 1] + y * (2.0 * a[:, 2] + 3.0 * y * a[:, 3])
        ddq = 2.0 * a[:, 2] + 6.0 * y * a[:, 3]
        qd = dq * sd[:, None]
        qdd = dq * sdd[:, None] + ddq * (sd * sd)[:, None]
        before, after = t <= 0.0, t >= self.duration_s
        q[before], q[after] = self.waypoints[0], self.waypoints[-1]
        qd[before | after] = 0.0
        qdd[before | after] = 0.0
        return q, qd, qdd

    def samples(self, dt_s: float) -> TrajectorySamples:
        """Samples every ``dt_s`` [s] from 0 up to and including the first instant >= the end."""
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise PlanningError(f"dt_s: expected a positive number of seconds, got {dt_s!r}")
        count = math.ceil(self.duration_s / dt_s - 1e-9) + 1
        times = np.arange(count, dtype=np.float64) * dt_s
        q, qd, qdd = self.sample_many(times)
        return TrajectorySamples(times_s=times, positions=q, velocities=qd, accelerations=qdd)

    def limit_ratios(self, *, dt_s: float = _CHECK_DT_S) -> tuple[float, float]:
        """Max of |qd|/v_lim and |qdd|/a_lim over a dense grid plus every kink.

        Acceleration kinks (where maxima sit) are at the breakpoints of ``s_f(t)``
        and where ``s_f`` crosses a breakpoint of the path spline; both are sampled
        exactly, so only smooth maxima between grid points can be missed (by
        O(dt^2)).
        """
        grid = np.arange(0.0, self.duration_s, dt_s)
        s_grid, _, _ = self._path_parameter(grid)
        inner = self.path_breaks[1:-1]
        crossings = np.interp(inner, s_grid, grid)
        for _ in range(4):  # Newton on s_f(t) = break, where s_f is moving
            s, sd, _ = self._path_parameter(crossings)
            moving = sd > 1e-9
            crossings[moving] -= (s[moving] - inner[moving]) / sd[moving]
            crossings = np.clip(crossings, 0.0, self.duration_s)
        times = np.concatenate([grid, self.time_breaks_s, crossings])
        _, qd, qdd = self.sample_many(times)
        r_v = float(np.max(np.abs(qd) / self.velocity_limits, initial=0.0))
        r_a = float(np.max(np.abs(qdd) / self.acceleration_limits, initial=0.0))
        return r_v, r_a


# ---------------------------------------------------------------- geometric path


class _Clear:
    """Planner semantics for a ``CollisionChecker``: within limits and clear by its padding."""

    def __init__(self, checker: CollisionChecker) -> None:
        self._checker = checker

    def is_valid(self, q: ArrayLike) -> bool:
        return self._checker.within_limits(q) and self._checker.is_clear(q)


@dataclass(frozen=True)
class _GeomPath:
    kind: Interpolation
    waypoints: F64
    breaks: F64  # (P+1,) chord-length breakpoints
    coeffs: F64  # (P, 4, n), increasing powers


def _chord(waypoints: F64) -> F64:
    seg = np.linalg.norm(np.diff(waypoints, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def _spline_path(waypoints: F64) -> _GeomPath:
    ss = _chord(waypoints)
    if len(waypoints) == 2:
        return _polyline_path(waypoints, kind="spline")
    interp = toppra.SplineInterpolator(ss, waypoints, bc_type="natural")
    c = np.asarray(interp.cspl.c)  # (4, P, n), decreasing powers
    return _GeomPath("spline", waypoints, ss, np.ascontiguousarray(c[::-1].transpose(1, 0, 2)))


def _polyline_path(waypoints: F64, *, kind: Interpolation = "stop_and_go") -> _GeomPath:
    ss = _chord(waypoints)
    p, n = len(waypoints) - 1, waypoints.shape[1]
    coeffs = np.zeros((p, 4, n))
    coeffs[:, 0] = waypoints[:-1]
    coeffs[:, 1] = np.diff(waypoints, axis=0) / np.diff(ss)[:, None]
    return _GeomPath(kind, waypoints, ss, coeffs)


def _densify(waypoints: F64, factor: int) -> F64:
    out = [waypoints[0]]
    for qa, qb in pairwise(waypoints):
        out.extend(qa + (qb - qa) * (k / factor) for k in range(1, factor + 1))
    return np.array(out)


def _eval_path(path: _GeomPath, s: F64) -> F64:
    j = np.clip(np.searchsorted(path.breaks, s, side="right") - 1, 0, len(path.coeffs) - 1)
    y = (s - path.breaks[j])[:, None]
    a = path.coeffs[j]
    q: F64 = a[:, 0] + y * (a[:, 1] + y * (a[:, 2] + y * a[:, 3]))
    return q


def _first_invalid(path: _GeomPath, checker: StateChecker, step_rad: float) -> F64 | None:
    """First configuration on ``path`` that ``checker`` rejects, checked every <= step_rad."""
    length = float(path.breaks[-1])
    count = max(2, math.ceil(4.0 * length / step_rad) + 1)
    while True:
        qs = _eval_path(path, np.linspace(0.0, length, count))
        if np.max(np.linalg.norm(np.diff(qs, axis=0), axis=1)) <= step_rad:
            break
        count *= 2
    for q in qs:
        if not checker.is_valid(q):
            return np.asarray(q, dtype=np.float64)
    return None


# ---------------------------------------------------------------- time scaling


@dataclass(frozen=True)
class _Profile:
    """Piecewise quadratic s(t): on [t_k, t_{k+1}], s = c0 + c1 x + c2 x^2, x = t - t_k."""

    breaks: F64  # (M+1,)
    coeffs: F64  # (M, 3)


def _toppra_profile(path: _GeomPath, vlim: F64, alim: F64) -> _Profile:
    """TOPP-RA's rest-to-rest time-optimal profile of ``path``, rebuilt exactly from its grid."""
    if len(path.waypoints) == 2 or path.kind == "stop_and_go":
        # a single straight piece (stop_and_go calls this per segment)
        geom = toppra.SplineInterpolator(
            path.breaks[[0, -1]], path.waypoints[[0, -1]], bc_type="natural"
        )
    else:
        geom = toppra.SplineInterpolator(path.breaks, path.waypoints, bc_type="natural")
    constraints = [
        toppra_constraint.JointVelocityConstraint(np.stack([-vlim, vlim], axis=1)),
        toppra_constraint.JointAccelerationConstraint(np.stack([-alim, alim], axis=1)),
    ]
    algo = toppra_algo.TOPPRA(constraints, geom, parametrizer="ParametrizeConstAccel")
    algo.compute_parameterization(0.0, 0.0)
    data = algo.problem_data
    if data.return_code != toppra_algo.ParameterizationReturnCode.Ok or data.sd_vec is None:
        raise PlanningError(
            f"time parameterization failed (TOPP-RA: {data.return_code}); expected a "
            "feasible path for the velocity/acceleration limits"
        )
    grid = np.asarray(data.gridpoints, dtype=np.float64)
    sd = np.sqrt(np.maximum(np.asarray(data.sd_vec, dtype=np.float64) ** 2, 0.0))
    ds = np.diff(grid)
    denom = sd[:-1] + sd[1:]
    if np.any(denom <= 0.0):
        raise PlanningError("time parameterization failed: TOPP-RA stopped inside the path")
    dt = 2.0 * ds / denom
    u = (sd[1:] ** 2 - sd[:-1] ** 2) / (2.0 * ds)
    breaks = np.concatenate([[0.0], np.cumsum(dt)])
    coeffs = np.stack([grid[:-1], sd[:-1], 0.5 * u], axis=1)
    return _Profile(breaks, coeffs)


def _join(profiles: Sequence[_Profile], s_starts: Sequence[float], dwell_s: float) -> _Profile:
    """Concatenate rest-to-rest profiles, holding ``dwell_s`` at each junction."""
    breaks: list[F64] = []
    coeffs: list[F64] = []
    t0 = 0.0
    for i, (prof, s0) in enumerate(zip(profiles, s_starts, strict=True)):
        if i > 0:
            breaks.append(np.array([t0]))
            coeffs.append(np.array([[s0, 0.0, 0.0]]))
            t0 += dwell_s
        c = prof.coeffs.copy()
        c[:, 0] += s0
        breaks.append(prof.breaks[:-1] + t0)
        coeffs.append(c)
        t0 += float(prof.breaks[-1])
    breaks.append(np.array([t0]))
    return _Profile(np.concatenate(breaks), np.concatenate(coeffs))


def _filter(profile: _Profile, length: float, w: float) -> tuple[F64, F64]:
    """Moving average of width ``w`` of s(t) (s = 0 before 0, = length after the end).

    Returns:
        breaks (M+1,) from 0 to T + w and cubic coefficients (M, 4), increasing powers.
    """
    tb, c = profile.breaks, profile.coeffs
    m = len(c)
    dt = np.diff(tb)
    # S(t) = integral_0^t s: values at the breakpoints
    piece_int = c[:, 0] * dt + c[:, 1] * dt**2 / 2 + c[:, 2] * dt**3 / 3
    s_at = np.concatenate([[0.0], np.cumsum(piece_int)])
    t_end = float(tb[-1])

    def derivs(t: F64) -> tuple[F64, F64, F64, F64]:
        """S, s, sd, sdd at times t (any real)."""
        k = np.clip(np.searchsorted(tb, t, side="right") - 1, 0, m - 1)
        x = t - tb[k]
        a0, a1, a2 = c[k, 0], c[k, 1], c[k, 2]
        big_s = s_at[k] + a0 * x + a1 * x**2 / 2 + a2 * x**3 / 3
        s = a0 + a1 * x + a2 * x**2
        sd = a1 + 2 * a2 * x
        sdd = 2 * a2
        before, after = t < 0.0, t > t_end
        big_s = np.where(before, 0.0, np.where(after, s_at[-1] + length * (t - t_end), big_s))
        s = np.where(before, 0.0, np.where(after, length, s))
        sd = np.where(before | after, 0.0, sd)
        sdd = np.where(before | after, 0.0, sdd)
        return big_s, s, sd, sdd

    merged = np.unique(np.concatenate([tb, tb + w]))
    keep = np.concatenate([[True], np.diff(merged) > 1e-12 * max(1.0, t_end)])
    merged = merged[keep]
    merged[-1] = t_end + w
    mid = 0.5 * (merged[:-1] + merged[1:])
    now, ago = derivs(mid), derivs(mid - w)
    f = [(a - b) / w for a, b in zip(now, ago, strict=True)]  # f, f', f'', f''' at mid
    # Taylor at mid -> coefficients around the left breakpoint (robust to the
    # breakpoint itself being a hair off after the +w shift)
    d = merged[:-1] - mid
    out = np.zeros((len(mid), 4))
    fact = [1.0, 1.0, 2.0, 6.0]
    for j in range(4):
        for order in range(j, 4):
            out[:, j] += f[order] * d ** (order - j) / (fact[order - j] * fact[j])
    return merged, out


def _retimed(
    spec: RobotSpec,
    path: _GeomPath,
    vlim: F64,
    alim: F64,
    w: float,
) -> TimedTrajectory:
    """TOPP-RA + filter, lowering the limits given to TOPP-RA until the result complies."""
    f_v = f_a = 1.0
    ratios = (math.inf, math.inf)
    for _ in range(_MAX_RETIME):
        if path.kind == "stop_and_go":
            pieces = [
                _toppra_profile(_polyline_path(path.waypoints[i : i + 2]), vlim * f_v, alim * f_a)
                for i in range(len(path.waypoints) - 1)
            ]
            profile = _join(pieces, path.breaks[:-1].tolist(), w)
        else:
            profile = _toppra_profile(path, vlim * f_v, alim * f_a)
        breaks, coeffs = _filter(profile, float(path.breaks[-1]), w)
        traj = TimedTrajectory(
            joint_names=spec.joint_names,
            waypoints=path.waypoints,
            interpolation=path.kind,
            duration_s=float(breaks[-1]),
            velocity_limits=vlim,
            acceleration_limits=alim,
            smoothing_window_s=w,
            time_breaks_s=breaks,
            s_coeffs=coeffs,
            path_breaks=path.breaks,
            path_coeffs=path.coeffs,
        )
        ratios = traj.limit_ratios()
        if max(ratios) <= 1.0 + LIMIT_TOLERANCE:
            return traj
        # velocity scales with f_v; acceleration with f_a (and with f_v^2 on curves)
        if ratios[0] > 1.0:
            f_v /= ratios[0] * (1.0 + 1e-4)
        if ratios[1] > 1.0:
            f_a /= ratios[1] * (1.0 + 1e-4)
    raise PlanningError(
        f"time parameterization exceeds the limits by {max(ratios) - 1:.2%} after "
        f"{_MAX_RETIME} re-timings (velocity x{ratios[0]:.4f}, acceleration "
        f"x{ratios[1]:.4f}); expected <= 1"
    )


def _rest(spec: RobotSpec, q: F64, vlim: F64, alim: F64, w: float) -> TimedTrajectory:
    n = spec.dof
    return TimedTrajectory(
        joint_names=spec.joint_names,
        waypoints=np.stack([q, q]),
        interpolation="spline",
        duration_s=0.0,
        velocity_limits=vlim,
        acceleration_limits=alim,
        smoothing_window_s=w,
        time_breaks_s=np.array([0.0, 1.0]),
        s_coeffs=np.zeros((1, 4)),
        path_breaks=np.array([0.0, 1.0]),
        path_coeffs=np.concatenate([q[None, None, :], np.zeros((1, 3, n))], axis=1),
    )


def _scaling(value: float, name: str) -> float:
    if not (isinstance(value, int | float) and 0.0 < value <= 1.0):
        raise PlanningError(f"{name}: expected a factor in (0, 1], got {value!r}")
    return float(value)


def time_parameterize(
    spec: RobotSpec,
    path: PlannedPath | ArrayLike,
    *,
    velocity_scaling: float = 1.0,
    acceleration_scaling: float = 1.0,
    smoothing_window_s: float = DEFAULT_SMOOTHING_WINDOW_S,
    obstacles: Sequence[Box] | None = None,
    checker: StateChecker | None = None,
) -> TimedTrajectory:
    """Time-parameterize a joint path within the (scaled) velocity and acceleration limits.

    Args:
        spec: the robot (its ``velocity_limits`` and ``acceleration_limits``).
        path: a ``PlannedPath`` or (K, n) waypoints [rad].
        velocity_scaling: MoveIt's ``max_velocity_scaling_factor``, in (0, 1].
        acceleration_scaling: MoveIt's ``max_acceleration_scaling_factor``, in (0, 1].
        smoothing_window_s: moving-average width [s]; bounds jerk by 2 a_max / w.
        obstacles: for the collision check of the interpolated path; default: the
            ``PlannedPath``'s obstacles, or none.
        checker: overrides the check of the interpolated path (anything with
            ``is_valid(q)``); default: the obstacles with the plan's padding.

    Raises:
        PlanningError: bad arguments, waypoints outside the limits, or a path that is
            in collision even as the plain polyline.
    """
    vs = _scaling(velocity_scaling, "velocity_scaling")
    acs = _scaling(acceleration_scaling, "acceleration_scaling")
    if not (isinstance(smoothing_window_s, int | float) and smoothing_window_s > 0.0):
        raise PlanningError(
            f"smoothing_window_s: expected a positive number of seconds, got {smoothing_window_s!r}"
        )
    w = float(smoothing_window_s)
    if isinstance(path, PlannedPath):
        raw = path.waypoints
        if obstacles is None:
            obstacles = path.obstacles
    else:
        raw = np.asarray(path, dtype=np.float64)
    if raw.ndim != 2 or raw.shape[1] != spec.dof or raw.shape[0] < 1:
        raise PlanningError(
            f"path_waypoints: expected shape (K, {spec.dof}) with K >= 1, got {raw.shape}"
        )
    if not np.all(np.isfinite(raw)):
        raise PlanningError("path_waypoints: expected finite joint positions")
    keep = np.concatenate([[True], np.linalg.norm(np.diff(raw, axis=0), axis=1) > 1e-12])
    waypoints = np.array(raw[keep], dtype=np.float64)
    vlim = spec.velocity_limits * vs
    alim = spec.acceleration_limits * acs
    if isinstance(path, PlannedPath):
        padding, step = path.padding_m, path.check_step_rad
    else:
        exact = CollisionChecker(spec, obstacles=obstacles or ())
        exact.check_state(waypoints[0], "path start")
        exact.check_state(waypoints[-1], "path goal")
        padding = exact.planning_padding_m(waypoints[0], waypoints[-1])
        step = motion_check_step_rad(spec, padding)
    if checker is None:
        checker = _Clear(CollisionChecker(spec, obstacles=obstacles or (), padding_m=padding))
    if len(waypoints) == 1:
        if not checker.is_valid(waypoints[0]):
            raise PlanningError(
                f"path_waypoints: {np.round(waypoints[0], 4).tolist()} is in collision or "
                "outside the joint limits"
            )
        return _rest(spec, waypoints[0], vlim, alim, w)
    candidates = [_spline_path(waypoints)]
    if len(waypoints) > 2:
        candidates += [_spline_path(_densify(waypoints, k)) for k in _DENSIFY_FACTORS]
        candidates.append(_polyline_path(waypoints))
    bad: F64 | None = None
    for geom in candidates:
        bad = _first_invalid(geom, checker, step)
        if bad is None:
            return _retimed(spec, geom, vlim, alim, w)
    assert bad is not None
    raise PlanningError(
        f"path_waypoints: the path is in collision or outside the joint limits at q = "
        f"{np.round(bad, 4).tolist()}; expected a collision-free path (plan it with plan_path)"
    )


logging.getLogger("toppra").setLevel(logging.WARNING)  # toppra logs every solve at INFO
