"""Standard errors that hold on autocorrelated residuals, and parameters the data cannot
separate reported as from the prior."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from pipeline.identify import covariance
from pipeline.identify.regressor import base_parameters
from pipeline.identify.stage import fit_command
from pipeline.robots.loaders import load_spec


def _slope_errors(rho: float, *, runs: int, n: int, seed: int) -> tuple[float, float, float]:
    """Monte-Carlo spread of the slope of ``y = a + b x + e`` with AR(1) ``e`` (and a
    smooth ``x``), and the mean naive and Newey-West standard errors of it."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    x = np.sin(2 * np.pi * t / 97) + 0.5 * np.cos(2 * np.pi * t / 31)
    y = np.column_stack([np.ones(n), x])
    gram_inv = np.linalg.inv(y.T @ y)
    slopes, naive, hac = [], [], []
    for _ in range(runs):
        shocks = rng.normal(size=n)
        e = np.empty(n)
        e[0] = shocks[0] / np.sqrt(1 - rho**2)
        for k in range(1, n):
            e[k] = rho * e[k - 1] + shocks[k]
        beta = gram_inv @ (y.T @ e)  # true coefficients 0
        resid = e - y @ beta
        slopes.append(beta[1])
        naive.append(np.sqrt(resid @ resid / (n - 2) * gram_inv[1, 1]))
        g = covariance.scores(y, resid, t, np.zeros(n, dtype=np.intp))
        lags = covariance.bandwidth([resid])
        cov = covariance.hac_covariance(gram_inv, g, lags, dof_correction=n / (n - 2))
        hac.append(np.sqrt(cov[1, 1]))
    return float(np.std(slopes)), float(np.mean(naive)), float(np.mean(hac))


def test_newey_west_matches_the_spread_of_an_estimate_under_ar1_noise() -> None:
    """AR(1) residuals (rho 0.8): the textbook error is about a third of the estimate's
    true spread; the Newey-West error is within 25 % of it."""
    spread, naive, hac = _slope_errors(0.8, runs=300, n=600, seed=1)
    assert naive < 0.5 * spread, (naive, spread)
    assert abs(hac / spread - 1) < 0.25, (hac, spread)


def test_newey_west_equals_the_textbook_error_on_white_noise() -> None:
    spread, naive, hac = _slope_errors(0.0, runs=300, n=600, seed=2)
    assert abs(naive / spread - 1) < 0.15, (naive, spread)
    assert abs(hac / naive - 1) < 0.15, (hac, naive)


def test_block_bootstrap_agrees_with_newey_west() -> None:
    rng = np.random.default_rng(3)
    n = 800
    t = np.arange(n)
    y = np.column_stack([np.ones(n), np.sin(2 * np.pi * t / 97)])
    e = np.convolve(rng.normal(size=n + 20), np.ones(20) / 20, mode="valid")[:n]
    gram_inv = np.linalg.inv(y.T @ y)
    resid = e - y @ (gram_inv @ (y.T @ e))
    g = covariance.scores(y, resid, t, np.zeros(n, dtype=np.intp))
    lags = covariance.bandwidth([resid])
    hac = covariance.hac_covariance(gram_inv, g, lags, dof_correction=1.0)
    boot = covariance.block_bootstrap_covariance(gram_inv, g, lags + 1, replicates=2000, seed=0)
    np.testing.assert_allclose(np.sqrt(np.diag(boot)), np.sqrt(np.diag(hac)), rtol=0.3)


def test_bandwidth_grows_with_the_residuals_correlation() -> None:
    rng = np.random.default_rng(4)
    white = rng.normal(size=1000)
    smooth = np.convolve(rng.normal(size=1030), np.ones(30) / 30, mode="valid")[:1000]
    assert covariance.bandwidth([white]) <= 3
    assert covariance.bandwidth([smooth]) >= 15


def test_inseparable_armatures_are_reported_as_from_the_prior(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    """The UR5's shoulder-pan armature only shows summed with link 1's inertia about z,
    the shoulder-lift's with link 2's: both are labelled "from the prior" in the model
    file and in fit's output; the elbow's armature is separable and identified."""
    spec = load_spec("ur5")
    model = tmp_path / "model.yaml"
    summary = fit_command([ideal_bags[0]], out=model, cutoff_hz=0.0)
    pair = ["shoulder_pan_joint.armature", "shoulder_lift_joint.armature"]
    assert summary["from_prior"] == pair
    doc = yaml.safe_load(model.read_text())
    ident = doc["identification"]
    assert ident["from_prior"]["drive"] == pair
    assert "shoulder_pan_joint.m" in ident["from_prior"]["inertial"]  # never in a torque
    assert "shoulder_pan_joint, shoulder_lift_joint" in doc["robot"]["armature_source"]
    assert [e["armature_from"] for e in doc["links"]] == ["prior"] * 2 + ["data"] * 4
    assert "from the prior" in ident["torque_side"]["armature"]
    assert "elbow_joint.armature" in base_parameters(spec).names  # separable, identified
    assert "elbow_joint" not in ident["torque_side"]["armature"]


def test_the_fft_long_run_covariance_is_the_sum_over_lags() -> None:
    rng = np.random.default_rng(5)
    g = [rng.normal(size=(300, 4)), rng.normal(size=(40, 4))]
    for lags in (1, 7, 60):
        np.testing.assert_allclose(
            covariance.long_run_covariance(g, lags),
            covariance.long_run_covariance_direct(g, lags),
            rtol=1e-10,
            atol=1e-9,
        )
