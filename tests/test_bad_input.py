"""Every bad input a user can reach gets one line, a non-zero exit and no traceback.

A battery over the CLI (params files, robot files, kinematics values, paths), run
in-process through the real entry point: an exception that is not a PipelineError
escapes ``main()`` and fails the test; a RuntimeWarning (an overflow numpy only
warns about) is turned into an error too. A few cases run as real processes to check
the same from the outside. None of these cases may start work: each is refused while
validating, in well under a second.
"""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from pipeline.cli import main

REPO = Path(__file__).parents[1]
PARAMS = yaml.safe_load((REPO / "params.yaml").read_text())
UR5 = yaml.safe_load((REPO / "pipeline/robots/ur5.yaml").read_text())
Q0 = ["0.1"] * 6


def run_cli_out(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Run ``pipeline argv`` in-process; return (exit code, stdout, stderr)."""
    old = sys.argv
    sys.argv = ["pipeline", *argv]
    try:
        main()
        code = 0
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else 1
    finally:
        sys.argv = old
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Run ``pipeline argv`` in-process; return (exit code, stderr)."""
    code, _, err = run_cli_out(argv, capsys)
    return code, err


def assert_one_line(code: int, err: str, expected: str) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code != 0, err
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    line = lines[0]
    # click's own usage errors (a bad --jobs) are framed in a box; ours are one "error:" line
    assert line.startswith("error:") or "Invalid value" in err, err
    assert expected in line, f"expected {expected!r} in {line!r}"


# --- params files ------------------------------------------------------------------------


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    keys = path.split(".")

    def mutate(d: dict[str, Any]) -> None:
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value

    return mutate


PARAMS_CASES: list[tuple[str, Callable[[dict[str, Any]], None], str]] = [
    # runaway settings
    ("dt-1e-9", _set("sim.physics_dt_s", 1e-9), "sim.physics_dt_s"),
    ("dt-zero", _set("sim.physics_dt_s", 0.0), "sim.physics_dt_s"),
    ("dt-negative", _set("sim.physics_dt_s", -0.001), "sim.physics_dt_s"),
    ("dt-coarse", _set("sim.physics_dt_s", 0.5), "sim.physics_dt_s"),
    ("dt-nan", _set("sim.physics_dt_s", float("nan")), "sim.physics_dt_s"),
    ("dt-string", _set("sim.physics_dt_s", "fast"), "sim.physics_dt_s"),
    ("dt-bool", _set("sim.physics_dt_s", True), "physics_dt_s: expected a number"),
    ("period-1e9", _set("sim.control_period_steps", 10**9), "sim.control_period_steps"),
    ("period-zero", _set("sim.control_period_steps", 0), "sim.control_period_steps"),
    ("period-float", _set("sim.control_period_steps", 1.5), "sim.control_period_steps"),
    ("period-slow", _set("sim.control_period_steps", 500), "control period"),
    ("tf-1e9", _set("sim.tf_rate_hz", 1e9), "sim.tf_rate_hz"),
    ("tf-zero", _set("sim.tf_rate_hz", 0), "sim.tf_rate_hz"),
    ("decimation-zero", _set("sim.joint_state_decimation", 0), "sim.joint_state_decimation"),
    ("decimation-huge", _set("sim.joint_state_decimation", 10**7), "joint_state_decimation"),
    ("hold-bool", _set("scenarios.paper.hold_s", True), "hold_s: expected a number"),
    ("hold-negative", _set("scenarios.paper.hold_s", -1), "scenarios.paper.hold_s"),
    ("hold-huge", _set("scenarios.paper.hold_s", 1e9), "scenarios.paper.hold_s"),
    ("hold-inf", _set("scenarios.paper.hold_s", float("inf")), "scenarios.paper.hold_s"),
    ("planner-time", _set("scenarios.paper.planner.time_limit_s", 1e9), "time_limit_s"),
    ("planner-seed", _set("scenarios.paper.planner.seed", -1), "planner.seed"),
    ("scaling-zero", _set("scenarios.paper.timing.velocity_scaling", 0), "velocity_scaling"),
    ("scaling-bool", _set("scenarios.paper.timing.velocity_scaling", True), "expected a number"),
    ("payload-huge", _set("scenarios.paper.plant.payload_kg", 1e9), "payload_kg"),
    ("noise-huge", _set("scenarios.paper.plant.position_noise_std_rad", 1e9), "noise"),
    ("damping-len", _set("scenarios.paper.plant.damping", [1.0, 2.0]), "plant.damping"),
    ("damping-huge", _set("scenarios.paper.plant.damping", 1e300), "damping"),
    # joints and goals
    ("start-nan", _set("scenarios.paper.start", [float("nan")] * 6), "scenarios.paper.start"),
    ("start-len", _set("scenarios.paper.start", [0.0] * 5), "expected 6 values"),
    ("start-limits", _set("scenarios.paper.start", [7.0] + [0.0] * 5), "outside"),
    (
        "start-named-unknown",
        _set("scenarios.paper.start", "ready"),
        "scenarios.paper.start: robot ur5 (no SRDF) defines no state 'ready'; defined: none",
    ),
    (
        "goal-named-unknown",
        _set("scenarios.paper.goal", "ready"),
        "scenarios.paper.goal: robot ur5 (no SRDF) defines no state 'ready'",
    ),
    (
        "goal-named-and-joints",
        _set("scenarios.paper.goal", {"state": "a", "joints": [0.0] * 6}),
        "exactly one of joints or pose, or a named state",
    ),
    ("start-strings", _set("scenarios.paper.start", ["a"] * 6), "scenarios.paper.start"),
    ("goal-inf", _set("scenarios.paper.goal", {"joints": [float("inf")] * 6}), "goal"),
    (
        "goal-zero-quaternion",
        _set(
            "scenarios.paper.goal",
            {"pose": {"position": [0.3, 0.2, 0.4], "quaternion_wxyz": [0, 0, 0, 0]}},
        ),
        "quaternion",
    ),
    (
        "goal-unreachable",
        _set("scenarios.paper.goal", {"pose": {"position": [1e308, 0, 0], "rpy": [0, 0, 0]}}),
        "goal.pose",
    ),
    # names that go into XML and file names
    (
        "obstacle-duplicate",
        _set(
            "scenarios.paper.obstacles",
            [
                {"name": "box", "center": [1, 1, 1], "half_size": [0.1, 0.1, 0.1]},
                {"name": "box", "center": [2, 1, 1], "half_size": [0.1, 0.1, 0.1]},
            ],
        ),
        "duplicate obstacle name(s) box",
    ),
    (
        "obstacle-xml",
        _set(
            "scenarios.paper.obstacles",
            [{"name": 'a"<b>&', "center": [1, 1, 1], "half_size": [0.1, 0.1, 0.1]}],
        ),
        "obstacles[0].name: invalid name",
    ),
    (
        "obstacle-reserved",
        _set(
            "scenarios.paper.obstacles",
            [{"name": "ground", "center": [1, 1, 1], "half_size": [0.1, 0.1, 0.1]}],
        ),
        "reserved",
    ),
    (
        "episode-key-long",
        lambda d: d["episodes"].update({"e" * 300: d["episodes"]["paper-pid"]}),
        "at most 100 characters",
    ),
    (
        "episode-key-slash",
        lambda d: d["episodes"].update({"a/b": d["episodes"]["paper-pid"]}),
        "directory names",
    ),
    ("episode-unknown-scenario", _set("episodes.paper-pid.scenario", "nope"), "unknown scenario"),
    ("episode-seed", _set("episodes.paper-pid.seed", -1), "seed"),
    # gains
    ("gain-1e300", _set("controllers.pid.gains.omega_n_rad_s", 1e300), "gains.omega_n_rad_s"),
    ("gain-nan", _set("controllers.ctc.gains.kp", float("nan")), "gains.kp"),
    ("gain-list-inf", _set("controllers.ctc.gains.kp", [float("inf")] * 6), "gains.kp"),
    ("controller-unknown", _set("controllers.pid.type", "lqr"), "lqr"),
    # where the default gains are designed (issue 28)
    (
        "design-at-outside-limits",
        _set("controllers.pid.gains.design_at", [0.0, 0.0, 9.0, 0.0, 0.0, 0.0]),
        "controllers.pid.gains.design_at: joint elbow_joint = 9 rad is outside",
    ),
    (
        "design-at-wrong-length",
        _set("controllers.pid.gains.design_at", [0.0, 0.0, 0.0]),
        "controllers.pid.gains.design_at: expected 6 finite joint angles",
    ),
    (
        "design-at-unknown",
        _set("controllers.pid.gains.design_at", "goal"),
        "controllers.pid.gains.design_at: expected 'path', 'start'",
    ),
    # shape
    ("not-a-mapping", lambda d: d.clear() or d.update({"x": None}), "params.yaml"),
    ("no-episodes", lambda d: d.pop("episodes"), "episodes"),
]


def battery(cases: list[tuple[str, Callable[[dict[str, Any]], None], str]]) -> Any:
    """Parametrize (mutate, expected) over named cases."""
    return pytest.mark.parametrize(
        ("mutate", "expected"), [c[1:] for c in cases], ids=[c[0] for c in cases]
    )


def mutated(base: dict[str, Any], mutate: Callable[[dict[str, Any]], None], path: Path) -> Path:
    """Write a mutated copy of ``base`` as YAML to ``path``."""
    data = copy.deepcopy(base)
    mutate(data)
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.filterwarnings("error::RuntimeWarning")
@battery(PARAMS_CASES)
def test_bad_params_fail_in_one_line(tmp_path, capsys, mutate, expected):
    params = mutated(PARAMS, mutate, tmp_path / "params.yaml")
    out = tmp_path / "rec"
    code, err = run_cli(["record", "--params", str(params), "--out", str(out)], capsys)
    assert_one_line(code, err, expected)
    assert not out.exists(), "a refused run must not create its output"


RAW_PARAMS = [
    ("duplicate-key", "sim: {physics_dt_s: 0.001}\nsim: {physics_dt_s: 0.002}\n",
     "duplicate key 'sim' (first at line 1) at line 2"),
    ("duplicate-nested-key",
     (REPO / "params.yaml").read_text().replace("hold_s: 1.0", "hold_s: 1.0\n    hold_s: 2.0"),
     "duplicate key 'hold_s'"),
    ("not-yaml", "sim: [1, 2\n", "not valid YAML at line"),
    ("binary", "\x00\x01\x02", "params.yaml"),
    ("empty", "", "expected a mapping"),
    ("list", "- 1\n- 2\n", "expected a mapping"),
]  # fmt: skip


@pytest.mark.parametrize(
    ("text", "expected"), [c[1:] for c in RAW_PARAMS], ids=[c[0] for c in RAW_PARAMS]
)
def test_bad_params_text_fails_in_one_line(tmp_path, capsys, text, expected):
    params = tmp_path / "params.yaml"
    params.write_text(text)
    code, err = run_cli(["record", "--params", str(params), "--out", str(tmp_path / "r")], capsys)
    assert_one_line(code, err, expected)


# --- robot files ---------------------------------------------------------------------------


def _joint(i: int, **changes: Any) -> Callable[[dict[str, Any]], None]:
    def mutate(d: dict[str, Any]) -> None:
        j = d["joints"][i]
        for key, value in changes.items():
            if "." in key:
                outer, inner = key.split(".")
                j[outer][inner] = value
            else:
                j[key] = value

    return mutate


ROBOT_CASES: list[tuple[str, Callable[[dict[str, Any]], None], str]] = [
    ("limits-1e308", _joint(0, **{"limits.lower": -1e308, "limits.upper": 1e308}),
     "joints[0].limits.lower"),
    ("limits-nan", _joint(0, **{"limits.lower": float("nan")}), "joints[0].limits.lower"),
    ("mass-1e-300", _joint(1, **{"inertial.mass": 1e-300}), "joints[1].inertial.mass"),
    ("mass-1e300", _joint(1, **{"inertial.mass": 1e300}), "joints[1].inertial.mass"),
    ("mass-bool", _joint(1, **{"inertial.mass": True}), "mass: expected a number"),
    ("inertia-1e-300", _joint(1, **{"inertial.inertia": [1e-300, 1e-300, 1e-300, 0, 0, 0]}),
     "joints[1].inertial.inertia"),
    ("inertia-1e300", _joint(1, **{"inertial.inertia": [1e300, 1e300, 1e300, 0, 0, 0]}),
     "joints[1].inertial.inertia"),
    ("com-1e308", _joint(1, **{"inertial.com": [1e308, 0, 0]}), "joints[1].inertial.com"),
    ("dh-a-1e308", _joint(1, dh=[0, 1e308, 0, 0]), "joints[1].dh[1] (a)"),
    ("dh-alpha-1e308", _joint(1, dh=[1e308, 0, 0, 0]), "joints[1].dh[0] (alpha)"),
    ("dh-nan", _joint(1, dh=[0, float("nan"), 0, 0]), "joints[1].dh"),
    ("dh-short", _joint(1, dh=[0, 0, 0]), "joints[1].dh"),
    ("velocity-1e308", _joint(2, **{"limits.velocity": 1e308}), "limits.velocity"),
    ("effort-1e308", _joint(2, **{"limits.effort": 1e308}), "limits.effort"),
    ("effort-zero", _joint(2, **{"limits.effort": 0}), "limits.effort"),
    ("radius-1e308", _joint(2, **{"collision.radius": 1e308}), "collision.radius"),
    ("radius-1e-300", _joint(2, **{"collision.radius": 1e-300}), "collision.radius"),
    ("name-quote", _joint(0, name='sh"oulder'), "joints[0].name: invalid name"),
    ("name-lt", _joint(0, name="a<b"), "joints[0].name: invalid name"),
    ("name-amp", _joint(0, name="a&b"), "joints[0].name: invalid name"),
    ("name-nul", _joint(0, name="a\x00b"), "joints[0].name: invalid name"),
    ("name-space", _joint(0, name="a b"), "joints[0].name: invalid name"),
    ("name-empty", _joint(0, name=""), "joints[0].name: invalid name"),
    ("name-long", _joint(0, name="j" * 300), "joints[0].name: invalid name"),
    ("name-base-link", _joint(0, name="base"), "already used by the base frame"),
    ("name-link-clash", _joint(1, name="shoulder_pan"), "already used by joint"),
    ("robot-name", lambda d: d.update(name="<ur5>"), "name: invalid name"),
    ("no-joints", lambda d: d.update(joints=[]), "joints"),
    ("deg-limits-huge", lambda d: d.update(angle_unit="deg") or _joint(0, **{
        "limits.lower": -1e308, "limits.upper": 1e308})(d), "limits.lower"),
]  # fmt: skip


@pytest.mark.filterwarnings("error::RuntimeWarning")
@battery(ROBOT_CASES)
def test_bad_robot_files_fail_in_one_line(tmp_path, capsys, mutate, expected):
    robot = mutated(UR5, mutate, tmp_path / "arm.yaml")
    code, err = run_cli(["fk", str(robot), *Q0], capsys)
    assert_one_line(code, err, expected)
    assert str(robot) in err


def test_robot_file_with_a_duplicate_key_is_refused(tmp_path, capsys):
    text = (REPO / "pipeline/robots/ur5.yaml").read_text()
    robot = tmp_path / "arm.yaml"
    robot.write_text(text.replace("convention: standard", "convention: standard\nname: ur6"))
    code, err = run_cli(["fk", str(robot), *Q0], capsys)
    assert_one_line(code, err, "duplicate key 'name'")


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_a_single_joint_robot_is_usable_or_refused_cleanly(tmp_path, capsys):
    data = copy.deepcopy(UR5)
    data["joints"] = data["joints"][:1]
    robot = tmp_path / "one.yaml"
    robot.write_text(yaml.safe_dump(data))
    assert run_cli(["fk", str(robot), "0.3", "--json"], capsys)[0] == 0
    # fewer than 6 joints: position-only IK, so an orientation is refused and a
    # position off the joint's circle is unreachable
    code, err = run_cli(["ik", str(robot), "--position", "0.1", "0", "0.1", "--rpy", "0", "0",
                         "0"], capsys)  # fmt: skip
    assert_one_line(code, err, "has 1 joint: its IK matches the flange position only")
    code, err = run_cli(["ik", str(robot), "--position", "0.1", "0", "0.1"], capsys)
    assert_one_line(code, err, "cannot reach position [0.1000, 0.0000, 0.1000] m (position-only")


# --- kinematics commands -----------------------------------------------------------------

KINEMATICS_CASES = [
    ("fk-inf", ["fk", "ur5", "inf", *Q0[1:]], "joint 1 (shoulder_pan_joint): inf"),
    ("fk-nan", ["fk", "ur5", *Q0[:2], "nan", *Q0[3:]], "joint 3 (elbow_joint): nan"),
    ("fk-1e308", ["fk", "ur5", "1e308", *Q0[1:]], "outside its limits"),
    ("fk-count", ["fk", "ur5", "0", "0"], "has 6 joints, got 2"),
    ("fk-unknown-robot", ["fk", "ur55", *Q0], "did you mean 'ur5'"),
    ("fk-robot-dir", ["fk", "/tmp/", *Q0], "is a directory"),
    ("ik-zero-quaternion", ["ik", "ur5", "--position", "0.3", "0.2", "0.4", "--quaternion",
                            "0", "0", "0", "0"], "must not be zero"),
    ("ik-nan-position", ["ik", "ur5", "--position", "nan", "0.2", "0.4", "--rpy", "0", "0", "0"],
     "finite"),
    ("ik-inf-rpy", ["ik", "ur5", "--position", "0.3", "0.2", "0.4", "--rpy", "inf", "0", "0"],
     "finite"),
    ("ik-nan-seed", ["ik", "ur5", "--position", "0.3", "0.2", "0.4", "--rpy", "0", "0", "0",
                     "--seed-joints", "nan,0,0,0,0,0"], "seed must be finite"),
    ("ik-seed-text", ["ik", "ur5", "--position", "0.3", "0.2", "0.4", "--rpy", "0", "0", "0",
                      "--seed-joints", "a,b"], "--seed-joints"),
    ("ik-no-orientation", ["ik", "ur5", "--position", "0.3", "0.2", "0.4"], "exactly one"),
    ("ik-unknown-solver", ["ik", "ur5", "--position", "0.3", "0.2", "0.4", "--rpy", "0", "0",
                           "0", "--solver", "magic"], "magic"),
    ("ik-check-seed", ["ik-check", "ur5", "--samples", "2", "--seed", "-1"], "Invalid value"),
    ("ik-check-samples", ["ik-check", "ur5", "--samples", "0"], "Invalid value"),
]  # fmt: skip


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize(
    ("argv", "expected"), [c[1:] for c in KINEMATICS_CASES], ids=[c[0] for c in KINEMATICS_CASES]
)
def test_bad_kinematics_values_fail_in_one_line(capsys, argv, expected):
    code, err = run_cli(argv, capsys)
    if "Invalid value" in expected:  # click's usage error: a framed block, exit 2
        assert code == 2 and "Traceback" not in err and expected in err, err
        return
    assert_one_line(code, err, expected)


def test_ik_check_refuses_a_bad_out_before_working(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("")
    code, err = run_cli(["ik-check", "ur5", "--samples", "5", "--out", str(a_file)], capsys)
    assert_one_line(code, err, "--out is a file")
    code, err = run_cli(["ik-check", "ur5", "--samples", "5", "--out", "/proc/no/such"], capsys)
    assert_one_line(code, err, "cannot create the --out directory")


def test_a_collision_matrix_without_collision_geometry_writes_nothing(tmp_path, capsys):
    out = tmp_path / "ur5.srdf"
    code, err = run_cli(["robots", "collision-matrix", "ur5", "--out", str(out)], capsys)
    assert_one_line(code, err, "robot 'ur5' has no collision geometry")
    assert list(tmp_path.iterdir()) == []
    out.write_text("mine")
    code, err = run_cli(["robots", "collision-matrix", "ur5", "--out", str(out)], capsys)
    assert_one_line(code, err, "the file exists; pass --force")
    assert out.read_text() == "mine"


def test_ik_normalises_a_huge_quaternion_without_overflow(capsys):
    """1e308 1e308 0 0 is 90 deg about x, like 1 1 0 0 (it used to overflow to identity)."""
    args = ["ik", "ur5", "--position", "0.3", "0.2", "0.4", "--json", "--quaternion"]
    code, out, err = run_cli_out([*args, "1e308", "1e308", "0", "0"], capsys)
    assert code == 0 and not err, err
    huge = json.loads(out)
    code, out, _ = run_cli_out([*args, "1", "1", "0", "0"], capsys)
    unit = json.loads(out)
    half = 2**-0.5
    assert huge["target"]["quaternion_wxyz"] == pytest.approx([half, half, 0, 0], abs=1e-12)
    assert huge["target"] == unit["target"]
    assert huge["solutions"] == unit["solutions"]


# --- paths -------------------------------------------------------------------------------


def test_bad_paths_fail_in_one_line(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("")
    cases = [
        (["record", "--params", str(tmp_path)], "is a directory"),
        (["record", "--params", str(tmp_path / "none.yaml")], "no such params file"),
        (["record", "--out", str(a_file)], "--out is a file"),
        (["record", "--out", "/proc/no/such"], "cannot create the --out directory"),
        (["record", "--only", "nope", "--out", str(tmp_path / "r")], "unknown episode 'nope'"),
        (["report", "--recordings", str(tmp_path / "none")], "no such directory"),
        (["report", "--recordings", str(a_file), "--out", str(tmp_path / "o")], "empty file"),
        (["report", "--recordings", str(tmp_path / "none"), "--out", str(a_file)], "is a file"),
    ]
    for argv, expected in cases:
        if argv[0] == "record" and "--params" not in argv:
            argv = [*argv, "--params", str(REPO / "params.yaml")]
        code, err = run_cli(argv, capsys)
        assert_one_line(code, err, expected)


@pytest.mark.parametrize(
    "argv",
    [
        ["fk", "ur5", "inf", "0", "0", "0", "0", "0"],
        ["ik-check", "ur5", "--samples", "3", "--out", "/proc/no/such"],
        ["record", "--params", "pipeline/robots/ur5.yaml"],
    ],
    ids=["fk-inf", "ik-check-out", "record-wrong-file"],
)
def test_the_real_command_prints_one_line_and_no_traceback(argv):
    result = subprocess.run(
        [sys.executable, "-m", "pipeline", *argv], cwd=REPO, capture_output=True, text=True
    )
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 1, result.stderr
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
