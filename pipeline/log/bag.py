"""An episode's topics, and writing them as a rosbag2 directory (``metadata.yaml`` + MCAP).

Layout (what ``ros2 bag record -s mcap`` produces, so ``ros2 bag info/play``, Foxglove,
PlotJuggler, ``rosbags`` and ``mcap_ros2`` open it)::

    <bag_dir>/metadata.yaml       rosbag2 metadata (Jazzy: version 8 + custom_data; Humble: 5)
    <bag_dir>/<name>_0.mcap       profile "ros2", ros2msg schemas, CDR messages, zstd chunks

A topic is a schema plus its data: its row in :data:`pipeline.log.topics.TOPICS` names it,
its type and QoS, and fills its messages' leaves (``header.stamp.sec``, ``position``, ...)
with whole columns of the episode (:class:`pipeline.log.streams.EpisodeStreams`); the
message definitions of the chosen ROS distro (:mod:`pipeline.log.schemas`) give the
layout, and :func:`encode_streams` encodes every row's fill at once
(:class:`pipeline.log.cdr.Template`). The MCAP records are written by
:mod:`pipeline.log.mcap`, the directory by :mod:`pipeline.log.rosbag2`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from pipeline.constants import METADATA_EPISODE
from pipeline.errors import RecordingError
from pipeline.log import cdr, rosbag2
from pipeline.log.mcap import CHUNK_BYTES, ChannelSpec, MessageBlock, write_mcap
from pipeline.log.schemas import (
    DEFAULT_ROS_DISTRO,
    TYPE_HASHES,
    RosDistro,
    full_definition,
    message_types,
)
from pipeline.log.streams import (
    REQUIRED_METADATA_KEYS,
    EpisodeStreams,
    check_metadata,
    check_rates,
    check_result,
    planned_arrays,
)
from pipeline.log.topics import TOPICS, tf_poses, tf_sample_indices
from pipeline.robots.spec import RobotSpec
from pipeline.sim.result import EpisodeResult, TrajectorySamples

__all__ = [
    "CHUNK_BYTES",
    "REQUIRED_METADATA_KEYS",
    "BagSummary",
    "MessageBlock",
    "check_metadata",
    "check_rates",
    "check_result",
    "encode_episode",
    "encode_streams",
    "planned_arrays",
    "tf_poses",
    "tf_sample_indices",
    "write_episode_bag",
    "write_streams",
]


_TOPIC = {t.name: t for t in TOPICS}


def channel_specs(distro: RosDistro) -> list[ChannelSpec]:
    """The MCAP channels of :data:`TOPICS` with ``distro``'s schemas and channel metadata
    (Humble's rosbag2 stores only the QoS; later ones also the type hash)."""
    specs = []
    for t in TOPICS:
        meta = {"offered_qos_profiles": t.qos.to_yaml()}
        if distro != "humble":
            meta["topic_type_hash"] = TYPE_HASHES[distro][t.type]
        specs.append(ChannelSpec(t.name, t.type, full_definition(t.type, distro), meta))
    return specs


@dataclass(frozen=True)
class BagSummary:
    """What :func:`write_episode_bag` wrote.

    Attributes:
        path: the bag directory.
        mcap_path: its MCAP file.
        message_counts: messages per topic.
        size_bytes: bytes of the MCAP file plus metadata.yaml.
        start_ns: first log time [ns] (simulated time).
        duration_ns: last minus first log time [ns].
        ros_distro: whose message definitions and metadata layout the bag uses.
    """

    path: Path
    mcap_path: Path
    message_counts: Mapping[str, int]
    size_bytes: int
    start_ns: int
    duration_ns: int
    ros_distro: RosDistro = DEFAULT_ROS_DISTRO


# --- public entry point -------------------------------------------------------------------


def write_episode_bag(
    bag_dir: Path,
    *,
    spec: RobotSpec,
    result: EpisodeResult,
    planned: TrajectorySamples,
    metadata: Mapping[str, str],
    motion_start_ns: int = 0,
    joint_state_decimation: int = 1,
    tf_rate_hz: float = 50.0,
    tf_source: Literal["measured", "true"] = "measured",
    ros_distro: str = DEFAULT_ROS_DISTRO,
    force: bool = False,
) -> BagSummary:
    """Record an episode as a rosbag2 directory (MCAP storage), atomically.

    Args:
        bag_dir: directory to create; its parent is created if missing.
        spec: the robot (URDF for /robot_description, frames for /tf).
        result: the episode; its ``stamp_ns`` become log times and header stamps.
        planned: the planned trajectory, published once on /planned_trajectory, its header
            stamped ``motion_start_ns`` after the first stamp (when the motion starts).
        motion_start_ns: the pre-roll: time from the first stamp to the motion start [ns].
        metadata: episode settings as strings; must hold REQUIRED_METADATA_KEYS, and
            "settings" must be JSON. Stored as the MCAP metadata record "armlab.episode" and
            (Jazzy) as metadata.yaml ``custom_data``.
        joint_state_decimation: publish /joint_states every k-th control step.
        tf_rate_hz: /tf publication rate [Hz] (sampled from the control steps).
        tf_source: joint positions /tf is computed from: "measured" (as
            robot_state_publisher would from /joint_states) or "true" (noise-free plant).
        ros_distro: "jazzy" or "humble": the message definitions and metadata layout, so
            subscribers of that distro decode every topic.
        force: replace an existing recording at ``bag_dir``.

    Raises:
        RecordingError: ``bag_dir`` exists without ``force``, or inputs are inconsistent.
    """
    bag_dir = Path(bag_dir)
    if os.path.lexists(bag_dir) and not force:
        raise RecordingError(f"{bag_dir}: recording already exists; use --force to overwrite it")
    episode = EpisodeStreams.of(
        spec=spec,
        result=result,
        planned=planned,
        metadata=metadata,
        motion_start_ns=motion_start_ns,
        joint_state_decimation=joint_state_decimation,
        tf_rate_hz=tf_rate_hz,
        tf_source=tf_source,
        ros_distro=ros_distro,
    )
    return write_streams(bag_dir, episode, force=force)


def write_streams(bag_dir: Path, episode: EpisodeStreams, *, force: bool = False) -> BagSummary:
    """Record ``episode`` as a rosbag2 directory (MCAP storage) at ``bag_dir``, atomically
    (:func:`write_episode_bag` of its arrays).

    Raises:
        RecordingError: ``bag_dir`` exists without ``force``, or a fill is refused.
    """
    bag_dir = Path(bag_dir)
    if os.path.lexists(bag_dir) and not force:
        raise RecordingError(f"{bag_dir}: recording already exists; use --force to overwrite it")
    distro, meta = episode.ros_distro, episode.metadata
    blocks = encode_streams(episode)
    mcap_name = f"{bag_dir.name}_0.mcap"
    written: dict[str, Any] = {}

    def write(tmp: Path) -> None:
        with open(tmp / mcap_name, "xb") as f:
            stats = write_mcap(f, channel_specs(distro), blocks, metadata={METADATA_EPISODE: meta})
        topics = [
            rosbag2.TopicInfo(
                name,
                _TOPIC[name].type,
                _TOPIC[name].qos.to_yaml(),
                TYPE_HASHES[distro][_TOPIC[name].type],
                count,
            )
            for name, count in stats.message_counts.items()
        ]
        text = rosbag2.metadata_yaml(
            mcap_name,
            topics=topics,
            start_ns=stats.start_ns,
            end_ns=stats.end_ns,
            custom_data=meta,
            ros_distro=distro,
        )
        with open(tmp / rosbag2.METADATA_FILE, "x", encoding="utf-8") as f:
            f.write(text)
        written["stats"] = stats

    size = rosbag2.write_bag_dir(bag_dir, write, force=force)
    stats = written["stats"]
    return BagSummary(
        path=bag_dir,
        mcap_path=bag_dir / mcap_name,
        message_counts=dict(stats.message_counts),
        size_bytes=size,
        start_ns=stats.start_ns,
        duration_ns=stats.end_ns - stats.start_ns,
        ros_distro=distro,
    )


# --- episode -> messages ------------------------------------------------------------------


def encode_episode(
    spec: RobotSpec,
    result: EpisodeResult,
    planned: TrajectorySamples,
    *,
    motion_start_ns: int = 0,
    joint_state_decimation: int = 1,
    tf_rate_hz: float = 50.0,
    tf_source: Literal["measured", "true"] = "measured",
    ros_distro: str = DEFAULT_ROS_DISTRO,
) -> list[MessageBlock]:
    """All messages of an episode's arrays, CDR-encoded (:func:`encode_streams`)."""
    return encode_streams(
        EpisodeStreams.of(
            spec=spec,
            result=result,
            planned=planned,
            metadata=None,
            motion_start_ns=motion_start_ns,
            joint_state_decimation=joint_state_decimation,
            tf_rate_hz=tf_rate_hz,
            tf_source=tf_source,
            ros_distro=ros_distro,
        )
    )


def encode_streams(episode: EpisodeStreams) -> list[MessageBlock]:
    """All messages of an episode, CDR-encoded, one block per topic in :data:`TOPICS` order:
    each row's fill (:mod:`pipeline.log.topics` says what each topic carries).

    Log times and header stamps are the simulated stamps; /robot_description and
    /planned_trajectory are logged once at the first stamp.
    """
    distro = episode.ros_distro
    blocks = []
    for topic in TOPICS:
        fill = topic.fill(episode)
        types = message_types(topic.type, distro)
        if fill.sample is None:  # one message: its whole value
            data, _ = cdr.encode(types, topic.type, fill.columns)
            rows = np.frombuffer(data, np.uint8).reshape(1, -1)
        else:
            tpl = cdr.template(types, topic.type, fill.sample)
            rows = tpl.fill(fill.stamps.size, fill.columns)
        blocks.append(MessageBlock(topic.name, fill.stamps, rows))
    return blocks
