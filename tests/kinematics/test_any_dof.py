"""Kinematics on 3, 6 and 7 joints: the Panda against an independent URDF, redundant IK
with its rest-posture pull, position-only IK, the analytic solver's refusal."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib import metadata

import numpy as np
import pinocchio as pin
import pytest
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.errors import KinematicsError
from pipeline.kinematics import (
    IKOptions,
    flange_pose,
    make_solver,
    pose_error,
    position_only,
    solve_pose_nearest,
    within_limits,
)
from pipeline.model.dh import forward_kinematics
from pipeline.robots import load_spec

PANDA_URDF = "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"
runner = CliRunner()


@pytest.fixture(scope="module")
def panda():
    return load_spec("panda_dh")


@pytest.fixture(scope="module")
def arm3():
    return load_spec("arm3_example")


def _poses(spec, count, seed):
    qs = np.random.default_rng(seed).uniform(spec.lower, spec.upper, (count, spec.dof))
    return qs, [forward_kinematics(spec, q) for q in qs]


def test_panda_dh_flange_matches_example_robot_data_panda_urdf(panda):
    # an independent description: Franka's URDF as example-robot-data ships it, loaded
    # by Pinocchio's own parser; panda_link8 is the flange (before the hand's -pi/4 yaw)
    try:
        path = metadata.distribution("example-robot-data").locate_file(PANDA_URDF)
    except metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    link8 = model.getFrameId("panda_link8")
    assert [model.names[i] for i in range(1, 8)] == list(panda.joint_names)
    fingers = np.zeros(model.nq - panda.dof)
    worst = 0.0
    for q in np.random.default_rng(0).uniform(panda.lower, panda.upper, (200, 7)):
        pin.framesForwardKinematics(model, data, np.concatenate([q, fingers]))
        urdf = data.oMf[link8].homogeneous
        for ours in (forward_kinematics(panda, q), flange_pose(panda, q)):
            worst = max(worst, float(np.abs(ours[:3, 3] - urdf[:3, 3]).max()))
            assert np.abs(ours[:3, :3] - urdf[:3, :3]).max() < 1e-9
    assert worst < 1e-6
    lower = [model.lowerPositionLimit[i] for i in range(7)]
    upper = [model.upperPositionLimit[i] for i in range(7)]
    assert np.allclose(panda.lower, lower) and np.allclose(panda.upper, upper)


def test_seven_joint_ik_solves_hundreds_of_poses_verified_by_dh_fk_within_limits(panda):
    opts = IKOptions(tol_m=1e-6, tol_rad=1e-6)
    solver = make_solver("numeric", panda, options=opts)
    _, targets = _poses(panda, 300, seed=21)
    for target in targets:
        (q,) = solver.solve(target).solutions
        pos, ang = pose_error(forward_kinematics(panda, q), target)
        assert pos <= opts.tol_m and ang <= opts.tol_rad
        assert np.all(q >= panda.lower) and np.all(q <= panda.upper)


def test_null_space_pull_moves_toward_rest_without_breaking_the_pose(panda):
    # seeded at the generating joints the descent stops at once; the pull then slides
    # along the self-motion manifold toward the rest posture
    rest = (0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.7)
    pulled = make_solver("numeric", panda, options=IKOptions(rest_q=rest))
    still = make_solver("numeric", panda, options=IKOptions(rest_q=rest, null_space_iterations=0))
    qs, targets = _poses(panda, 40, seed=22)
    closer = 0
    for q, target in zip(qs, targets, strict=True):
        a = still.solve(target, seed_q=q).best()
        b = pulled.solve(target, seed_q=q).best()
        assert np.allclose(a, q)  # no pull: the seed itself
        pos, ang = pose_error(forward_kinematics(panda, b), target)
        assert pos <= 1e-6 and ang <= 1e-6
        assert within_limits(panda, b)
        d_seed = np.linalg.norm(q - rest)
        d_pulled = np.linalg.norm(b - rest)
        assert d_pulled <= d_seed
        closer += d_pulled < d_seed - 0.05
    assert closer >= 20


def test_rest_posture_outside_the_limits_or_of_the_wrong_length_is_refused(panda):
    with pytest.raises(KinematicsError, match=r"panda_joint4 = 0 rad is outside its limits"):
        make_solver("numeric", panda, options=IKOptions(rest_q=(0.0,) * 7))
    with pytest.raises(KinematicsError, match=r"has 7 joints; the IK rest posture has 6 values"):
        make_solver("numeric", panda, options=IKOptions(rest_q=(0.0,) * 6))
    with pytest.raises(KinematicsError, match=r"rest posture must be finite"):
        IKOptions(rest_q=(float("nan"),) * 7)


def test_three_joints_get_position_only_ik(arm3):
    assert position_only(arm3)
    solver = make_solver("numeric", arm3)
    _, targets = _poses(arm3, 100, seed=23)
    for target in targets:
        tilted = target.copy()
        tilted[:3, :3] = np.eye(3)  # the rotation is not matched: any will do
        (q,) = solver.solve(tilted).solutions
        assert np.linalg.norm(forward_kinematics(arm3, q)[:3, 3] - target[:3, 3]) <= 1e-6
        assert within_limits(arm3, q)
    q = solve_pose_nearest(arm3, position=targets[0][:3, 3])  # no orientation needed
    assert np.linalg.norm(flange_pose(arm3, q)[:3, 3] - targets[0][:3, 3]) <= 1e-6


def test_an_unreachable_position_names_position_only_ik(arm3):
    target = np.eye(4)
    target[:3, 3] = (0.0, 0.0, 0.3)  # the shoulder: the folded arm stays 0.05 m away
    result = make_solver("numeric", arm3, options=IKOptions(max_restarts=2)).solve(target)
    assert not result.ok
    assert "(position-only IK, 3 joints)" in result.reason and "closest: " in result.reason
    assert " rad" not in result.reason.split("closest: ")[1]


@pytest.mark.parametrize(
    ("robot", "why"),
    [("panda_dh", "it has 7 joints (needs 6)"), ("arm3_example", "it has 3 joints (needs 6)")],
)
def test_analytic_solver_refuses_other_structures_in_one_line(robot, why):
    with pytest.raises(KinematicsError, match=r"analytic IK does not fit") as err:
        make_solver("analytic", load_spec(robot))
    assert why in str(err.value) and "\n" not in str(err.value)
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "ik", robot, "--position", "0.3", "0", "0.4",
         *(["--rpy", "3.1", "0", "0"] if robot == "panda_dh" else []), "--solver", "analytic"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 1 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1
    assert proc.stderr.startswith(f"error: analytic IK does not fit robot '{robot}'")
    assert why in proc.stderr and "Traceback" not in proc.stderr


def _cli(*args: str) -> dict:
    result = runner.invoke(app, list(args))
    assert result.exit_code == 0, result.output
    out: dict = json.loads(result.stdout)
    return out


def test_fk_and_ik_cli_on_the_seven_joint_robot(panda):
    q = [0.3, -0.5, 0.2, -2.0, 0.4, 1.8, -0.6]
    fk = _cli("fk", "panda_dh", *map(str, q), "--json")
    want = forward_kinematics(panda, q)
    assert np.abs(np.array(fk["position"]) - want[:3, 3]).max() < 1e-12
    ik = _cli("ik", "panda_dh", "--position", *map(str, fk["position"]),
              "--quaternion", *map(str, fk["quaternion_wxyz"]), "--json")  # fmt: skip
    assert ik["position_only"] is False and len(ik["solutions"]) == 1
    (sol,) = ik["solutions"]
    assert len(sol) == 7
    pos, ang = pose_error(forward_kinematics(panda, sol), want)
    assert pos <= 1e-6 and ang <= 1e-6
    rest = "0,0.2,0,-2,0,2.2,0.7"
    pulled = _cli("ik", "panda_dh", "--position", *map(str, fk["position"]),
                  "--quaternion", *map(str, fk["quaternion_wxyz"]), "--rest-joints", rest,
                  "--json")["solutions"][0]  # fmt: skip
    pos, ang = pose_error(forward_kinematics(panda, pulled), want)
    assert pos <= 1e-6 and ang <= 1e-6
    table = runner.invoke(app, ["ik", "panda_dh", "--position", *map(str, fk["position"]),
                                "--quaternion", *map(str, fk["quaternion_wxyz"])])  # fmt: skip
    assert table.exit_code == 0 and "q7" in table.stdout and "ori [rad]" in table.stdout


def test_position_only_cli_on_the_three_joint_robot(arm3, tmp_path):
    fk = _cli("fk", "arm3_example", "0.4", "0.3", "-0.9", "--json")
    ik = _cli("ik", "arm3_example", "--position", *map(str, fk["position"]), "--json")
    assert ik["position_only"] is True and ik["orientation_error_rad"] is None
    (sol,) = ik["solutions"]
    assert np.linalg.norm(forward_kinematics(arm3, sol)[:3, 3] - fk["position"]) <= 1e-6
    refused = runner.invoke(app, ["ik", "arm3_example", "--position", "0.3", "0", "0.4",
                                  "--rpy", "0", "0", "0"])  # fmt: skip
    assert refused.exit_code == 1
    result = runner.invoke(app, ["ik-check", "arm3_example", "--samples", "6", "--json",
                                 "--out", str(tmp_path)])  # fmt: skip
    report = json.loads(result.stdout)
    assert report["position_only"] is True and report["successes"] == 6
    assert report["checks"]["orientation_error"] is True  # not judged
    assert result.exit_code == (0 if report["passed"] else 1)
