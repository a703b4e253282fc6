"""Flange Jacobian, manipulability and the singularity flag, against independent references."""

from __future__ import annotations

import numpy as np

from pipeline.kinematics import is_singular, jacobian, manipulability
from pipeline.model.dh import forward_kinematics


def _fd_jacobian(spec, q, h=1e-6):
    """Central differences of DH FK: linear velocity and world angular velocity columns."""
    cols = []
    for i in range(spec.dof):
        dq = np.zeros(spec.dof)
        dq[i] = h
        tp, tm = forward_kinematics(spec, q + dq), forward_kinematics(spec, q - dq)
        v = (tp[:3, 3] - tm[:3, 3]) / (2 * h)
        skew = (tp[:3, :3] - tm[:3, :3]) / (2 * h) @ forward_kinematics(spec, q)[:3, :3].T
        cols.append(np.concatenate((v, [skew[2, 1], skew[0, 2], skew[1, 0]])))
    return np.array(cols).T


def test_pinocchio_jacobian_matches_finite_differences_of_dh_fk(every_dof_robot):
    spec = every_dof_robot
    for q in np.random.default_rng(21).uniform(spec.lower, spec.upper, (10, spec.dof)):
        assert jacobian(spec, q).shape == (6, spec.dof)
        assert np.abs(jacobian(spec, q) - _fd_jacobian(spec, q)).max() < 1e-7


def test_manipulability_matches_the_ur_closed_form_determinant(ur_robot):
    # det J = a2 a3 s3 s5 (a2 c2 + a3 c23 + d5 s234) for UR geometry
    a2, a3, d5 = ur_robot.joints[1].dh.a, ur_robot.joints[2].dh.a, ur_robot.joints[4].dh.d
    for q in np.random.default_rng(22).uniform(-3.0, 3.0, (20, 6)):
        c2, c23, s234 = np.cos(q[1]), np.cos(q[1] + q[2]), np.sin(q[1] + q[2] + q[3])
        det = a2 * a3 * np.sin(q[2]) * np.sin(q[4]) * (a2 * c2 + a3 * c23 + d5 * s234)
        assert abs(manipulability(ur_robot, q) - abs(det)) < 1e-12


def test_singularity_flag_fires_at_wrist_and_elbow_singularities_only(ur5):
    regular = np.array([0.3, -1.2, 1.4, -0.8, 1.1, 0.5])
    assert not is_singular(ur5, regular)
    assert manipulability(ur5, regular) > 1e-3
    for singular in ([0.3, -1.2, 1.4, -0.8, 0.0, 0.5], [0.3, -1.2, 0.0, -0.8, 1.1, 0.5]):
        assert is_singular(ur5, singular)
        assert manipulability(ur5, singular) < 1e-12
    assert is_singular(ur5, [0.3, -1.2, 1.4, -0.8, 1e-4, 0.5])
    assert not is_singular(ur5, [0.3, -1.2, 1.4, -0.8, 1e-4, 0.5], threshold=1e-5)
