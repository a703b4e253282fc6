"""Standard errors of a least-squares fit whose residuals are not white.

Identification fits ``tau = Y beta`` on low-pass filtered, decimated samples: the
residual of one sample is correlated with its neighbours' (the filter spreads every
error over about a cutoff period) and with the other joints' at the same instant (one
model error shows on every joint). The textbook covariance ``s^2 (Y^T Y)^-1`` assumes
independent residuals and is several times too small there.

Two residual-based estimators, both from the *scores* ``g_k = sum_j y_kj e_kj`` (the
rows of one instant ``k`` summed over joints: any correlation across joints at an
instant is kept whole):

- :func:`hac_covariance`: the Newey-West (1987) sandwich ``G^-1 S G^-1`` with
  ``G = Y^T Y`` and ``S = sum_l w_l (Gamma_l + Gamma_l^T)`` (``Gamma_0`` once), Bartlett
  weights ``w_l = 1 - l / (L + 1)``, autocovariances summed within each recording
  (recordings are independent). The bandwidth ``L`` comes from :func:`bandwidth`.
- :func:`block_bootstrap_covariance`: a moving-block bootstrap of the scores (Kuensch
  1989), blocks of ``L + 1`` instants, per recording: the covariance of
  ``G^-1 sum_k g*_k`` over the replicates.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import signal

F64 = NDArray[np.float64]

MAX_RHO = 0.97
"""An AR(1) coefficient is clipped to this (the plug-in rule diverges at 1)."""


def scores(y: F64, resid: F64, instant: NDArray[np.intp], recording: NDArray[np.intp]) -> list[F64]:
    """Per recording, the (T_r, p) scores ``g_k = sum of y_row * e_row`` over the rows of
    instant ``k`` (instants without a row score zero).

    Args:
        y: (n, p) regressor rows (weighted, as fitted).
        resid: (n,) residuals of those rows (weighted alike).
        instant: (n,) each row's sample index within its recording.
        recording: (n,) each row's recording index.
    """
    out = []
    for r in np.unique(recording):
        rows = recording == r
        g = np.zeros((int(instant[rows].max()) + 1, y.shape[1]))
        np.add.at(g, instant[rows], y[rows] * resid[rows, None])
        out.append(g)
    return out


def bandwidth(series: Sequence[F64]) -> int:
    """Newey-West lags by Andrews' (1991) AR(1) plug-in rule for the Bartlett kernel.

    Each series (one column of one recording's residuals at consecutive instants) gets
    an AR(1) fit ``rho_a``, innovation variance ``s_a^2``; then
    ``alpha = sum 4 rho^2 s^4 / ((1 - rho)^6 (1 + rho)^2) / sum s^4 / (1 - rho)^4`` and
    ``L = ceil(1.1447 (alpha T)^(1/3))`` with ``T`` the longest recording, ``rho``
    clipped to :data:`MAX_RHO`; at least 1, at most ``T - 1``.
    """
    num = den = 0.0
    longest = 1
    for x in series:
        x = np.asarray(x, dtype=float) - float(np.mean(x))
        longest = max(longest, x.size)
        if x.size < 3 or not np.any(x):
            continue
        rho = float(np.dot(x[1:], x[:-1]) / max(float(np.dot(x[:-1], x[:-1])), 1e-300))
        rho = min(max(rho, -MAX_RHO), MAX_RHO)
        s2 = float(np.mean((x[1:] - rho * x[:-1]) ** 2))
        num += 4 * rho**2 * s2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += s2**2 / (1 - rho) ** 4
    if den <= 0:
        return 1
    lags = int(np.ceil(1.1447 * (num / den * longest) ** (1 / 3)))
    return max(1, min(lags, longest - 1))


def long_run_covariance(g: Sequence[F64], lags: int) -> F64:
    """``S``: Bartlett-weighted autocovariances of the scores up to ``lags``, summed over
    recordings. Computed as ``g^T (W g)`` with ``W`` the Toeplitz matrix of the weights
    (``W g``: each column convolved with the kernel, by FFT): exactly the sum of the
    weighted ``Gamma_l``, in ``O(T p^2)`` rather than ``O(L T p^2)``."""
    p = g[0].shape[1]
    s = np.zeros((p, p))
    weights = 1 - np.abs(np.arange(-lags, lags + 1)) / (lags + 1)
    for x in g:
        smoothed = signal.fftconvolve(x, weights[:, None], mode="same", axes=0)
        s += x.T @ smoothed
    return np.asarray((s + s.T) / 2, dtype=float)


def long_run_covariance_direct(g: Sequence[F64], lags: int) -> F64:
    """:func:`long_run_covariance` as the textbook sum over lags (the cross-check)."""
    p = g[0].shape[1]
    s = np.zeros((p, p))
    for x in g:
        s += x.T @ x
        for lag in range(1, min(lags, x.shape[0] - 1) + 1):
            gamma = x[lag:].T @ x[:-lag]
            s += (1 - lag / (lags + 1)) * (gamma + gamma.T)
    return s


def hac_covariance(gram_inv: F64, g: Sequence[F64], lags: int, *, dof_correction: float) -> F64:
    """Newey-West covariance ``c G^-1 S G^-1`` (``c``: ``n / (n - p)``, given)."""
    s = long_run_covariance(g, lags)
    cov = dof_correction * gram_inv @ s @ gram_inv
    return np.asarray((cov + cov.T) / 2, dtype=float)


def block_bootstrap_covariance(
    gram_inv: F64, g: Sequence[F64], block: int, *, replicates: int, seed: int
) -> F64:
    """Moving-block bootstrap covariance of ``G^-1 sum_k g_k``: per recording, blocks of
    ``block`` consecutive centred scores drawn with replacement (starts uniform) until
    the recording's length; ``replicates`` draws, seeded."""
    rng = np.random.default_rng(seed)
    p = gram_inv.shape[0]
    totals = np.zeros((replicates, p))
    for x in g:
        x = x - x.mean(axis=0)
        t = x.shape[0]
        b = max(1, min(block, t))
        # block sums at every start: cumulative sums make each draw O(p)
        csum = np.vstack([np.zeros((1, p)), np.cumsum(x, axis=0)])
        sums = csum[b:] - csum[:-b]  # (t - b + 1, p)
        n_blocks = int(np.ceil(t / b))
        starts = rng.integers(0, t - b + 1, size=(replicates, n_blocks))
        totals += sums[starts].sum(axis=1) * (t / (n_blocks * b))
    deltas = totals @ gram_inv.T
    cov = np.cov(deltas, rowvar=False)
    return np.asarray(np.atleast_2d(cov), dtype=float)
