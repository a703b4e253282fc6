"""The fk / ik / ik-check commands: JSON contracts, checked against DH forward kinematics."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from pipeline import transforms as tf
from pipeline.cli import app
from pipeline.kinematics import pose_error
from pipeline.model.dh import forward_kinematics
from pipeline.robots import load_spec

ROBOTS = ["ur5", "ur10", "mdh_example"]
Q = [0.3, -1.2, 1.4, -0.8, 1.1, 0.5]  # within every robot's limits, far from singularities
runner = CliRunner()


def _run(*args: str) -> dict:
    result = runner.invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def _pipeline(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pipeline", *args], capture_output=True, text=True, timeout=120
    )


@pytest.mark.parametrize("robot", ROBOTS)
def test_fk_json_matches_dh_fk_with_negative_joints(robot):
    out = _run("fk", robot, *map(str, Q), "--json")
    assert set(out) >= {"position", "quaternion_wxyz", "rpy", "joints"}
    assert out["joints"] == Q
    want = forward_kinematics(load_spec(robot), Q)
    assert np.abs(np.array(out["position"]) - want[:3, 3]).max() < 1e-12
    assert np.abs(tf.quat_to_matrix(np.array(out["quaternion_wxyz"])) - want[:3, :3]).max() < 1e-12
    assert np.abs(tf.rpy_to_matrix(*out["rpy"]) - want[:3, :3]).max() < 1e-12


def test_fk_prints_a_table_without_json():
    result = runner.invoke(app, ["fk", "ur5", "0", "-1.57", "0", "0", "0", "0"])
    assert result.exit_code == 0
    assert "position [m]" in result.stdout and "-0.191450" in result.stdout


@pytest.mark.parametrize(
    ("robot", "solver", "count"),
    [("ur5", "analytic", 8), ("ur10", "analytic", 8), ("ur5", "numeric", 1),
     ("ur10", "numeric", 1), ("mdh_example", "numeric", 1)],
)  # fmt: skip
def test_ik_json_solutions_reproduce_the_target(robot, solver, count):
    spec = load_spec(robot)
    target = forward_kinematics(spec, Q)
    quat = tf.quat_wxyz(target[:3, :3])
    out = _run("ik", robot, "--position", *map(str, target[:3, 3]),
               "--quaternion", *map(str, quat), "--solver", solver, "--json")  # fmt: skip
    assert len(out["solutions"]) == count
    for q in out["solutions"]:
        pos, ang = pose_error(forward_kinematics(spec, q), target)
        # the CLI prints 17 significant digits, so only rounding is lost
        assert pos < 1e-6 and ang < 1e-6


def test_ik_accepts_rpy_and_a_seed(ur5):
    target = forward_kinematics(ur5, Q)
    rpy = tf.rpy(target[:3, :3])
    seed = ",".join(str(v + 0.05) for v in Q)
    out = _run("ik", "ur5", "--position", *map(str, target[:3, 3]), "--rpy", *map(str, rpy),
               "--seed-joints", seed, "--json")  # fmt: skip
    assert np.abs(np.array(out["solutions"][0]) - Q).max() < 1e-4


@pytest.mark.parametrize("robot", ROBOTS)
def test_ik_check_quick_run_writes_the_map_and_the_summary(robot, tmp_path):
    result = runner.invoke(
        app, ["ik-check", robot, "--samples", "6", "--out", str(tmp_path), "--json"]
    )
    report = json.loads(result.stdout)
    assert result.exit_code == (0 if report["passed"] else 1)
    assert report["samples"] == 6 and report["solver"] == "numeric"
    assert report["position_error_m"]["max"] < 1e-4
    assert set(report["solve_time_ms"]) == {"mean", "median", "p99"}
    png = (tmp_path / "error_map.png").read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 10_000
    assert json.loads((tmp_path / "ik_check.json").read_text()) == report
    assert not list(tmp_path.glob(".*.tmp"))


def test_ik_check_analytic_passes_and_prints_a_verdict(tmp_path):
    result = runner.invoke(
        app, ["ik-check", "ur10", "--solver", "analytic", "--samples", "20", "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    assert "PASS" in result.stdout and "success rate" in result.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["fk", "ur5", "0", "-1.57"], "error: robot 'ur5' has 6 joints, got 2 joint values"),
        (["ik", "ur5", "--position", "2", "0", "0.3", "--rpy", "0", "0", "0"],
         "error: robot 'ur5' cannot reach position [2.0000, 0.0000, 0.3000] m"),
        (["ik", "mdh_example", "--position", "0.3", "0", "0.3", "--rpy", "0", "0", "0",
          "--solver", "analytic"],
         "error: analytic IK does not fit robot 'mdh_example'"),
        (["ik", "ur5", "--position", "0.3", "0", "0.3", "--solver", "fast", "--rpy", "0", "0", "0"],
         "error: unknown IK solver 'fast'; valid: analytic, numeric"),
    ],
)  # fmt: skip
def test_user_errors_exit_1_with_one_line(args, message):
    proc = _pipeline(*args)
    assert proc.returncode == 1
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith(message), proc.stderr
    assert proc.stdout == ""


@pytest.mark.parametrize("command", ["fk", "ik", "ik-check"])
def test_every_option_is_explained_with_units(command):
    result = runner.invoke(app, [command, "--help"], terminal_width=200)
    assert result.exit_code == 0
    text = result.stdout
    assert "--json" in text
    if command == "ik":
        assert "[m]" in text and "[rad]" in text and "--seed-joints" in text
    if command == "ik-check":
        for option in ("--solver", "--samples", "--seed", "--out", "--min-success-rate"):
            assert option in text


@pytest.mark.parametrize("solver", ["numeric", "analytic"])
@pytest.mark.parametrize("position", [["1e308", "0", "0"], ["-1e308", "1e308", "1e308"]])
def test_a_target_at_1e308_m_is_one_line_without_runtime_warnings(solver, position):
    proc = _pipeline("ik", "ur5", "--position", *position, "--rpy", "0", "0", "0",
                     "--solver", solver)  # fmt: skip
    assert proc.returncode == 1
    assert proc.stderr.count("\n") == 1, proc.stderr  # no RuntimeWarning lines before it
    assert proc.stderr.startswith("error: robot 'ur5' cannot reach position [")
    assert "Warning" not in proc.stderr


def test_ik_check_refuses_ten_million_samples_up_front(tmp_path):
    proc = _pipeline("ik-check", "ur5", "--samples", "10000000", "--out", str(tmp_path / "o"))
    assert proc.returncode == 1
    assert proc.stderr.count("\n") == 1
    assert proc.stderr.startswith("error: --samples 10,000,000: at most 1,000,000 ")
    assert not (tmp_path / "o").exists()
