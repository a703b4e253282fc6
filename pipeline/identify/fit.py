# long: the fit and its standard errors (iid, Newey-West, bootstrap) share one regressor
"""Weighted least squares on the base parameters, then a physically consistent model.

1. Stack the base regressor ``Y_b`` and torques of every sample, leaving out a joint's
   rows while it moves slower than ``min_speed_rad_s`` (sticking friction is no
   function of ``sign(qd)``) or, on filtered samples, while a stuck joint is within the
   filter's reach (:func:`kept_rows`). On filtered samples the Coulomb columns are
   filtered like the torque (:meth:`.JointSamples.coulomb`).
2. Check the excitation: pivoted QR of the column-normalized ``Y_b``; parameters whose
   pivot falls below ``1 / max_condition`` of the first are not excited (an error
   naming them).
3. Ordinary least squares, per-joint residual standard deviation ``sigma_j``, then
   weighted least squares with weights ``1 / sigma_j`` (Gautier & Poignet 2001). The
   standard error per base parameter is residual-based (:mod:`.covariance`): the
   Newey-West sandwich over the weighted scores, Andrews' AR(1) bandwidth, because the
   filtered, decimated residuals are correlated in time and across joints; the
   textbook ``s^2 (Y_w^T Y_w)^-1`` (kept as ``std_error_iid``) is several times too small.
4. Physical consistency: over every link's log-Cholesky vector (:mod:`.physical`,
   physical by construction), armature, Coulomb and viscous friction >= 0 and offsets,
   minimise ``||Y_w (E theta - beta_wls)||^2`` (the weighted residual's increase over
   the WLS optimum, via the R factor of ``Y_w``), plus a small pull of the
   *unidentifiable* part of ``theta`` (the null space of ``E``) towards the CAD values,
   which leaves the base parameters alone. Armature and friction are squares (>= 0).
   Start: the WLS fit where physical, else the CAD model. Solver: SciPy's
   ``least_squares`` (MINPACK Levenberg-Marquardt), on one BLAS thread.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
from numpy.typing import NDArray
from scipy import optimize

from pipeline.errors import IdentificationError
from pipeline.identify import covariance, physical
from pipeline.identify.blas import one_thread
from pipeline.identify.defaults import (
    DEFAULT_MAX_CONDITION,
    DEFAULT_MIN_SPEED_RAD_S,
)
from pipeline.identify.model_file import TransitionSpeed, coulomb_shape
from pipeline.identify.regressor import (
    ARMATURE,
    COULOMB,
    PER_JOINT,
    VISCOUS,
    BaseParameters,
    Regressor,
    base_parameters,
    standard_names,
    standard_parameters,
)
from pipeline.identify.samples import JointSamples
from pipeline.pathlist import summarise_paths
from pipeline.robots.spec import RobotSpec

F64 = NDArray[np.float64]

STUCK_SPEED_RAD_S = 1e-3
"""A joint moving slower than this (unfiltered) sticks [rad/s]."""
STUCK_SHARE = 0.01
"""A filtered row is left out when this share of its low-passed torque comes from samples
where the joint sticks (:func:`kept_rows`)."""
NULL_SPACE_WEIGHT = 1e-4
"""Weight of the pull towards CAD in the unidentifiable directions (relative)."""
MIN_ROWS_PER_PARAMETER = 10
MAX_EVALUATIONS = 100
COST_TOL = 1e-8
"""Stop when an iteration lowers the cost by less than this share (an optimum on the
boundary of the physical set lies at infinity in log-Cholesky coordinates)."""
ROUNDING_TOL = 1e-9
START_MIN = 1e-4
MARGIN_REL = 1e-6
MARGIN_MIN_KG_M2 = 1e-9


@dataclass(frozen=True)
class FitResult:
    """An identification.

    Attributes:
        base: the base parameters identified.
        beta_wls: (rank,) weighted least-squares estimate.
        std_error: (rank,) standard error of ``beta_wls``: Newey-West (HAC), see
            :mod:`.covariance`.
        beta: (rank,) base parameters of the physically consistent model.
        theta: (n_standard,) the physically consistent standard parameters.
        theta_cad: (n_standard,) the CAD model's (start and null-space prior).
        condition_number: of the base regressor ``Y_b`` (unweighted).
        condition_number_scaled: of ``Y_b`` with unit-norm columns.
        joint_sigma_nm: (dof,) first-pass (OLS) residual RMS per joint [N m].
        residual_rms_nm: (dof,) residual RMS of the consistent model per joint [N m].
        torque_rms_nm: (dof,) RMS of the fitted torque per joint [N m].
        rows: equations used (joint samples above the speed threshold).
        projection_cost: increase of the weighted residual's sum of squares from the WLS
            estimate to the physically consistent one, as a share of the weighted
            torque's (0: the WLS estimate is physical).
        torque_side: ``motor`` (armature identified) or ``link`` (armature columns left
            out: the CAD armature is kept).
        torque_side_reason: why (declared, or what the detection saw).
        transition_speed_rad_s: the Coulomb column's ``tanh`` speed (0: ``sign``).
        std_error_iid: (rank,) the textbook ``s^2 (Y_w^T Y_w)^-1`` standard error
            (white residuals assumed; too small on filtered data).
        std_error_bootstrap: (rank,) moving-block bootstrap standard error (blocks of
            ``hac_lags + 1`` instants, :data:`BOOTSTRAP_REPLICATES` seeded replicates).
        hac_lags: the Newey-West bandwidth (Andrews' AR(1) plug-in rule).
    """

    base: BaseParameters
    beta_wls: F64
    std_error: F64
    beta: F64
    theta: F64
    theta_cad: F64
    condition_number: float
    condition_number_scaled: float
    joint_sigma_nm: F64
    residual_rms_nm: F64
    torque_rms_nm: F64
    rows: int
    projection_cost: float
    torque_side: str = "motor"
    torque_side_reason: str = "declared"
    transition_speed_rad_s: TransitionSpeed = 0.0
    std_error_iid: F64 | None = None
    std_error_bootstrap: F64 | None = None
    hac_lags: int = 0


BOOTSTRAP_REPLICATES = 400
BOOTSTRAP_SEED = 0
TORQUE_SIDES = ("auto", "motor", "link")
ARMATURE_FLOOR_KG_M2 = 1e-6
"""An armature estimate below this (or below two standard errors) is not seen."""


class UnexcitedError(IdentificationError):
    """The data do not excite some base parameters (``weak``: their names)."""

    def __init__(self, message: str, weak: Sequence[str]) -> None:
        super().__init__(message)
        self.weak = tuple(weak)


def stuck_rows_method() -> dict[str, str | float]:
    """The stuck-row rule of :func:`kept_rows` as a model file's ``method`` records it."""
    return {
        "rule": "a filtered row is left out of fit and validate when at least max_share of "
        "its low-passed torque comes from samples whose unfiltered speed is below speed_rad_s",
        "speed_rad_s": STUCK_SPEED_RAD_S,
        "max_share": STUCK_SHARE,
    }


def kept_rows(s: JointSamples, min_speed_rad_s: float) -> NDArray[np.bool_]:
    """Which of a recording's joint samples (sample-major, as :func:`stacked` stacks them)
    the fit uses: faster than ``min_speed_rad_s``, and, on filtered samples, no stuck
    joint within the filter's reach (:meth:`.JointSamples.stuck_share` below
    :data:`STUCK_SHARE`): while a joint sticks its friction is whatever holds it, no
    ``fc sign(qd)``, and the low-pass spreads that into the rows around it."""
    keep = np.abs(s.qd) >= min_speed_rad_s
    share = s.stuck_share(STUCK_SPEED_RAD_S)
    if share is not None:
        keep &= share < STUCK_SHARE
    return np.asarray(keep.ravel(), dtype=bool)


def stacked(
    spec: RobotSpec,
    samples: Sequence[JointSamples],
    *,
    min_speed_rad_s: float,
    transition_speed_rad_s: TransitionSpeed = 0.0,
) -> tuple[F64, F64, NDArray[np.intp]]:
    """Standard regressor rows, torques and each row's joint, slow rows left out."""
    reg = Regressor(spec, transition_speed_rad_s=transition_speed_rad_s)
    ys, taus, joints = [], [], []
    for s in samples:
        y = reg.stacked(s.q, s.qd, s.qdd, coulomb=s.coulomb(transition_speed_rad_s))
        keep = kept_rows(s, min_speed_rad_s)
        ys.append(y[keep])
        taus.append(s.tau_nm.ravel()[keep])
        joints.append(np.tile(np.arange(spec.dof), s.q.shape[0])[keep])
    return np.concatenate(ys), np.concatenate(taus), np.concatenate(joints)


TRANSITION_CANDIDATES_RAD_S = (0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.5)
"""The transition speeds a fitted sigmoid friction model chooses from [rad/s]."""
JOINT_TRANSITION_CANDIDATES_RAD_S = (
    0.01, 0.02, 0.03, 0.05, 0.07, 0.1, 0.13, 0.16, 0.2, 0.25, 0.3, 0.4, 0.5, 0.7,
)  # fmt: skip
"""The candidates of a per-joint fitted transition speed [rad/s] (a finer grid: each joint
is searched alone)."""
JOINT_TRANSITION_SWEEPS = 2
"""Sweeps over the joints of the per-joint search (the second changed nothing measured)."""


def fitted_transition_speed(
    spec: RobotSpec,
    samples: Sequence[JointSamples],
    *,
    min_speed_rad_s: float = DEFAULT_MIN_SPEED_RAD_S,
    candidates: Sequence[float] = TRANSITION_CANDIDATES_RAD_S,
    per_joint: bool = False,
) -> tuple[TransitionSpeed, dict[float, float]]:
    """The sigmoid model's transition speed ``v_s`` the data fit best: per candidate, the
    least-squares residual (per-joint RMS-normalized rows) with Coulomb columns
    ``tanh(qd / v_s)``; the smallest wins (a grid search: the torque is not linear in
    ``v_s``).

    ``per_joint``: then, from the best common speed, each joint's own speed, searched over
    :data:`JOINT_TRANSITION_CANDIDATES_RAD_S` one joint at a time with the others held
    (coordinate descent, :data:`JOINT_TRANSITION_SWEEPS` sweeps): real joints differ (Gaz
    et al.'s Panda: 0.12-0.39 rad/s).

    Returns:
        The chosen speed [rad/s] (a tuple, one per joint, with ``per_joint``) and each
        common candidate's residual sum of squares.
    """
    with one_thread():
        y, tau, joint_of = stacked(spec, samples, min_speed_rad_s=min_speed_rad_s)
        kept = [kept_rows(s, min_speed_rad_s) for s in samples]
        base = base_parameters(spec)
        scale = 1.0 / np.maximum(_per_joint_rms(tau, joint_of, spec.dof), 1e-9)[joint_of]
        rows = np.arange(tau.size)
        coulomb = PER_JOINT * joint_of + COULOMB

        def cost(v_s: F64) -> float:
            speeds = tuple(float(v) for v in v_s)
            shapes = (s.coulomb(speeds) for s in samples)
            y[rows, coulomb] = np.concatenate(
                [
                    (coulomb_shape(s.qd, speeds) if c is None else c).ravel()[k]
                    for s, c, k in zip(samples, shapes, kept, strict=True)
                ]
            )
            y_b = y[:, base.columns] * scale[:, None]
            beta = np.linalg.lstsq(y_b, tau * scale, rcond=None)[0]
            return float(np.sum((tau * scale - y_b @ beta) ** 2))

        costs = {float(v): cost(np.full(spec.dof, float(v))) for v in candidates}
        common = min(costs, key=lambda v: costs[v])
        if not per_joint:
            return common, costs
        speeds = np.full(spec.dof, common)
        for _ in range(JOINT_TRANSITION_SWEEPS):
            for j in range(spec.dof):
                tried = {}
                for v in JOINT_TRANSITION_CANDIDATES_RAD_S:
                    speeds[j] = v
                    tried[v] = cost(speeds)
                speeds[j] = min(tried, key=lambda v: tried[v])
    return tuple(float(v) for v in speeds), costs


def row_instants(
    spec: RobotSpec, samples: Sequence[JointSamples], *, min_speed_rad_s: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Each row of :func:`stacked`: its sample index and its recording index."""
    instants, recordings = [], []
    for r, s in enumerate(samples):
        keep = kept_rows(s, min_speed_rad_s)
        k = np.repeat(np.arange(s.q.shape[0]), spec.dof)[keep]
        instants.append(k)
        recordings.append(np.full(k.size, r, dtype=np.intp))
    return np.concatenate(instants), np.concatenate(recordings)


SEPARABLE_TOL = 1e-9
"""A standard parameter is separable when its unit vector lies in ``E``'s row space to
this (``1 - P_ii``, ``P`` the projector on the row space)."""


def from_prior(spec: RobotSpec, base: BaseParameters) -> tuple[str, ...]:
    """Standard parameters the data cannot separate, in standard order: those whose unit
    vector is not in the row space of the base projection ``E`` (no torque shows them
    alone: either no column at all, like link 1's mass, or only a sum with others, like
    the shoulder armatures with the link inertias about the same axis). The fit's value
    of such a parameter is the CAD prior's, moved by its share of the combination's
    correction (the null-space pull), never a measurement."""
    e = base.projection
    diag = np.sum(np.linalg.pinv(e) * e.T, axis=1)  # diagonal of pinv(E) E
    names = standard_names(spec)
    return tuple(names[i] for i in np.flatnonzero(1.0 - diag > SEPARABLE_TOL))


DRIVE_SUFFIXES = (".armature", ".fc", ".fv", ".offset")


def drive_from_prior(spec: RobotSpec, base: BaseParameters) -> tuple[str, ...]:
    """The armature and friction parameters among :func:`from_prior` (the inertial ones
    are many and expected: a link's parameters about other axes, link 1's mass)."""
    return tuple(n for n in from_prior(spec, base) if n.endswith(DRIVE_SUFFIXES))


def unexcited(gram: F64, names: Sequence[str], *, max_condition: float) -> tuple[list[str], float]:
    """Base parameters the data do not excite, and the scaled condition number.

    ``gram`` is ``Y_b^T Y_b``. Columns are scaled to unit norm (a parameter's units do not
    matter); the pivoted Cholesky factor of the scaled Gram matrix is the R factor of the
    pivoted QR of the scaled regressor, and a pivot below ``1 / max_condition`` of the
    first marks its parameter.
    """
    norms = np.sqrt(np.maximum(np.diag(gram), 0.0))
    zero = [names[int(i)] for i in np.flatnonzero(norms == 0)]
    inv = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 0.0)
    scaled = gram * inv[:, None] * inv[None, :]
    eig = np.linalg.eigvalsh(scaled)
    cond = float(np.sqrt(eig[-1] / eig[0])) if eig[0] > 0 else float("inf")
    factor, piv, rank, _ = scipy.linalg.lapack.dpstrf(scaled, lower=0, tol=-1.0)
    piv = piv - 1  # LAPACK counts from 1
    diag = np.abs(np.diag(factor))
    diag[rank:] = 0.0
    weak = [names[int(piv[i])] for i in np.flatnonzero(diag < diag[0] / max_condition)]
    out = zero + [w for w in weak if w not in zero]
    if not out and cond > max_condition:
        out = [names[int(piv[-1])]]
    return out, cond


def _per_joint_rms(values: F64, joint_of: NDArray[np.intp], dof: int) -> F64:
    counts = np.bincount(joint_of, minlength=dof)
    sums = np.bincount(joint_of, weights=values**2, minlength=dof)
    return np.sqrt(sums / np.maximum(counts, 1))


def _upper_factor(gram: F64) -> F64:
    """R with ``R^T R = gram`` (the R factor of the regressor), via a scaled Cholesky."""
    d = np.sqrt(np.diag(gram))
    chol = np.linalg.cholesky(gram / d[:, None] / d[None, :])
    return np.asarray(chol.T * d[None, :], dtype=float)


def identify(
    spec: RobotSpec,
    samples: Sequence[JointSamples],
    *,
    min_speed_rad_s: float = DEFAULT_MIN_SPEED_RAD_S,
    max_condition: float = DEFAULT_MAX_CONDITION,
    physical_fit: bool = True,
    transition_speed_rad_s: TransitionSpeed = 0.0,
    torque_side: str = "motor",
) -> FitResult:
    """Identify ``spec``'s base parameters from ``samples`` (see the module docstring).

    The least squares run on per-joint Gram matrices ``Y_j^T Y_j`` (one pass over the
    data; column-scaled Cholesky solves): the weighted problem is their weighted sum.

    Args:
        transition_speed_rad_s: 0: Coulomb friction ``fc sign(qd)``; > 0: the sigmoid
            model ``fc tanh(qd / v_s)``.
        torque_side: ``motor`` (armature identified), ``link`` (torque sensed after the
            gearbox: armature columns left out, the CAD armature kept) or ``auto``:
            ``link`` when no armature is seen (every separable armature estimate below
            two standard errors or :data:`ARMATURE_FLOOR_KG_M2`, or none excited).

    Raises:
        IdentificationError: too few equations for the parameters, or parameters the data
            do not excite (named).
    """
    if torque_side not in TORQUE_SIDES:
        raise IdentificationError(
            f"--torque-side: expected one of {', '.join(TORQUE_SIDES)}, got {torque_side!r}"
        )
    v_s = transition_speed_rad_s
    with one_thread():
        y_std, tau, joint_of = stacked(
            spec, samples, min_speed_rad_s=min_speed_rad_s,
            transition_speed_rad_s=transition_speed_rad_s,
        )  # fmt: skip
        kw = {
            "min_speed_rad_s": min_speed_rad_s, "max_condition": max_condition,
            "physical_fit": physical_fit,
        }  # fmt: skip
        if torque_side != "link":
            try:
                fit = _identify(spec, samples, y_std, tau, joint_of, armature=True, **kw)  # type: ignore[arg-type]
            except UnexcitedError as err:
                armature_only = all(".armature" in w for w in err.weak)
                if torque_side == "motor" or not armature_only:
                    raise
                reason = "detected: armature not excited (" + ", ".join(err.weak) + ")"
            else:
                if torque_side == "motor":
                    return replace(fit, torque_side_reason="declared", transition_speed_rad_s=v_s)
                seen = _armature_seen(fit)
                if seen is None or seen:
                    why = (
                        "no armature separable from the link inertias"
                        if seen is None
                        else "armature seen (estimates above two standard errors)"
                    )
                    return replace(
                        fit, torque_side_reason=f"detected: {why}", transition_speed_rad_s=v_s
                    )
                reason = (
                    "detected: no armature estimate above two standard errors "
                    f"or {ARMATURE_FLOOR_KG_M2:g} kg m^2"
                )
        else:
            reason = "declared"
        link_y = y_std.copy()
        link_y[:, ARMATURE::PER_JOINT] = 0.0
        fit = _identify(spec, samples, link_y, tau, joint_of, armature=False, **kw)  # type: ignore[arg-type]
        return replace(
            fit, torque_side="link", torque_side_reason=reason, transition_speed_rad_s=v_s
        )


def _armature_seen(fit: FitResult) -> bool | None:
    """Whether the separable armature estimates show a rotor (None: none separable)."""
    pure = [i for i, n in enumerate(fit.base.names) if n.endswith(".armature")]
    if not pure:
        return None
    est, se = fit.beta_wls[pure], fit.std_error[pure]
    return bool(np.any((est > 2 * se) & (est > ARMATURE_FLOOR_KG_M2)))


def _identify(
    spec: RobotSpec,
    samples: Sequence[JointSamples],
    y_std: F64,
    tau: F64,
    joint_of: NDArray[np.intp],
    *,
    min_speed_rad_s: float,
    max_condition: float,
    physical_fit: bool,
    armature: bool,
) -> FitResult:
    base = base_parameters(spec, armature=armature)
    y_b = y_std[:, base.columns]
    where = summarise_paths([s.source for s in samples], what="recording")
    need = MIN_ROWS_PER_PARAMETER * base.rank
    dof = spec.dof
    grams = np.empty((dof, base.rank, base.rank))
    moments = np.empty((dof, base.rank))
    for j in range(dof):
        rows = y_b[joint_of == j]
        grams[j] = rows.T @ rows
        moments[j] = rows.T @ tau[joint_of == j]
    weak, cond_scaled = unexcited(grams.sum(axis=0), base.names, max_condition=max_condition)
    if tau.size < need:
        shown = ", ".join(weak[:6]) + (f" (+{len(weak) - 6} more)" if len(weak) > 6 else "")
        raise UnexcitedError(
            f"{where}: {tau.size} equations (joint samples moving faster than "
            f"{min_speed_rad_s:g} rad/s), too short for {base.rank} base parameters "
            f"(needs {need}); not excited: {shown or 'none singled out'}: record a longer "
            "excitation",
            weak,
        )
    if weak:
        shown = ", ".join(weak[:6]) + (f" (+{len(weak) - 6} more)" if len(weak) > 6 else "")
        raise UnexcitedError(
            f"{where}: regressor too ill-conditioned to identify (scaled condition number "
            f"{cond_scaled:.3g} > {max_condition:g}); not excited: {shown}; record an "
            "excitation (pipeline identify excite)",
            weak,
        )
    r_ols = _upper_factor(grams.sum(axis=0))
    beta_ols = scipy.linalg.cho_solve((r_ols, False), moments.sum(axis=0))
    sigma = _per_joint_rms(tau - y_b @ beta_ols, joint_of, dof)
    tau_rms = _per_joint_rms(tau, joint_of, dof)
    # exact (noise-free) data: no residual to weigh by; a floor keeps the weights finite
    floor = 1e-9 * np.maximum(tau_rms, 1e-3)
    w2 = 1.0 / np.maximum(sigma, floor) ** 2
    r_w = _upper_factor(np.tensordot(w2, grams, axes=1))
    beta_wls = scipy.linalg.cho_solve((r_w, False), w2 @ moments)
    resid = tau - y_b @ beta_wls
    resid_w2 = float(np.sum(w2[joint_of] * resid**2))
    s2 = resid_w2 / max(tau.size - base.rank, 1)
    r_inv = scipy.linalg.solve_triangular(r_w, np.eye(base.rank))
    std_error_iid = np.sqrt(s2 * np.sum(r_inv**2, axis=1))
    # residual-based: scores of the weighted rows, summed per instant over joints
    w = np.sqrt(w2)[joint_of]
    instant, recording = row_instants(spec, samples, min_speed_rad_s=min_speed_rad_s)
    g = covariance.scores(y_b * w[:, None], resid * w, instant, recording)
    series: list[F64] = []
    for r in np.unique(recording):
        rows = recording == r
        e = np.zeros((int(instant[rows].max()) + 1, dof))
        e[instant[rows], joint_of[rows]] = (resid * w)[rows]
        series.extend(e.T)
    lags = covariance.bandwidth(series)
    gram_inv = r_inv @ r_inv.T
    # the sandwich's observations are the instants' scores, not the rows
    instants = sum(x.shape[0] for x in g)
    correction = instants / max(instants - base.rank, 1)
    cov_hac = covariance.hac_covariance(gram_inv, g, lags, dof_correction=correction)
    std_error = np.sqrt(np.maximum(np.diag(cov_hac), 0.0))
    cov_boot = covariance.block_bootstrap_covariance(
        gram_inv, g, lags + 1, replicates=BOOTSTRAP_REPLICATES, seed=BOOTSTRAP_SEED
    )
    std_error_bootstrap = np.sqrt(correction * np.maximum(np.diag(cov_boot), 0.0))
    sv = np.linalg.svd(r_ols, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    theta_cad = standard_parameters(spec)
    if physical_fit:
        theta = consistent_parameters(
            base, beta_wls, r_w, theta_cad, column_scale=np.linalg.norm(y_std, axis=0)
        )
    else:
        theta = theta_cad + np.linalg.pinv(base.projection) @ (beta_wls - base.of(theta_cad))
    beta = base.of(theta)
    final = tau - y_b @ beta
    tau_w2 = float(w2 @ (tau_rms**2 * np.bincount(joint_of, minlength=dof)))
    final_w2 = float(np.sum(w2[joint_of] * final**2))
    return FitResult(
        base=base,
        beta_wls=beta_wls,
        std_error=std_error,
        beta=beta,
        theta=theta,
        theta_cad=theta_cad,
        condition_number=cond,
        condition_number_scaled=cond_scaled,
        joint_sigma_nm=sigma,
        residual_rms_nm=_per_joint_rms(final, joint_of, dof),
        torque_rms_nm=tau_rms,
        rows=int(tau.size),
        projection_cost=max(final_w2 - resid_w2, 0.0) / max(tau_w2, 1e-300),
        std_error_iid=std_error_iid,
        std_error_bootstrap=std_error_bootstrap,
        hac_lags=lags,
    )


# --- physical consistency -------------------------------------------------------------------

_NONNEGATIVE = (ARMATURE, COULOMB, VISCOUS)


def violations(spec: RobotSpec, theta: F64, *, tol: float = 0.0) -> list[str]:
    """Why a standard parameter set is not physical (empty: it is).

    A link is physical iff its pseudo-inertia is positive definite (eigenvalue > ``tol``);
    armature, Coulomb and viscous friction must be >= 0.
    """
    out = []
    names = standard_names(spec)
    for j, joint in enumerate(spec.joint_names):
        block = theta[PER_JOINT * j : PER_JOINT * (j + 1)]
        eig = physical.min_eigenvalue(block[:10])
        if not eig > tol:
            out.append(
                f"{joint}: link pseudo-inertia not positive definite (smallest eigenvalue "
                f"{eig:.3g})"
            )
        for k in _NONNEGATIVE:
            if block[k] < 0:
                out.append(f"{names[PER_JOINT * j + k]}: {block[k]:.6g} < 0")
    return out


def _nonnegative_indices(n_standard: int) -> NDArray[np.intp]:
    return np.array(
        [PER_JOINT * j + k for j in range(n_standard // PER_JOINT) for k in _NONNEGATIVE],
        dtype=np.intp,
    )


def violations_of(theta: F64) -> bool:
    """Whether a standard parameter vector is not physical (fast, no messages)."""
    for j in range(theta.size // PER_JOINT):
        block = theta[PER_JOINT * j : PER_JOINT * (j + 1)]
        if not physical.min_eigenvalue(block[:10]) > 0 or (block[list(_NONNEGATIVE)] < 0).any():
            return True
    return False


def _to_phi(theta: F64) -> F64:
    dof = theta.size // PER_JOINT
    phi = theta.copy()
    for j in range(dof):
        phi[PER_JOINT * j : PER_JOINT * j + 10] = physical.to_log_cholesky(
            theta[PER_JOINT * j : PER_JOINT * j + 10]
        )
    return phi


def consistent_parameters(
    base: BaseParameters,
    beta_target: F64,
    r_w: F64,
    theta_start: F64,
    *,
    column_scale: F64,
) -> F64:
    """Physical standard parameters whose base parameters best fit ``beta_target``.

    Args:
        base: the base parameters.
        beta_target: the unconstrained (WLS) estimate.
        r_w: R factor of the weighted base regressor (the metric of the residual).
        theta_start: a physical start (the CAD model); also the prior in the null space.
        column_scale: per standard parameter, the norm of its regressor column (makes
            the null-space pull unit-free; zero columns get the median).

    Raises:
        IdentificationError: ``theta_start`` is not physical.
    """
    dof = theta_start.size // PER_JOINT
    try:
        phi0 = _to_phi(theta_start)
    except ValueError as err:
        raise IdentificationError(f"the start model is not physical: {err}") from err
    e = base.projection
    e_pinv = np.linalg.pinv(e)
    # the nearest point to the start that fits beta_target exactly: if physical, it is the
    # optimum (zero misfit, zero pull), no search needed
    nearest = theta_start + e_pinv @ (beta_target - e @ theta_start)
    signed: NDArray[np.intp] = _nonnegative_indices(nearest.size)
    values = nearest[signed]
    # rounding-level negatives of a zero friction (exact data) are zero
    nearest[signed] = np.where((values < 0) & (values > -ROUNDING_TOL), 0.0, values)
    if not violations_of(nearest):
        return nearest
    null = np.eye(theta_start.size) - e_pinv @ e
    positive = column_scale[column_scale > 0]
    scale = np.where(column_scale > 0, column_scale, np.median(positive) if positive.size else 1.0)
    fit_scale = float(np.linalg.norm(r_w)) / np.sqrt(base.rank)
    pull = np.sqrt(NULL_SPACE_WEIGHT) * fit_scale / float(np.median(scale))
    # residual(theta) = A theta - c: the weighted misfit, then the pull in the null space
    a_map = np.vstack([r_w @ e, pull * scale[:, None] * null])
    c = np.concatenate([r_w @ beta_target, pull * scale * (null @ theta_start)])
    blocks = [slice(PER_JOINT * j, PER_JOINT * j + 10) for j in range(dof)]
    a_blocks = [np.ascontiguousarray(a_map[:, blk]) for blk in blocks]
    a_signed = np.ascontiguousarray(a_map[:, signed])

    def theta_of(x: F64) -> tuple[F64, list[F64]]:
        theta = x.copy()
        jacs = []
        for blk in blocks:
            theta[blk], jac = physical.log_cholesky_jacobian(x[blk])
            jacs.append(jac)
        theta[signed] = x[signed] ** 2  # armature and friction >= 0 by construction
        return theta, jacs

    def residual(x: F64) -> F64:
        return np.asarray(a_map @ theta_of(x)[0] - c, dtype=float)

    def jacobian(x: F64) -> F64:
        # block by block: d theta / d x is block diagonal, and small products stay off
        # the BLAS thread pool (a shared machine makes it 10x slower on these sizes)
        _, jacs = theta_of(x)
        out = a_map.copy()
        for blk, a_blk, jac in zip(blocks, a_blocks, jacs, strict=True):
            out[:, blk] = a_blk @ jac
        out[:, signed] = a_signed * (2 * x[signed])
        return out

    # start: the exact fit's links where they are physical, else the start model's; its
    # armature and friction where >= 0, else a small positive value (x^2 has no gradient
    # at 0, so a parameter started at 0 would stay there)
    x0 = phi0.copy()
    for blk in blocks:
        if physical.min_eigenvalue(nearest[blk]) > 0:
            x0[blk] = physical.to_log_cholesky(nearest[blk])
    x0[signed] = np.sqrt(np.maximum(nearest[signed], START_MIN))
    # MINPACK's Levenberg-Marquardt: no bounds needed (every x is physical)
    sol = optimize.least_squares(
        residual, x0, jac=jacobian, method="lm", x_scale="jac",
        xtol=1e-10, ftol=COST_TOL, gtol=1e-10, max_nfev=MAX_EVALUATIONS,
    )  # fmt: skip
    return with_margin(theta_of(sol.x)[0])


def with_margin(theta: F64) -> F64:
    """``theta`` with every link's second moments raised by a hair (:data:`MARGIN_REL` of
    its rotational inertia's trace) where its pseudo-inertia is nearly singular.

    An optimum on the boundary of the physical set is a degenerate body (a rod, a point
    mass): its pseudo-inertia's smallest eigenvalue is zero up to rounding, and the robot
    loader refuses principal moments below 1e-12 kg m^2. Adding ``delta I3`` to Sigma
    adds ``2 delta I3`` to the inertia; the torques change by far less than the noise.
    """
    out = theta.copy()
    for j in range(theta.size // PER_JOINT):
        block = out[PER_JOINT * j : PER_JOINT * j + 10]
        trace = float(np.trace(physical.inertia_matrix(block)))
        delta = max(MARGIN_REL * trace, MARGIN_MIN_KG_M2)
        if physical.min_eigenvalue(block) < delta:
            for k in (4, 6, 9):  # Ixx, Iyy, Izz
                block[k] += 2 * delta
    return out
