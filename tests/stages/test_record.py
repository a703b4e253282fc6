"""End-to-end: `pipeline record` through the real planner, simulator and writer."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

REPO = Path(__file__).parents[2]
PIPELINE = [sys.executable, "-m", "pipeline"]


def _params(tmp_path: Path, name: str = "params.yaml", **scenario_overrides: object) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = 0.3
    data["scenarios"]["paper"].update(scenario_overrides)
    data["episodes"] = {k: v for k, v in data["episodes"].items() if v["scenario"] == "paper"}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def _record(params: Path, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*PIPELINE, "record", "--params", str(params), "--out", str(out), *extra],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )


def _mcap_bytes(out: Path) -> dict[str, bytes]:
    """Bags under their final names (hidden .partial directories are not recordings)."""
    return {
        p.parent.name: p.read_bytes()
        for p in sorted(out.glob("*/*.mcap"))
        if not p.parent.name.startswith(".")
    }


@pytest.mark.slow
def test_two_runs_give_byte_identical_recordings(tmp_path):
    params = _params(tmp_path)
    # plus one episode on the realistic plant: its drawn link parameters are seeded too
    data = yaml.safe_load(params.read_text())
    data["scenarios"]["paper-realistic"]["hold_s"] = 0.3
    data["episodes"]["real-ctc-s1"] = {
        "scenario": "paper-realistic",
        "controller": "ctc",
        "seed": 1,
    }
    params.write_text(yaml.safe_dump(data))
    first = _record(params, tmp_path / "a", "--jobs", "2")
    second = _record(params, tmp_path / "b", "--jobs", "1")
    assert first.returncode == 0, first.stderr
    assert second.returncode == 0, second.stderr
    a, b = _mcap_bytes(tmp_path / "a"), _mcap_bytes(tmp_path / "b")
    assert sorted(a) == ["paper-ctc", "paper-pid", "real-ctc-s1"]
    assert a == b
    for name in ("paper-pid", "paper-ctc"):
        meta_a = (tmp_path / "a" / name / "metadata.yaml").read_bytes()
        assert meta_a == (tmp_path / "b" / name / "metadata.yaml").read_bytes()
        final = _last_joint_state_by_rosbags(tmp_path / "a" / name)
        # 0.3 s after the motion: PID is still settling (wrist 1 ~2 mrad), CTC has converged
        tolerance = {"paper-pid": 5e-3, "paper-ctc": 1e-6}[name]
        np.testing.assert_allclose(final, TABLE_2_GOAL, atol=tolerance)
    # issue 28: PID's default gains were designed along the planned motion, and the
    # recording says so (CTC's explicit gains depend on no configuration: no design)
    import json

    def design(name: str) -> object:
        meta = yaml.safe_load((tmp_path / "a" / name / "metadata.yaml").read_text())
        text = _find_settings(meta)
        return json.loads(text)["controller"]["design"]

    pid = design("paper-pid")
    assert isinstance(pid, dict) and pid["at"] == "path" and len(pid["inertia_kg_m2"]) == 6
    assert design("paper-ctc") is None


def _find_settings(node: object) -> str:
    """The settings JSON string inside a bag's metadata.yaml."""
    if isinstance(node, dict):
        if isinstance(node.get("settings"), str):
            return str(node["settings"])
        for value in node.values():
            found = _find_settings(value)
            if found:
                return found
    if isinstance(node, list):
        for value in node:
            found = _find_settings(value)
            if found:
                return found
    return ""


TABLE_2_GOAL = [-0.15, -0.5, 0.785, -1.15, -0.3925, 0.0]


