"""`pipeline report --salvage` as a process, on bags damaged after writing (our writer's MCAP,
rosbags' sqlite3): refused without the flag, salvaged ones marked in the status column of
report.md, episodes.csv and metrics.json, and not compared when cut before the motion end.
A bag without our metadata takes its effort limits from its own URDF only."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import StoragePlugin

from pipeline.log import bag
from pipeline.log.reader import ReadOptions, read_recording
from pipeline.robots import RobotSpec
from tests.log.test_external_bags import write_external_bag
from tests.log.test_salvage import chunk_offsets
from tests.log.test_writer import analytic_episode, episode_metadata

N_STEPS = 4000  # 4 s at 1 kHz: several chunks


def report(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", "from pipeline.cli import main; main()", "report", *args],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def bag_counts(bag_dir: Path) -> int:
    info = yaml.safe_load((bag_dir / "metadata.yaml").read_text())
    return int(info["rosbag2_bagfile_information"]["message_count"])


def episode_rows(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "episodes.csv", newline="") as f:
        return {r["episode"]: r for r in csv.DictReader(f)}


def markdown_status(text: str, episode: str) -> str:
    """The status cell of ``episode``'s row in report.md's episode table."""
    section = text.split("## Episodes", 1)[1]
    header = next(line for line in section.splitlines() if line.startswith("| episode"))
    cells = [c.strip() for c in header.strip("|").split("|")]
    row = next(line for line in section.splitlines() if line.startswith(f"| {episode} |"))
    return [c.strip() for c in row.strip("|").split("|")][cells.index("status")]


@pytest.mark.slow
def test_a_truncated_bag_of_ours_is_salvaged_marked_and_not_compared(
    ur5: RobotSpec, tmp_path: Path
) -> None:
    recordings = tmp_path / "recordings"
    for name, controller in (("pid_paper", "pid"), ("ctc_paper", "ctc")):
        result, planned = analytic_episode(ur5, n_steps=N_STEPS)
        bag.write_episode_bag(
            recordings / name,
            spec=ur5,
            result=result,
            planned=planned,
            metadata=episode_metadata(episode=name, controller=controller),
        )
    damaged = next((recordings / "ctc_paper").glob("*.mcap"))
    starts = chunk_offsets(damaged)
    cut = (starts[2] + starts[3]) // 2  # inside the third chunk
    damaged.write_bytes(damaged.read_bytes()[:cut])

    refused = report(tmp_path, "--baseline", "pid")
    assert refused.returncode == 1
    assert refused.stderr.count("\n") == 1 and "Traceback" not in refused.stderr
    assert str(damaged.relative_to(tmp_path)) in refused.stderr
    assert "truncated" in refused.stderr
    assert not (tmp_path / "reports").exists()

    done = report(tmp_path, "--baseline", "pid", "--salvage")
    assert done.returncode == 0, done.stderr
    out = tmp_path / "reports"
    # lost: the messages metadata.yaml counts that were not read (not the bytes after the
    # damage of the bytes that survived, issue 20)
    declared = bag_counts(recordings / "ctc_paper")
    read = read_recording(recordings / "ctc_paper", ReadOptions(salvage=True)).topic_counts
    lost_pct = 100 * (declared - sum(read.values())) / declared
    assert lost_pct > 100 * (cut - starts[2]) / cut
    shown = f"ok (salvaged: {lost_pct:.1f} % lost; cut before the motion end, not compared)"
    text = (out / "report.md").read_text()
    assert markdown_status(text, "ctc_paper") == shown
    assert markdown_status(text, "pid_paper") == "ok"
    assert "**1 episode(s) salvaged**" in text
    rows = episode_rows(out)
    assert rows["ctc_paper"]["salvaged"] == "true" and rows["pid_paper"]["salvaged"] == "false"
    assert float(rows["ctc_paper"]["salvage_lost_pct"]) == pytest.approx(lost_pct)
    assert rows["pid_paper"]["salvage_lost_pct"] == ""
    # The recording stops before the planned motion's end: no final error, no comparison.
    assert rows["ctc_paper"]["motion_completed"] == "false"
    assert float(rows["ctc_paper"]["end_s"]) < float(rows["ctc_paper"]["motion_end_s"])
    metrics = json.loads((out / "metrics.json").read_text())
    ctc = metrics["episodes"]["ctc_paper"]
    assert ctc["salvaged"] is True and ctc["salvage_lost_pct"] == pytest.approx(lost_pct)
    assert ctc["motion_completed"] is False
    assert all(j["final_error"] is None for k, j in ctc["joints"].items() if k != "tcp")
    assert ctc["joints"]["tcp"]["tcp_final_position_error"] is None
    assert metrics["comparisons"] == []
    assert "salvaged" in done.stdout  # the terminal summary's status too


def _foreign_pair(bags: Path) -> Path:
    """Two robots' bags written by rosbags in sqlite3: ``pid`` (Humble, intact) and ``ctc``
    (Jazzy, truncated at 60 %)."""
    write_external_bag(bags / "pid", distro="humble", storage=StoragePlugin.SQLITE3)
    write_external_bag(bags / "ctc", distro="jazzy", storage=StoragePlugin.SQLITE3)
    [db] = (bags / "ctc").glob("*.db3")
    data = db.read_bytes()
    db.write_bytes(data[: len(data) * 6 // 10])
    return db


@pytest.mark.slow
def test_a_truncated_db3_of_a_foreign_robot_is_salvaged_and_marked(tmp_path: Path) -> None:
    db = _foreign_pair(tmp_path / "bags")
    args = ("--recordings", "bags", "--out", "out", "--baseline", "pid")
    refused = report(tmp_path, *args)
    assert refused.returncode == 1
    assert refused.stderr.count("\n") == 1 and "Traceback" not in refused.stderr
    assert db.name in refused.stderr and "truncated" in refused.stderr

    done = report(tmp_path, *args, "--salvage")
    assert done.returncode == 0, done.stderr
    out = tmp_path / "out"
    text = (out / "report.md").read_text()
    status = markdown_status(text, "ctc")
    found = re.fullmatch(
        r"ok \(salvaged: ([\d.]+) % lost; cut before the motion end, not compared\)", status
    )
    assert found, status
    rows = episode_rows(out)
    assert float(rows["ctc"]["salvage_lost_pct"]) == pytest.approx(float(found[1]), abs=0.05)
    # the share lost is of the message rows: about the share of the file cut off
    assert 20 < float(found[1]) < 60
    assert int(rows["ctc"]["samples"]) < int(rows["pid"]["samples"])
    # No planned trajectory, so no motion end: the salvaged one is not called complete.
    assert rows["ctc"]["motion_completed"] == "false" and rows["pid"]["motion_completed"] == "true"
    assert "recording salvaged: cut at the damage" in text
    metrics: dict[str, Any] = json.loads((out / "metrics.json").read_text())
    assert metrics["comparisons"] == []
    assert any(w.startswith("salvaged: ") for w in metrics["episodes"]["ctc"]["warnings"])


UR5_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint")


@pytest.mark.slow
def test_a_foreign_ur5_takes_its_effort_limits_from_its_urdf(tmp_path: Path) -> None:
    # Named like our built-in ur5 (150 N m on these joints), with limits of its own.
    limits = (4.0, 4.5, 300.0)
    s = write_external_bag(
        tmp_path / "bags" / "jtc",
        distro="jazzy",
        storage=StoragePlugin.MCAP,
        joints=UR5_JOINTS,
        robot_name="ur5",
        urdf_effort_nm=limits,
    )
    done = report(tmp_path, "--recordings", "bags", "--out", "out", "--baseline", "jtc")
    assert done.returncode == 0, done.stderr
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    episode = metrics["episodes"]["jtc"]
    assert episode["robot"] == "ur5"
    for j, joint in enumerate(UR5_JOINTS):
        # independent: the share of written efforts at or above the URDF's limit
        expected = float(np.mean(np.abs(s["effort"][:, j]) >= limits[j] * (1 - 1e-6)))
        got = episode["joints"][joint]["saturation_fraction"]
        assert got == pytest.approx(expected, abs=1e-3)
    assert episode["joints"]["shoulder_pan_joint"]["saturation_fraction"] > 0.1
    text = (tmp_path / "out" / "report.md").read_text()
    assert "effort limits from the bag's /robot_description URDF [N m]: " in text
    assert "shoulder_pan_joint 4, shoulder_lift_joint 4.5, elbow_joint 300" in text


@pytest.mark.slow
def test_a_bag_missing_declared_messages_is_refused_unless_salvaged(tmp_path: Path) -> None:
    """A rosbags bag whose metadata.yaml counts 39 more joint states than it holds: the
    report refuses it in one line, and with --salvage marks it salvaged with the share."""
    bags = tmp_path / "bags"
    write_external_bag(bags / "pid", distro="jazzy", storage=StoragePlugin.MCAP)
    write_external_bag(bags / "ctc", distro="jazzy", storage=StoragePlugin.MCAP)
    meta = bags / "ctc" / "metadata.yaml"
    info = yaml.safe_load(meta.read_text())
    for entry in info["rosbag2_bagfile_information"]["topics_with_message_count"]:
        if entry["topic_metadata"]["name"] == "/joint_states":
            entry["message_count"] += 39
    meta.write_text(yaml.safe_dump(info))
    args = ("--recordings", "bags", "--out", "out", "--baseline", "pid")
    refused = report(tmp_path, *args)
    assert refused.returncode == 1
    assert refused.stderr.count("\n") == 1 and "Traceback" not in refused.stderr
    assert "metadata.yaml declares" in refused.stderr and "--salvage" in refused.stderr
    assert not (tmp_path / "out").exists()

    done = report(tmp_path, *args, "--salvage")
    assert done.returncode == 0, done.stderr
    rows = episode_rows(tmp_path / "out")
    assert rows["ctc"]["salvaged"] == "true" and rows["pid"]["salvaged"] == "false"
    assert 0 < float(rows["ctc"]["salvage_lost_pct"]) < 2
