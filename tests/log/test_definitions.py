"""Every definition our bags embed is the upstream one of its ROS distro, with its real hash.

Upstream = rosbags' bundled Humble / Jazzy type stores (common_interfaces & co.) plus the
control_msgs files vendored under ``tests/log/data`` (see its SOURCES.md). Bags written for a
distro are decoded with that distro's upstream definitions, not with the ones they embed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from pipeline.constants import (
    TOPIC_CONTROLLER_STATE,
    TOPIC_JOINT_STATES,
    TYPE_CONTROLLER_STATE,
)
from pipeline.log import bag
from pipeline.log.schemas import ROS_DISTROS, TYPE_HASHES, full_definition
from pipeline.robots import RobotSpec
from tests.log.test_writer import analytic_episode, episode_metadata

DATA = Path(__file__).parent / "data"
CONTROL_MSGS_VERSION = {"humble": "4.8.0", "jazzy": "5.3.0"}
STORES = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}


def upstream_store(distro: str) -> Typestore:
    """The distro's type store plus its upstream control_msgs definition."""
    store = get_typestore(STORES[distro])
    path = DATA / "control_msgs" / CONTROL_MSGS_VERSION[distro]
    text = (path / "JointTrajectoryControllerState.msg").read_text()
    store.register(get_types_from_msg(text, TYPE_CONTROLLER_STATE))
    return store


@pytest.mark.parametrize("distro", ROS_DISTROS)
@pytest.mark.parametrize("type_name", sorted(TYPE_HASHES["jazzy"]))
def test_embedded_definition_is_the_upstream_one_with_its_hash(distro: str, type_name: str) -> None:
    upstream = upstream_store(distro)
    ours = get_types_from_msg(full_definition(type_name, distro), type_name)
    assert type_name in ours
    for name, fields in ours.items():
        assert fields == upstream.fielddefs[name], name
    mine = get_typestore(Stores.EMPTY)
    mine.register(ours)
    assert mine.hash_rihs01(type_name) == upstream.hash_rihs01(type_name)
    assert mine.hash_rihs01(type_name) == TYPE_HASHES[distro][type_name]


def test_controller_state_hashes_are_the_published_ones() -> None:
    assert TYPE_HASHES["jazzy"][TYPE_CONTROLLER_STATE].startswith("RIHS01_51d8dd89")
    assert TYPE_HASHES["humble"][TYPE_CONTROLLER_STATE].startswith("RIHS01_5e2fe5a0")


@pytest.fixture(scope="module", params=ROS_DISTROS)
def distro_bag(
    request: pytest.FixtureRequest, ur5: RobotSpec, tmp_path_factory: pytest.TempPathFactory
) -> tuple[str, bag.BagSummary]:
    result, planned = analytic_episode(ur5, n_steps=300)
    summary = bag.write_episode_bag(
        tmp_path_factory.mktemp(request.param) / "ep",
        spec=ur5,
        result=result,
        planned=planned,
        metadata=episode_metadata(),
        ros_distro=request.param,
    )
    return request.param, summary


def test_every_message_decodes_with_the_distros_upstream_definitions(
    distro_bag: tuple[str, bag.BagSummary], ur5: RobotSpec
) -> None:
    distro, summary = distro_bag
    result, _ = analytic_episode(ur5, n_steps=300)
    store = upstream_store(distro)
    counts: dict[str, int] = {}
    with open(summary.mcap_path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert schema is not None
            msg = store.deserialize_cdr(message.data, schema.name)
            # Re-encoding with the upstream definition gives our bytes back: same layout.
            assert bytes(store.serialize_cdr(msg, schema.name)) == message.data
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            k = int(message.log_time // 1_000_000)
            if channel.topic == TOPIC_CONTROLLER_STATE:
                assert np.array_equal(msg.reference.positions, result.q_ref[k])
                assert np.array_equal(msg.feedback.positions, result.q[k])
                assert np.array_equal(msg.output.effort, result.tau_cmd_nm[k])
                if distro == "humble":
                    assert np.array_equal(msg.desired.positions, result.q_ref[k])
                    assert np.array_equal(msg.actual.positions, result.q[k])
                else:
                    assert msg.speed_scaling_factor == 1.0
            elif channel.topic == TOPIC_JOINT_STATES:
                assert np.array_equal(msg.position, result.q[k])
    assert counts == dict(summary.message_counts)
    assert counts[TOPIC_CONTROLLER_STATE] == 300


def test_metadata_has_the_distros_layout(distro_bag: tuple[str, bag.BagSummary]) -> None:
    distro, summary = distro_bag
    info = yaml.safe_load((summary.path / "metadata.yaml").read_text())
    info = info["rosbag2_bagfile_information"]
    topic = info["topics_with_message_count"][0]["topic_metadata"]
    with open(summary.mcap_path, "rb") as f:
        channels = make_reader(f).get_summary().channels.values()  # type: ignore[union-attr]
    if distro == "humble":  # rosbag2 0.15 (Humble) writes version 5: no hashes, no custom data
        assert info["version"] == 5
        assert "type_description_hash" not in topic and "custom_data" not in info
        assert all(set(c.metadata) == {"offered_qos_profiles"} for c in channels)
    else:
        assert info["version"] == 8 and info["ros_distro"] == "jazzy"
        assert topic["type_description_hash"] == TYPE_HASHES["jazzy"][topic["type"]]
        assert all(c.metadata["topic_type_hash"].startswith("RIHS01_") for c in channels)
    with Reader(summary.path) as reader:  # rosbags' own rosbag2 reader accepts both
        assert reader.message_count == sum(summary.message_counts.values())


def test_ros_distro_option_reaches_every_episode_and_rejects_others(tmp_path: Path) -> None:
    import subprocess
    import sys

    from pipeline.params import load_params

    repo = Path(__file__).resolve().parents[2]
    params = load_params(repo / "params.yaml")
    assert params.sim.ros_distro == "jazzy"
    humble = params.with_ros_distro("humble")
    assert {e.sim.ros_distro for e in humble.episodes} == {"humble"}
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(repo / "params.yaml"),
         "--out", str(tmp_path / "rec"), "--ros-distro", "foxy"],
        capture_output=True, text=True, cwd=repo, check=False,
    )  # fmt: skip
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines() == [
        "error: --ros-distro: 'foxy', expected jazzy or humble"
    ]
    assert not (tmp_path / "rec").exists()
