"""'Use as goal': the taught pose or joints land in a params file, validated and atomic."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import ParamsError
from pipeline.kinematics import solve_pose_nearest
from pipeline.model.dh import forward_kinematics
from pipeline.params import load_params
from pipeline.robots import RobotSpec
from pipeline.teach.goal import goal_from_state, write_goal
from pipeline.teach.session import TeachSession, choose_solver

REPO = Path(__file__).resolve().parents[2]
TAUGHT_Q = [0.4, -1.1, 1.3, -0.6, 0.9, -0.3]


@pytest.fixture
def params_file(tmp_path: Path) -> Path:
    path = tmp_path / "params.yaml"
    shutil.copy(REPO / "params.yaml", path)
    return path


def _taught(spec: RobotSpec) -> TeachSession:
    session = TeachSession(spec, choose_solver(spec, None)[0])
    session.set_target(forward_kinematics(spec, TAUGHT_Q))
    return session


def test_pose_goal_is_written_validated_and_resolves_to_the_taught_pose(
    ur5: RobotSpec, params_file: Path
) -> None:
    session = _taught(ur5)
    goal = goal_from_state(session.state, kind="pose", solver="analytic")
    write_goal(params_file, scenario="taught", robot="ur5", spec=ur5, goal=goal)
    params = load_params(params_file)  # what `pipeline record` reads
    scenario = params.scenarios["taught"]
    assert scenario.robot == "ur5" and scenario.goal.pose is not None
    pose = scenario.goal.pose
    # the record stage turns the pose into joints by IK nearest the start; FK lands on it
    q = solve_pose_nearest(ur5, position=pose.position, quaternion_wxyz=pose.quaternion_wxyz,
                           solver=pose.solver, near=scenario.start)  # fmt: skip
    np.testing.assert_allclose(forward_kinematics(ur5, q), forward_kinematics(ur5, TAUGHT_Q),
                               atol=1e-9)  # fmt: skip
    text = params_file.read_text()
    assert "# armlab pipeline parameters" in text  # comments survive the edit
    assert "paper-ctc" in text and {"paper", "taught"} <= set(params.scenarios)


def test_joints_goal_replaces_an_existing_scenarios_goal_exactly(
    ur5: RobotSpec, params_file: Path
) -> None:
    session = _taught(ur5)
    goal = goal_from_state(session.state, kind="joints", solver="analytic")
    write_goal(params_file, scenario="paper", robot="ur5", spec=ur5, goal=goal)
    written = load_params(params_file).scenarios["paper"].goal.joints
    assert written == [float(v) for v in session.state.q]  # repr floats round-trip exactly
    np.testing.assert_allclose(
        forward_kinematics(ur5, written), forward_kinematics(ur5, TAUGHT_Q), atol=1e-12
    )


def test_scenario_of_another_robot_is_refused_and_the_file_untouched(params_file: Path) -> None:
    from pipeline.robots import load_spec

    ur10 = load_spec("ur10")
    before = params_file.read_bytes()
    goal = goal_from_state(_taught(ur10).state, kind="joints", solver="analytic")
    with pytest.raises(ParamsError, match=r"scenarios\.paper\.robot: is 'ur5'"):
        write_goal(params_file, scenario="paper", robot="ur10", spec=ur10, goal=goal)
    assert params_file.read_bytes() == before


def test_an_invalid_result_is_not_written(ur5: RobotSpec, params_file: Path) -> None:
    # a params file that is already invalid elsewhere: validation of the result fails
    text = params_file.read_text().replace("hold_s: 1.0", "hold_s: -1.0", 1)
    params_file.write_text(text)
    goal = goal_from_state(_taught(ur5).state, kind="joints", solver="analytic")
    with pytest.raises(
        ParamsError, match=r"scenarios\.paper\.hold_s: .*greater than or equal to 0"
    ):
        write_goal(params_file, scenario="taught", robot="ur5", spec=ur5, goal=goal)
    assert params_file.read_text() == text
    assert [p.name for p in params_file.parent.iterdir()] == ["params.yaml"]  # no temp left


def test_unreachable_target_cannot_be_used_as_goal(ur5: RobotSpec) -> None:
    session = _taught(ur5)
    far = np.eye(4)
    far[:3, 3] = [3.0, 0.0, 0.0]
    session.set_target(far)
    with pytest.raises(ParamsError, match="unreachable, nothing to use"):
        goal_from_state(session.state, kind="pose", solver="analytic")


def test_missing_params_file_is_one_clear_error(ur5: RobotSpec, tmp_path: Path) -> None:
    goal = goal_from_state(_taught(ur5).state, kind="joints", solver="analytic")
    with pytest.raises(ParamsError, match="no such params file"):
        write_goal(tmp_path / "nope.yaml", scenario="t", robot="ur5", spec=ur5, goal=goal)


def test_use_as_goal_on_an_alias_writes_only_that_scenario(
    ur5: RobotSpec, params_file: Path
) -> None:
    text = params_file.read_text().replace("  paper:\n", "  paper: &paper\n", 1)
    text = text.replace("\ncontrollers:", "\n  taught: *paper\n  also: *paper\ncontrollers:", 1)
    params_file.write_text(text)
    before = load_params(params_file).scenarios
    write_goal(params_file, scenario="taught", robot="ur5", spec=ur5,
               goal={"joints": TAUGHT_Q})  # fmt: skip
    after = load_params(params_file).scenarios
    assert after["taught"].goal.joints == TAUGHT_Q
    for other in ("paper", "also"):  # the anchor and its other user are unchanged
        assert after[other] == before[other]
    assert after["taught"].start == before["paper"].start  # the rest of the alias expanded


def _write_many(path: str, prefix: str, count: int) -> None:
    from pipeline.robots import load_spec

    spec = load_spec("ur5")
    for k in range(count):
        q = [0.01 * k, -0.5, 0.3, -0.2, 0.1, 0.0]
        write_goal(Path(path), scenario=f"{prefix}{k}", robot="ur5", spec=spec,
                   goal={"joints": q})  # fmt: skip


@pytest.mark.slow
def test_concurrent_writers_take_turns_and_lose_no_goal(params_file: Path) -> None:
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    procs = [ctx.Process(target=_write_many, args=(str(params_file), p, 6)) for p in "ab"]
    for p in procs:
        p.start()
    for p in procs:
        p.join(300)
    assert [p.exitcode for p in procs] == [0, 0]
    scenarios = load_params(params_file).scenarios
    assert {f"{p}{k}" for p in "ab" for k in range(6)} <= set(scenarios)
