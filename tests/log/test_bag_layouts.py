"""Issue 27 item 8: ``pipeline layouts --bag B --out DIR`` writes the Foxglove and
PlotJuggler layouts for that bag's joints and topics (a robot's bag written by rosbags)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from rosbags.rosbag2 import StoragePlugin

from pipeline.log.reader import ReadOptions, read_recording
from tests.log.test_external_bags import JOINTS, write_external_bag
from tests.test_bad_input import run_cli_out

CS = "/arm_controller/controller_state"


def _foxglove_topics(layout: dict[str, object]) -> set[str]:
    config = layout["configById"]
    assert isinstance(config, dict)
    paths = [p["value"] for c in config.values() if "paths" in c for p in c["paths"]]
    return {p.split(".")[0] for p in paths}


def test_layouts_for_a_robots_bag_name_its_joints_and_its_topics(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "run1"
    write_external_bag(bag, distro="jazzy", storage=StoragePlugin.MCAP, cs_topic=CS)
    present = set(read_recording(bag, ReadOptions()).topic_counts)
    out = tmp_path / "layouts"
    code, stdout, err = run_cli_out(
        ["layouts", "--bag", str(bag), "--out", str(out), "--topic", f"controller_state={CS}"],
        capsys,
    )
    assert code == 0, err
    assert "/ground_truth/joint_states" in stdout  # named as left out: a real robot has none
    fox = json.loads((out / "foxglove.json").read_text(encoding="utf-8"))
    tabs = fox["configById"]["Tab!joints"]["tabs"]
    assert [t["title"] for t in tabs[:-1]] == [f"{i + 1} {j}" for i, j in enumerate(JOINTS)]
    topics = _foxglove_topics(fox)
    assert (
        CS in topics
        and "/joint_states" in topics
        and topics <= present | {"/foxglove_script/true_state_error"}
    )
    assert "/foxglove_script/true_state_error" not in topics  # its input is not in the bag
    pj = ET.parse(out / "plotjuggler.xml").getroot()
    curves = {c.get("name") for c in pj.iter("curve")}
    assert f"/joint_states/{JOINTS[0]}/position" in curves  # JointState series by joint name
    assert f"{CS}/reference/positions[0]" in curves
    assert not any("ground_truth" in str(c) or "true_state_error" in str(c) for c in curves)


def test_without_the_remap_the_controller_state_plots_are_left_out_and_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "run1"
    write_external_bag(bag, distro="humble", storage=StoragePlugin.MCAP, cs_topic=CS)
    code, stdout, err = run_cli_out(["layouts", "--bag", str(bag), "--out", str(tmp_path)], capsys)
    assert code == 0, err
    assert "--topic" in stdout and "/controller_state" in stdout
    assert _foxglove_topics(json.loads((tmp_path / "foxglove.json").read_text())) == {
        "/joint_states"
    }
