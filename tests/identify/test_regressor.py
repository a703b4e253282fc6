"""The regressor against Pinocchio's RNEA, base parameters, and the log-Cholesky map."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.identify import physical
from pipeline.identify.regressor import (
    PER_JOINT,
    Regressor,
    base_parameters,
    link_inertial,
    random_samples,
    standard_parameters,
)
from pipeline.robots.loaders import load_spec
from pipeline.robots.urdf import build_pinocchio_model


@pytest.fixture(scope="module")
def ur5():  # type: ignore[no-untyped-def]
    return load_spec("ur5")


def test_regressor_times_parameters_is_rnea_plus_friction(ur5) -> None:  # type: ignore[no-untyped-def]
    fc, fv, off = np.linspace(1, 3, 6), np.linspace(0.1, 0.6, 6), np.linspace(-1, 1, 6)
    theta = standard_parameters(ur5, coulomb_nm=fc, viscous_nm_s_rad=fv, offset_nm=off)
    q, qd, qdd = random_samples(ur5, n=40, seed=3)
    tau = Regressor(ur5).stacked(q, qd, qdd) @ theta
    model = build_pinocchio_model(ur5)  # RNEA adds armature * qdd itself
    data = model.createData()
    expected = np.concatenate(
        [pin.rnea(model, data, q[k], qd[k], qdd[k]) + fc * np.sign(qd[k]) + fv * qd[k] + off
         for k in range(40)]
    )  # fmt: skip
    np.testing.assert_allclose(tau, expected, rtol=0, atol=1e-10)


def test_base_parameters_reproduce_every_torque(ur5) -> None:  # type: ignore[no-untyped-def]
    base = base_parameters(ur5)
    theta = standard_parameters(ur5, coulomb_nm=np.ones(6), viscous_nm_s_rad=np.ones(6))
    y = Regressor(ur5).stacked(*random_samples(ur5, n=60, seed=11))  # other states than QR's
    np.testing.assert_allclose(y[:, base.columns] @ base.of(theta), y @ theta, atol=1e-9)
    assert base.rank < theta.size
    assert np.linalg.matrix_rank(y[:, base.columns]) == base.rank


def test_link_inertial_inverts_the_standard_parameters(ur5) -> None:  # type: ignore[no-untyped-def]
    theta = standard_parameters(ur5)
    for j, joint in enumerate(ur5.joints):
        got = link_inertial(ur5, j, theta[PER_JOINT * j : PER_JOINT * j + 10])
        assert joint.inertial is not None
        assert got.mass == pytest.approx(joint.inertial.mass)
        np.testing.assert_allclose(got.com, joint.inertial.com, atol=1e-12)
        np.testing.assert_allclose(got.inertia, joint.inertial.inertia, atol=1e-12)


def test_log_cholesky_round_trip_and_always_physical(ur5) -> None:  # type: ignore[no-untyped-def]
    theta = standard_parameters(ur5)
    for j in range(ur5.dof):
        params = theta[PER_JOINT * j : PER_JOINT * j + 10]
        back = physical.from_log_cholesky(physical.to_log_cholesky(params))
        np.testing.assert_allclose(back, params, rtol=1e-12, atol=1e-15)
    rng = np.random.default_rng(0)
    for _ in range(50):
        assert physical.min_eigenvalue(physical.from_log_cholesky(rng.normal(size=10))) > 0


def test_pseudo_inertia_rejects_a_non_physical_link(ur5) -> None:  # type: ignore[no-untyped-def]
    params = standard_parameters(ur5)[PER_JOINT : PER_JOINT + 10].copy()
    # the centre of mass far outside the body's inertia ellipsoid: no density makes it
    params[1:4] *= 50
    assert physical.min_eigenvalue(params) < 0
    with pytest.raises(ValueError):
        physical.to_log_cholesky(params)