def _last_joint_state_by_rosbags(bag: Path) -> np.ndarray:
    """Decode /joint_states with rosbags (independent of our reader), types from the bag."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    with AnyReader([bag], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        connections = [c for c in reader.connections if c.topic == "/joint_states"]
        last = None
        for connection, _, raw in reader.messages(connections=connections):
            last = raw, connection
        assert last is not None
        msg = reader.deserialize(last[0], last[1].msgtype)
    return np.asarray(msg.position)


@pytest.mark.slow
def test_existing_recording_is_not_overwritten_without_force(tmp_path):
    params = _params(tmp_path)
    out = tmp_path / "rec"
    assert _record(params, out, "--only", "paper-ctc").returncode == 0
    before = _mcap_bytes(out)
    again = _record(params, out, "--only", "paper-ctc")
    assert again.returncode == 1
    assert "recording exists" in again.stderr and "--force" in again.stderr
    assert "Traceback" not in again.stderr
    assert _mcap_bytes(out) == before
    assert _record(params, out, "--only", "paper-ctc", "--force").returncode == 0


@pytest.mark.slow
def test_killed_run_leaves_no_partial_bag_and_keeps_earlier_ones(tmp_path):
    # a one-minute hold: its bag (~9 MB) takes about a second to write on a quiet machine,
    # ~100 polls below (a 600 s hold proved the same at 5x the CPU time)
    params = _params(tmp_path, "long.yaml", hold_s=60.0)
    out = tmp_path / "rec"
    quick = _params(tmp_path)
    assert _record(quick, out, "--only", "paper-pid").returncode == 0
    earlier = _mcap_bytes(out)
    proc = subprocess.Popen(
        [*PIPELINE, "record", "--params", str(params), "--out", str(out), "--only", "paper-ctc"],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    # kill while the bag is being written: its partial directory exists (the 60 s hold
    # first simulates, then writes);
    # no wall-clock deadline: a run that never writes ends, or meets pytest's timeout
    while not list(out.glob(".paper-ctc.partial-*")):
        assert proc.poll() is None, "the run ended before its bag was being written"
        time.sleep(0.01)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    finals = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert finals == ["paper-pid"]
    assert _mcap_bytes(out) == earlier


def test_out_of_limits_goal_is_refused_before_any_work(tmp_path):
    params = _params(tmp_path, goal={"joints": [0.0, 0.0, 0.0, 0.0, 0.0, 7.0]})
    result = _record(params, tmp_path / "rec")
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert re.search(
        r"^error: .*params\.yaml: scenarios\.paper\.goal\.joints\[5\]: 7\.0 rad is outside "
        r"wrist_3_joint's limits",
        result.stderr,
        re.MULTILINE,
    ), result.stderr
    assert not (tmp_path / "rec").exists()


def test_colliding_goal_fails_its_episodes_with_the_contact(tmp_path):
    # shoulder lift +1.2 rad swings the upper arm down through the pedestal and floor
    params = _params(tmp_path, goal={"joints": [0.0, 1.2, 0.0, 0.0, 0.0, 0.0]})
    result = _record(params, tmp_path / "rec", "--only", "paper-pid")
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    lines = [ln for ln in result.stderr.splitlines() if ln.startswith("error: paper-pid:")]
    assert len(lines) == 1, result.stderr
    assert "goal" in lines[0] and "collision" in lines[0], lines[0]
    assert not (tmp_path / "rec" / "paper-pid").exists()


def test_bad_params_exit_1_with_one_line(tmp_path):
    params = _params(tmp_path, robot="ur6")
    result = _record(params, tmp_path / "rec")
    assert result.returncode == 1
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert any("unknown robot 'ur6'" in ln and "did you mean 'ur5'" in ln for ln in lines)
    assert "Traceback" not in result.stderr


def test_cartesian_goal_becomes_the_ik_solution_nearest_the_start(ur5):
    from pipeline import transforms as tf
    from pipeline.experiment.goals import resolve_goal
    from pipeline.kinematics import make_solver
    from pipeline.model.dh import forward_kinematics
    from pipeline.params import load_params

    paper_goal = np.array([-0.15, -0.5, 0.785, -1.15, -0.3925, 0.0])
    pose = forward_kinematics(ur5, paper_goal)
    scenario = load_params(REPO / "params.yaml").scenarios["paper"]
    goal = {
        "pose": {
            "position": pose[:3, 3].tolist(),
            "quaternion_wxyz": tf.quat_wxyz(pose[:3, :3]).tolist(),
        }
    }
    scenario = scenario.model_copy(update={"goal": type(scenario.goal).model_validate(goal)})
    start, q = resolve_goal(ur5, scenario, name="paper", source="params.yaml")
    assert np.abs(forward_kinematics(ur5, q) - pose).max() < 1e-9
    every = make_solver("analytic", ur5).solve(pose).solutions
    distances = np.linalg.norm(every - start, axis=1)
    assert np.linalg.norm(q - start) == pytest.approx(distances.min(), abs=1e-9)
    # the paper's goal is one of the 8 solutions, but elbow-down is nearer all-zeros
    assert np.abs(every - paper_goal).max(axis=1).min() < 1e-9


@pytest.mark.slow
def test_diverging_episode_is_recorded_reported_and_fails_the_run(tmp_path):
    data = yaml.safe_load(_params(tmp_path).read_text())
    # without rotor armature the wrists are light enough for saturated torque to spin away
    ur5 = (REPO / "pipeline" / "robots" / "ur5.yaml").read_text()
    bare = re.sub(r"^ +armature: [0-9.e+-]+\n", "", ur5, flags=re.MULTILINE)
    assert bare != ur5 and not re.search(r"^ +armature:", bare, re.MULTILINE)
    (tmp_path / "ur5_bare.yaml").write_text(bare)
    data["scenarios"]["paper"]["robot"] = str(tmp_path / "ur5_bare.yaml")
    data["controllers"]["ctc"]["gains"] = {"kp": 1e9, "kd": 0.0}
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    out = tmp_path / "rec"
    result = _record(params, out)
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert re.search(r"^error: paper-ctc: diverged at t=", result.stderr, re.MULTILINE)
    assert sorted(p.name for p in out.iterdir()) == ["paper-ctc", "paper-pid"]
    report = subprocess.run(
        [
            *PIPELINE,
            "report",
            "--recordings",
            str(out),
            "--out",
            str(tmp_path / "rep"),
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert report.returncode == 0, report.stderr
    text = (tmp_path / "rep" / "report.md").read_text()
    assert re.search(r"\*\*paper-ctc\*\* \(ctc, paper\): diverged — diverged at t=", text)


@pytest.mark.slow
def test_a_soft_pid_landing_on_a_shelf_is_flagged_in_summary_recording_and_report(tmp_path):
    """A shelf 20 mm under the elbow at the start pose; a PID tuned to 10 rad/s sags onto
    it while holding the start (kp ~ m w^2, 16x softer than the default). The contact is
    named in the record summary, the recording's settings and the report."""
    from pipeline.model.dh import link_frames
    from pipeline.robots import load_spec
    from pipeline.robots.chain import chain

    spec = load_spec("ur5")
    frame = link_frames(spec, np.zeros(6))[2]
    seg = chain(spec)[2].segments[0]
    z = min((frame @ np.append(p, 1.0))[2] for p in (seg.start, seg.end)) - seg.radius
    shelf = {"name": "shelf", "center": [-0.6, 0.0, float(z) - 0.02 - 0.05],
             "half_size": [0.12, 0.1, 0.05]}  # fmt: skip
    data = yaml.safe_load(_params(tmp_path).read_text())
    data["scenarios"]["paper"]["obstacles"] = [shelf]
    data["scenarios"]["paper"]["preroll_s"] = 1.0
    data["controllers"]["soft"] = {"type": "pid", "gains": {"omega_n_rad_s": 10.0}}
    data["episodes"] = {"shelf-soft": {"scenario": "paper", "controller": "soft", "seed": 0}}
    params = tmp_path / "shelf.yaml"
    params.write_text(yaml.safe_dump(data))
    out = tmp_path / "rec"
    run = _record(params, out)
    assert run.returncode == 0, run.stderr
    assert "warning: shelf-soft: contact during execution: touched shelf" in run.stderr

    from pipeline.log.reader import read_recording

    rec = read_recording(out / "shelf-soft")
    settings = rec.settings
    assert settings is not None, rec.notes
    (contact,) = [c for c in settings.safety.contacts if c.bodies == ("elbow_link", "shelf")]
    assert contact.kind == "obstacle" and 1e-4 < contact.max_depth_m < 0.02
    assert contact.first_ns < settings.protocol.motion_start_s * 1e9  # while holding the start

    report = subprocess.run(
        [*PIPELINE, "report", "--recordings", str(out), "--out", str(tmp_path / "rep"),
         "--baseline", "soft"],
        capture_output=True, text=True, timeout=600, cwd=REPO,
    )  # fmt: skip
    assert report.returncode == 0, report.stderr
    text = (tmp_path / "rep" / "report.md").read_text()
    checks = text.split("## Physical checks", 1)[1].split("\n## ", 1)[0]
    assert "obstacle contact elbow_link – shelf" in checks
