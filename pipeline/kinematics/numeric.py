"""Iterative IK for any serial arm: Levenberg-Marquardt on Pinocchio Jacobians.

Any joint count (:mod:`pipeline.kinematics.ik` says what IK means for it):

- 6 or more joints, full pose: each attempt minimises F(q) = 1/2 |e(q)|^2 with
  e = log6(base_T_flange(q)^-1 target) (flange-frame twist: linear [m], angular
  [rad]) and the flange Jacobian J in the same frame (Pinocchio ``LOCAL``).
- fewer than 6 joints, position only: e = p_target - p(q) in the base frame and
  the linear rows of the ``LOCAL_WORLD_ALIGNED`` Jacobian; the target's rotation
  is ignored.

A step solves (J^T J + lambda I) dq = J^T e (Cholesky, LAPACK ``dposv``) and is
clamped to the joint limits; joints already at a limit that the step would push
further out are taken out of that step's system (an active set: clamping their
share alone bends the step off the descent direction, and on the Panda's narrow
ranges that halved the first attempt's failures). The damping lambda adapts by the gain ratio
rho = (F(q) - F(q + dq)) / (predicted decrease) (Nielsen 1999): good steps
shrink it towards Gauss-Newton, rejected steps grow it. Near a singularity
J^T J loses rank, undamped steps stop paying off and lambda rises, which is the
damping a singular configuration needs; near the solution it falls away, so
convergence stays quadratic. An attempt ends on success (position error
<= ``tol_m`` and, for a full pose, orientation error <= ``tol_rad``), after
``max_iterations`` trial steps, when lambda exceeds 1e3, or when it stalls far
from the target (after 6 steps, F > 1e-6 and F fell by less than 10 % over the
last 4 steps: a local minimum; measured on ur5, this stops 98 % of doomed
attempts early and 5 % of ones that would have succeeded).

Attempts: the first starts from the seed (default: the middle of the joint
range). Up to :data:`TABLE_STARTS` restarts then start from the robot's seed table
(:mod:`pipeline.kinematics.seeds`: joint vectors whose flange poses are nearest the
target in task space, nearest first); further restarts draw uniformly,
alternately from the middle half of each joint's range and from all of it, by a
generator created per call from ``IKOptions.seed``, so a solve is a pure
function of (target, seed_q, options). (2,000 random Panda targets, pull off: 313
are not reached from the middle of the ranges; the table's nearest pose reaches 75 %
of them in the next attempt, a uniform draw 56 %, and the p99 of the LM iterations
fell from 145 to 59; on ur5 from 96 to 56. On +-2 pi joints the middle half of
the range holds every angle once.)

Redundant arms (more joints than the task has dimensions: 7 for a pose, 4 for a
position) have a self-motion manifold of solutions. Once an attempt reaches the
target, a predictor-corrector walk moves the joints toward the rest posture
(``IKOptions.rest_q``, default the middle of each range) along the self-motion
manifold: predictor dq = J^+ e + N (q_rest - q),
N = I - J^+ J, the pull capped at 0.3 rad per step and clamped to the limits;
corrector: minimum-norm Gauss-Newton steps back to within 1e-4 of the target.
The walk stops when a step gains less than 1 mrad or once it has spent
``null_space_iterations`` steps, predictor and corrector steps alike (a bounded
budget: from a far start the walk is long); the configuration nearest the
rest posture then lands on the solver's tolerance and replaces the first only if
it does and is nearer, so the pull never costs a solution. It minimises
|q - q_rest| locally, on the self-motion branch the attempt landed on (from the
middle of the ranges, 10,000 random Panda targets: 0.09 rad nearer on average
for about 10 more iterations; seeded at far configurations it gains far more).

The returned joint vector is brought to the 2 pi representative nearest the seed
within the limits (same pose, tidier angles).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import lapack

from pipeline.errors import KinematicsError
from pipeline.kinematics.ik import (
    IKOptions,
    IKResult,
    as_pose,
    format_reason,
    position_only,
    seed_or_middle,
    task_dim,
)
from pipeline.kinematics.limits import nearest_representative
from pipeline.kinematics.seeds import seed_table
from pipeline.robots.chain import FLANGE
from pipeline.robots.spec import RobotSpec
from pipeline.robots.urdf import build_pinocchio_model

Array = NDArray[np.float64]

_RESTART_STREAM = 0x5EED_1C  # spawn key of the restart generator
TABLE_STARTS = 8
"""Restarts started from the seed table's poses nearest the target (after the first
attempt, which starts from the seed)."""
STALL_AFTER = 6
STALL_WINDOW = 4
STALL_RATIO = 0.9
STALL_F = 1e-6
LAMBDA_START = 0.1
LAMBDA_MIN = 1e-9
LAMBDA_MAX = 1e3
PULL_STEP_MAX_RAD = 0.3
"""Largest null-space pull per step [rad] (2-norm over the joints): the self-motion
manifold curves, and a longer step lands too far off the target to correct cheaply."""
PULL_DONE_RAD = 1e-3
"""The pull stops once its null-space step is this small [rad], or once a step brings
the joints less than this much nearer the rest posture (held at a limit)."""
PULL_DAMPING = 1e-9
"""Damping of J J^T in the pull's pseudo-inverse (keeps it defined at a singularity)."""
LANDING_STEPS = 6
"""Gauss-Newton steps after each pull step to land back on the target."""
PULL_WALK_TOL = 1e-4
"""The walk's own landing tolerance [m and rad] (looser than the answer's, which only
the configuration kept has to meet)."""


class NumericLMSolver:
    """Damped least squares / Levenberg-Marquardt IK with seeded restarts and, on
    redundant arms, a null-space pull toward a rest posture (module doc)."""

    def __init__(self, spec: RobotSpec, options: IKOptions | None = None) -> None:
        self._spec = spec
        self._options = opts = options or IKOptions()
        self._model = build_pinocchio_model(spec)
        self._data = self._model.createData()
        self._fid = int(self._model.getFrameId(FLANGE))
        self._lower = spec.lower
        self._upper = spec.upper
        self._middle = 0.5 * (spec.lower + spec.upper)
        self._span = spec.upper - spec.lower
        self._reach_m = float(spec.reach_m())  # every link end to end [m]
        self._eye = np.eye(spec.dof)
        self._position_only = position_only(spec)
        self._task_eye = np.eye(task_dim(spec))
        self._rest = self._middle if opts.rest_q is None else self._rest_posture(opts.rest_q)
        self._pull = spec.dof > task_dim(spec) and opts.null_space_iterations > 0

    def _rest_posture(self, rest_q: tuple[float, ...]) -> Array:
        spec = self._spec
        if len(rest_q) != spec.dof:
            raise KinematicsError(
                f"robot '{spec.name}' has {spec.dof} joints; the IK rest posture has "
                f"{len(rest_q)} values {list(rest_q)}"
            )
        rest = np.array(rest_q, dtype=float)
        for name, v, lo, hi in zip(spec.joint_names, rest_q, self._lower, self._upper, strict=True):
            if not lo <= v <= hi:
                raise KinematicsError(
                    f"robot '{spec.name}': the IK rest posture's {name} = {v:.6g} rad is "
                    f"outside its limits [{lo:.6g}, {hi:.6g}] rad"
                )
        return rest

    @property
    def name(self) -> str:
        return "numeric"

    @property
    def spec(self) -> RobotSpec:
        return self._spec

    @property
    def options(self) -> IKOptions:
        return self._options

    @property
    def rest_q(self) -> Array:
        """The rest posture the spare joints are pulled toward [rad] (a copy)."""
        return self._rest.copy()

    def solve(self, base_T_flange: ArrayLike, *, seed_q: ArrayLike | None = None) -> IKResult:
        """One solution [rad] within limits, or an empty result with the best error reached."""
        target = as_pose(base_T_flange)
        seed = self._middle if seed_q is None else seed_or_middle(self._spec, seed_q)
        opts = self._options
        # Beyond every link's length end to end no joint vector reaches: say so without
        # descending (a target at 1e308 m would overflow the error norms)
        p = target[:3, 3]
        biggest = float(np.abs(p).max())
        distance_m = biggest * float(np.linalg.norm(p / biggest)) if biggest > 0 else 0.0
        if distance_m > self._reach_m * (1 + 1e-9) + opts.tol_m:
            why = (
                f"it is {distance_m:.4g} m from the base, beyond the arm's reach of "
                f"{self._reach_m:.4g} m"
            )
            return IKResult(
                np.empty((0, self._spec.dof)), reason=format_reason(self._spec, target, why)
            )
        goal = pin.SE3(target[:3, :3].copy(), target[:3, 3].copy())
        near: Array | None = None  # the seed table's nearest joint vectors, once needed
        rng: np.random.Generator | None = None
        iterations = 0
        best = (math.inf, math.inf)
        for attempt in range(opts.max_restarts + 1):
            if attempt == 0:
                start = np.minimum(np.maximum(seed, self._lower), self._upper)
            elif attempt <= TABLE_STARTS:
                if near is None:
                    near = seed_table(self._spec).nearest(target, TABLE_STARTS)
                start = near[attempt - 1]
            else:
                if rng is None:
                    # made per call: the answer depends on (target, seed_q, options) only;
                    # its own stream, so callers drawing test poses from default_rng(seed)
                    # are not echoed back as restarts
                    rng = np.random.default_rng([opts.seed, _RESTART_STREAM])
                # odd attempts draw from the middle half of each range, even ones from all
                # of it: on +-2 pi joints the middle half already holds every angle once
                half = 0.25 if attempt % 2 else 0.5
                start = self._middle + rng.uniform(-half, half, self._spec.dof) * self._span
            q, used, err = self._attempt(start, goal)
            iterations += used
            if q is not None:
                if self._pull:
                    q, used = self._pull_toward_rest(q, goal)
                    iterations += used
                q = nearest_representative(q, seed, self._lower, self._upper)
                return IKResult(q[None, :], iterations=iterations, restarts=attempt)
            if err[0] + err[1] < best[0] + best[1]:
                best = err
        if self._position_only:
            within = f"no joint vector within {opts.tol_m:g} m"
            closest = f"{best[0]:.3g} m"
        else:
            within = f"no joint vector within {opts.tol_m:g} m / {opts.tol_rad:g} rad"
            closest = f"{best[0]:.3g} m, {best[1]:.3g} rad"
        why = (
            f"{within} after {opts.max_restarts + 1} attempts ({iterations} LM iterations); "
            f"closest: {closest}"
        )
        return IKResult(
            np.empty((0, self._spec.dof)),
            reason=format_reason(self._spec, target, why),
            iterations=iterations,
            restarts=opts.max_restarts,
        )

    def _residual(self, q: Array, goal: pin.SE3) -> tuple[Array, Array]:
        """Kinematics of ``q`` into the data; (task error e, position error vector [m])."""
        model, data = self._model, self._data
        pin.computeJointJacobians(model, data, q)
        placement = pin.updateFramePlacement(model, data, self._fid)
        if self._position_only:
            e: Array = goal.translation - placement.translation
            return e, e
        dm = placement.actInv(goal)
        return pin.log6(dm).vector, dm.translation

    def _errors(self, e: Array, t: Array) -> tuple[float, float]:
        """(position error [m], orientation error [rad]; 0 when position-only) of a
        :meth:`_residual`."""
        if self._position_only:
            return math.sqrt(float(t @ t)), 0.0
        w = e[3:]
        return math.sqrt(float(t @ t)), math.sqrt(float(w @ w))

    def _task_jacobian(self) -> Array:
        """The task Jacobian at the configuration of the last :meth:`_residual`."""
        if self._position_only:
            jac: Array = pin.getFrameJacobian(
                self._model, self._data, self._fid, pin.LOCAL_WORLD_ALIGNED
            )[:3]
            return jac
        out: Array = pin.getFrameJacobian(self._model, self._data, self._fid, pin.LOCAL)
        return out

    def _attempt(self, q0: Array, goal: pin.SE3) -> tuple[Array | None, int, tuple[float, float]]:
        """One LM descent: (solution or None, iterations, (position, orientation) error)."""
        lower, upper = self._lower, self._upper
        tol_m, tol_rad = self._options.tol_m, self._options.tol_rad
        eye = self._eye
        # F = 1/2 |e|^2; a cheap gate before the exact position/angle test
        gate = 0.5 * (tol_m * tol_m + tol_rad * tol_rad)
        q = q0.copy()
        e, t = self._residual(q, goal)
        f = 0.5 * float(e @ e)
        lam, nu = LAMBDA_START, 2.0
        jtj = np.empty(0)
        g = np.empty(0)
        fresh = True
        history = [f]
        it = 0
        for it in range(1, self._options.max_iterations + 1):
            if f <= gate:
                pos, ang = self._errors(e, t)
                if pos <= tol_m and ang <= tol_rad:
                    return q, it - 1, (pos, ang)
            if fresh:
                jac = self._task_jacobian()
                jtj = np.dot(jac.T, jac)  # np.dot: a little cheaper than @ at this size
                g = np.dot(e, jac)
                fresh = False
            _, dq, info = lapack.dposv(jtj + lam * eye, g)
            if info != 0:  # not positive definite: only with a non-finite Jacobian
                break
            dq = dq.reshape(-1)  # LAPACK returns a 0-d array for a one-joint arm
            raw = q + dq
            q_new = np.minimum(np.maximum(raw, lower), upper)
            if (q_new != raw).any():
                # joints held at a limit that the step pushes further out: solve without
                # them (clamping their share alone bends the step off the descent direction)
                blocked = ((q <= lower) & (dq < 0.0)) | ((q >= upper) & (dq > 0.0))
                if blocked.all():
                    break
                if blocked.any():
                    free = np.flatnonzero(~blocked)
                    sub = jtj[free[:, None], free] + lam * eye[: free.size, : free.size]
                    _, dq_free, info = lapack.dposv(sub, g[free])
                    if info != 0:
                        break
                    dq = np.zeros(dq.shape[0])
                    dq[free] = dq_free.reshape(-1)
                    q_new = np.minimum(np.maximum(q + dq, lower), upper)
            e_new, t_new = self._residual(q_new, goal)
            f_new = 0.5 * float(e_new @ e_new)
            predicted = 0.5 * float(dq @ (lam * dq + g))
            rho = (f - f_new) / predicted if predicted > 0.0 else -1.0
            if rho > 0.0:
                q, e, t, f = q_new, e_new, t_new, f_new
                lam = max(LAMBDA_MIN, lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3))
                nu = 2.0
                fresh = True
            else:
                # data now holds q_new's kinematics; J^T J and g of q are kept
                lam *= nu
                nu *= 2.0
                if lam > LAMBDA_MAX:
                    break
            history.append(f)
            # stalled far from the target (a local minimum): restart instead
            if it >= STALL_AFTER and f > STALL_F and f > STALL_RATIO * history[-1 - STALL_WINDOW]:
                break
        pos, ang = self._errors(e, t)
        if pos <= tol_m and ang <= tol_rad:
            return q, it, (pos, ang)
        return None, it, (pos, ang)

    def _pull_toward_rest(self, q0: Array, goal: pin.SE3) -> tuple[Array, int]:
        """Predictor-corrector walk along the self-motion manifold from solution ``q0``
        toward the rest posture: (the solution nearest rest found, steps spent)."""
        lower, upper, rest = self._lower, self._upper, self._rest
        opts = self._options
        damp = PULL_DAMPING * self._task_eye
        z = rest - q0
        d0 = best_d = math.sqrt(float(z @ z))
        best = q = q0
        e, _ = self._residual(q, goal)
        steps = 0
        # the walk lands loosely; only the configuration it keeps lands on the tolerance
        walk_m, walk_rad = max(opts.tol_m, PULL_WALK_TOL), max(opts.tol_rad, PULL_WALK_TOL)
        for _ in range(opts.null_space_iterations):
            # predictor: the null-space part of (rest - q), capped, plus the correction of
            # the residual left by the loose landing; J^+ = J^T (J J^T)^-1, one solve
            jac = self._task_jacobian()
            z = rest - q
            rhs = np.empty((e.shape[0], 2))
            rhs[:, 0] = e
            rhs[:, 1] = jac @ z
            _, y, info = lapack.dposv(jac @ jac.T + damp, rhs)
            if info != 0:  # only with a non-finite Jacobian
                break
            null = z - jac.T @ y[:, 1]
            size = math.sqrt(float(null @ null))
            if size < PULL_DONE_RAD:
                break  # a local minimum of |q - rest| on the manifold (or held at limits)
            if size > PULL_STEP_MAX_RAD:
                null *= PULL_STEP_MAX_RAD / size
            step = jac.T @ y[:, 0] + null
            # corrector: minimum-norm Gauss-Newton steps back near the target
            landed, e, used = self._land(
                np.minimum(np.maximum(q + step, lower), upper), goal, walk_m, walk_rad
            )
            steps += 1 + used
            if landed is None:
                break
            z = rest - landed
            d = math.sqrt(float(z @ z))
            if d < best_d:
                best, best_d = landed, d
            if d > best_d - PULL_DONE_RAD and best is not landed:
                break  # no longer paying off
            q = landed
            if steps >= opts.null_space_iterations:
                break  # the budget: predictor and corrector steps alike
        if best is q0:
            return q0, steps
        final, _, used = self._land(best, goal, opts.tol_m, opts.tol_rad)
        steps += used
        if final is None:
            return q0, steps
        z = rest - final
        return (final if math.sqrt(float(z @ z)) < d0 else q0), steps

    def _land(
        self, q: Array, goal: pin.SE3, tol_m: float, tol_rad: float
    ) -> tuple[Array | None, Array, int]:
        """Up to :data:`LANDING_STEPS` minimum-norm Gauss-Newton steps from ``q`` onto the
        target: (the configuration within the tolerances or None, its task error, steps
        spent). The data is left at the returned configuration's kinematics."""
        lower, upper = self._lower, self._upper
        damp = PULL_DAMPING * self._task_eye
        for step in range(LANDING_STEPS + 1):
            e, t = self._residual(q, goal)
            pos, ang = self._errors(e, t)
            if pos <= tol_m and ang <= tol_rad:
                return q, e, step
            if step == LANDING_STEPS:
                break
            jac = self._task_jacobian()
            _, y, info = lapack.dposv(jac @ jac.T + damp, e)
            if info != 0:
                break
            q = np.minimum(np.maximum(q + jac.T @ y.reshape(-1), lower), upper)
        return None, e, LANDING_STEPS


__all__ = ["NumericLMSolver"]
