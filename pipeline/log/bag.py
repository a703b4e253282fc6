"""An episode's topics, and writing them as a rosbag2 directory (``metadata.yaml`` + MCAP).

Layout (what ``ros2 bag record -s mcap`` produces, so ``ros2 bag info/play``, Foxglove,
PlotJuggler, ``rosbags`` and ``mcap_ros2`` open it)::

    <bag_dir>/metadata.yaml       rosbag2 metadata (Jazzy: version 8 + custom_data; Humble: 5)
    <bag_dir>/<name>_0.mcap       profile "ros2", ros2msg schemas, CDR messages, zstd chunks

A topic is a schema plus its data: its row in :data:`pipeline.log.topics.TOPICS` names it,
its type and QoS; the message definitions of the chosen ROS distro
(:mod:`pipeline.log.schemas`) give the layout; and :func:`encode_episode` fills that
layout's leaves (``header.stamp.sec``, ``position``, ...) with whole columns of the episode
at once (:class:`pipeline.log.cdr.Template`). The MCAP records are written by
:mod:`pipeline.log.mcap`, the directory by :mod:`pipeline.log.rosbag2`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline import transforms
from pipeline.constants import (
    METADATA_EPISODE,
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
    TOPIC_PLANNED_TRAJECTORY,
    TOPIC_ROBOT_DESCRIPTION,
    TOPIC_TF,
    TYPE_CONTROLLER_STATE,
)
from pipeline.errors import RecordingError
from pipeline.log import cdr, rosbag2
from pipeline.log.mcap import CHUNK_BYTES, ChannelSpec, MessageBlock, write_mcap
from pipeline.log.schemas import (
    DEFAULT_ROS_DISTRO,
    TYPE_HASHES,
    RosDistro,
    check_distro,
    full_definition,
    message_types,
)
from pipeline.log.topics import TOPICS
from pipeline.model.frames import tf_edges
from pipeline.robots.chain import then_joint_motions
from pipeline.robots.spec import RobotSpec
from pipeline.sim.result import EpisodeResult, TrajectorySamples

__all__ = [
    "CHUNK_BYTES",
    "BagSummary",
    "MessageBlock",
    "check_metadata",
    "check_rates",
    "check_result",
    "encode_episode",
    "planned_arrays",
    "write_episode_bag",
]

REQUIRED_METADATA_KEYS = ("episode", "scenario", "controller", "robot", "seed", "settings")


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
    try:
        distro = check_distro(ros_distro)
    except ValueError as err:
        raise RecordingError(f"ros_distro: {err}") from err
    meta = check_metadata(metadata)
    blocks = encode_episode(
        spec,
        result,
        planned,
        motion_start_ns=motion_start_ns,
        joint_state_decimation=joint_state_decimation,
        tf_rate_hz=tf_rate_hz,
        tf_source=tf_source,
        ros_distro=distro,
    )
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


def _block(
    topic: str,
    distro: RosDistro,
    sample: Mapping[str, Any],
    stamps: NDArray[np.int64],
    columns: Mapping[str, Any],
) -> MessageBlock:
    """A topic's messages: ``sample`` fixes the layout, ``columns`` fill it per message."""
    type_name = _TOPIC[topic].type
    tpl = cdr.template(message_types(type_name, distro), type_name, sample)
    return MessageBlock(topic, stamps, tpl.fill(stamps.size, columns))


def _once(topic: str, distro: RosDistro, stamp_ns: int, value: Mapping[str, Any]) -> MessageBlock:
    """A topic with one message (latched): ``value`` holds every field."""
    type_name = _TOPIC[topic].type
    data, _ = cdr.encode(message_types(type_name, distro), type_name, value)
    return MessageBlock(
        topic, np.array([stamp_ns], np.int64), np.frombuffer(data, np.uint8).reshape(1, -1)
    )


def _header_columns(stamps: NDArray[np.int64], path: str = "header.stamp") -> dict[str, Any]:
    try:
        return dict(cdr.time_values(path, stamps))
    except ValueError as err:
        raise RecordingError(f"result.stamp_ns: {err}") from err


# Which JointTrajectoryPoint fields each point of the controller state carries (as
# ros2_controllers' JTC fills them); the others stay empty. Humble's deprecated
# desired/actual repeat reference/feedback, so subscribers of either generation see them.
_CS_POINT_FIELDS: dict[str, tuple[str, ...]] = {
    "reference": ("positions", "velocities", "accelerations"),
    "feedback": ("positions", "velocities"),
    "error": ("positions", "velocities"),
    "output": ("effort",),
    "desired": ("positions", "velocities", "accelerations"),
    "actual": ("positions", "velocities"),
}


def encode_episode(
    spec: RobotSpec,
    result: EpisodeResult,
    planned: TrajectorySamples,
    *,
    motion_start_ns: int = 0,
    joint_state_decimation: int = 1,
    tf_rate_hz: float = 50.0,
    tf_source: Literal["measured", "true"] = "measured",
    ros_distro: RosDistro = DEFAULT_ROS_DISTRO,
) -> list[MessageBlock]:
    """All messages of an episode, CDR-encoded, one block per topic in :data:`TOPICS` order.

    Log times and header stamps are the simulated ``result.stamp_ns``; /robot_description
    and /planned_trajectory are logged once at the first stamp. /controller_state:
    ``reference`` = q_ref, qd_ref, qdd_ref; ``feedback`` = measured q, qd; ``error`` =
    reference - feedback (positions, velocities); ``output.effort`` = the commanded effort;
    each point's ``time_from_start`` = time since the episode start (where the planned
    trajectory starts); Humble's ``desired``/``actual`` repeat reference/feedback; Jazzy's
    ``speed_scaling_factor`` is 1; unused sequences and the ``multi_dof_*`` fields are empty.
    /joint_states carries the measured q, qd and the applied effort ``tau_nm``;
    /ground_truth/joint_states the plant's true q, qd (no sensor noise) and the same
    effort, at every control step (the report's tracking metrics use it). The planned
    trajectory's header is stamped at the motion start (``motion_start_ns`` after the first
    stamp).
    """
    distro = check_distro(ros_distro)
    stamps, arrays = check_result(spec, result)
    check_rates(joint_state_decimation=joint_state_decimation, tf_rate_hz=tf_rate_hz)
    if tf_source not in ("measured", "true"):
        raise RecordingError(f"tf_source: {tf_source!r}, expected 'measured' or 'true'")
    # Imported here: the URDF module pulls in Pinocchio, which readers of pipeline.log skip.
    from pipeline.robots.urdf import build_urdf

    names = list(spec.joint_names)
    n = len(names)
    t0 = int(stamps[0]) if stamps.size else 0
    header = {"stamp": cdr.time_value(t0 + int(motion_start_ns))}

    blocks = [
        _once(TOPIC_ROBOT_DESCRIPTION, distro, t0, {"data": spec.description or build_urdf(spec)}),
        _once(TOPIC_PLANNED_TRAJECTORY, distro, t0, _planned_value(names, header, planned)),
    ]

    js = slice(None, None, int(joint_state_decimation))
    zeros = np.zeros(n)
    joint_state = {"name": names, "position": zeros, "velocity": zeros, "effort": zeros}

    def joint_states(topic: str, rows: slice, q: str, qd: str) -> MessageBlock:
        columns = {"position": arrays[q][rows], "velocity": arrays[qd][rows]}
        columns["effort"] = arrays["tau_nm"][rows]
        return _block(
            topic, distro, joint_state, stamps[rows], _header_columns(stamps[rows]) | columns
        )

    blocks.append(joint_states(TOPIC_JOINT_STATES, js, "q", "qd"))

    q, qd, q_ref, qd_ref = arrays["q"], arrays["qd"], arrays["q_ref"], arrays["qd_ref"]
    values = {
        "reference": (q_ref, qd_ref, arrays["qdd_ref"]),
        "feedback": (q, qd),
        "error": (q_ref - q, qd_ref - qd),
        "output": (arrays["tau_cmd_nm"],),
    }
    values["desired"], values["actual"] = values["reference"], values["feedback"]
    cs_types = message_types(TYPE_CONTROLLER_STATE, distro)
    points = [f.name for f in cs_types[TYPE_CONTROLLER_STATE].fields if f.name in _CS_POINT_FIELDS]
    sample: dict[str, Any] = {"joint_names": names, "speed_scaling_factor": 1.0}
    columns = _header_columns(stamps)
    for point in points:
        fields = _CS_POINT_FIELDS[point]
        sample[point] = dict.fromkeys(fields, zeros)
        columns |= dict(zip((f"{point}.{f}" for f in fields), values[point], strict=True))
        columns |= _header_columns(stamps - t0, f"{point}.time_from_start")
    blocks.append(_block(TOPIC_CONTROLLER_STATE, distro, sample, stamps, columns))

    idx = tf_sample_indices(stamps, tf_rate_hz)
    q_tf = (arrays["q"] if tf_source == "measured" else arrays["q_true"])[idx]
    frames, translation, rotation = tf_poses(spec, q_tf)
    tf_stamps = stamps[idx]
    tf_sample = {
        "transforms": [
            {"header": {"frame_id": parent}, "child_frame_id": child} for parent, child in frames
        ]
    }
    tf_columns: dict[str, Any] = {}
    for e in range(len(frames)):
        edge = f"transforms[{e}]"
        tf_columns |= _header_columns(tf_stamps, f"{edge}.header.stamp")
        for k, axis in enumerate("xyz"):
            tf_columns[f"{edge}.transform.translation.{axis}"] = translation[:, e, k]
        for k, axis in enumerate("xyzw"):
            tf_columns[f"{edge}.transform.rotation.{axis}"] = rotation[:, e, k]
    blocks.append(_block(TOPIC_TF, distro, tf_sample, tf_stamps, tf_columns))
    blocks.append(joint_states(TOPIC_GROUND_TRUTH, slice(None), "q_true", "qd_true"))
    return blocks


def tf_sample_indices(stamp_ns: NDArray[np.int64], rate_hz: float) -> NDArray[np.intp]:
    """Control steps at which /tf is published: the first step at or after each tick of a
    ``rate_hz`` clock started at the first stamp (every step if the control rate is lower)."""
    if stamp_ns.size == 0:
        return np.zeros(0, dtype=np.intp)
    period_ns = max(1, round(1e9 / rate_hz))
    ticks = np.arange(int(stamp_ns[0]), int(stamp_ns[-1]) + 1, period_ns, dtype=np.int64)
    return np.unique(np.searchsorted(stamp_ns, ticks, side="left"))


def tf_poses(
    spec: RobotSpec, q: NDArray[np.float64]
) -> tuple[list[tuple[str, str]], NDArray[np.float64], NDArray[np.float64]]:
    """URDF link transforms for M joint configurations, vectorized.

    Every joint edge of :func:`pipeline.model.frames.tf_edges` is its transform at q = 0
    followed by the joint's motion (a rotation about, or a translation along, its axis:
    :func:`pipeline.robots.chain.then_joint_motions`); the flange edge is constant.

    Returns:
        (parent, child) frame pairs; (M, E, 3) translations [m]; (M, E, 4) quaternions
        (x, y, z, w) with w >= 0.
    """
    dof = spec.dof
    base = tf_edges(spec, np.zeros(dof))
    frames = [(e.parent, e.child) for e in base]
    m, edges = q.shape[0], len(base)
    translation = np.empty((m, edges, 3))
    quat_wxyz = np.empty((m, edges, 4))
    for i, edge in enumerate(base):
        if i < dof:
            translation[:, i], quat_wxyz[:, i] = then_joint_motions(
                edge.parent_T_child, spec.joints[i], q[:, i]
            )
        else:
            translation[:, i, :] = edge.parent_T_child[:3, 3]
            quat_wxyz[:, i] = transforms.quat_wxyz(edge.parent_T_child[:3, :3])
    quat_wxyz *= np.where(quat_wxyz[..., :1] < 0, -1.0, 1.0)
    return frames, translation, quat_wxyz[..., [1, 2, 3, 0]]


def _planned_value(
    names: list[str], header: Mapping[str, Any], planned: TrajectorySamples
) -> dict[str, Any]:
    """trajectory_msgs/JointTrajectory of the planned samples (effort left empty)."""
    tfs_ns, pos, vel, acc = planned_arrays(len(names), planned)
    return {
        "header": header,
        "joint_names": names,
        "points": [
            {
                "positions": pos[i],
                "velocities": vel[i],
                "accelerations": acc[i],
                "time_from_start": cdr.time_value(tfs_ns[i]),
            }
            for i in range(len(tfs_ns))
        ],
    }


def planned_arrays(
    n: int, planned: TrajectorySamples
) -> tuple[list[int], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The planned samples as recorded: each point's ``time_from_start`` [ns], positions,
    velocities and accelerations ((K, n) float64), checked.

    Raises:
        RecordingError: a shape is not (K, n), or the times are not K >= 1 finite,
            non-decreasing times >= 0.
    """
    times = np.asarray(planned.times_s, dtype=float).reshape(-1)
    k = times.size
    for field in ("positions", "velocities", "accelerations"):
        shape = np.shape(getattr(planned, field))
        if shape != (k, n):
            raise RecordingError(f"planned.{field}: shape {shape}, expected {(k, n)}")
    if k == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) < 0) or times[0] < 0:
        raise RecordingError("planned.times_s: expected >= 1 finite, non-decreasing times >= 0")
    tfs_ns = np.round(times * 1e9).astype(np.int64).tolist()
    pos, vel, acc = (
        np.asarray(getattr(planned, f), dtype=np.float64)
        for f in ("positions", "velocities", "accelerations")
    )
    return tfs_ns, pos, vel, acc


def check_rates(*, joint_state_decimation: int, tf_rate_hz: float) -> None:
    """Refuse a /joint_states decimation that is not an integer >= 1 or a /tf rate that
    is not positive (a :class:`RecordingError` naming the setting)."""
    if not isinstance(joint_state_decimation, int | np.integer) or joint_state_decimation < 1:
        raise RecordingError(
            f"joint_state_decimation: {joint_state_decimation!r}, expected an integer >= 1"
        )
    if not (math.isfinite(tf_rate_hz) and tf_rate_hz > 0):
        raise RecordingError(f"tf_rate_hz: {tf_rate_hz!r}, expected a positive rate [Hz]")


def check_result(
    spec: RobotSpec, result: EpisodeResult
) -> tuple[NDArray[np.int64], dict[str, NDArray[np.float64]]]:
    """The result's stamps [ns] and float64 arrays by name, checked against ``spec``
    (a :class:`RecordingError` naming the field otherwise)."""
    if tuple(result.joint_names) != spec.joint_names:
        raise RecordingError(
            f"result.joint_names {list(result.joint_names)} differ from robot "
            f"{spec.name!r} joints {list(spec.joint_names)}"
        )
    stamps = np.asarray(result.stamp_ns)
    if stamps.ndim != 1 or not np.issubdtype(stamps.dtype, np.integer):
        raise RecordingError(f"result.stamp_ns: expected (N,) integers, got {stamps.dtype}")
    stamps = stamps.astype(np.int64)
    if stamps.size and (stamps[0] < 0 or np.any(np.diff(stamps) <= 0)):
        raise RecordingError("result.stamp_ns: expected strictly increasing times >= 0 [ns]")
    shape = (stamps.size, spec.dof)
    arrays = {}
    for field in ("q", "qd", "q_true", "qd_true", "q_ref", "qd_ref", "qdd_ref", "tau_cmd_nm",
                  "tau_nm"):  # fmt: skip
        raw = np.asarray(getattr(result, field))
        if raw.dtype.kind not in "fiu":  # complex parts would be dropped, booleans read as 0/1
            raise RecordingError(f"result.{field}: dtype {raw.dtype}, expected real numbers")
        arrays[field] = raw.astype(np.float64)
    for field, arr in arrays.items():
        if arr.shape != shape:
            raise RecordingError(f"result.{field}: shape {arr.shape}, expected {shape}")
    return stamps, arrays


def _non_finite(value: Any, where: str) -> str | None:
    """The path and value of the first non-finite number in ``value`` (nested), or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return f"{where} = {value}"
    items = value.items() if isinstance(value, dict) else (
        enumerate(value) if isinstance(value, list) else ())  # fmt: skip
    for key, item in items:
        inner = f"{where}.{key}" if isinstance(value, dict) else f"{where}[{key}]"
        if found := _non_finite(item, inner):
            return found
    return None


def check_metadata(metadata: Mapping[str, str]) -> dict[str, str]:
    """The metadata as stored (keys sorted), checked: strings, the required keys, the
    settings JSON."""
    bad = [k for k, v in metadata.items() if not (isinstance(k, str) and isinstance(v, str))]
    if bad:
        raise RecordingError(f"metadata: keys and values must be strings (not at {bad})")
    missing = [k for k in REQUIRED_METADATA_KEYS if k not in metadata]
    if missing:
        raise RecordingError(
            f"metadata: missing {missing}; required keys: {list(REQUIRED_METADATA_KEYS)}"
        )
    try:
        settings = json.loads(metadata["settings"])
    except ValueError as err:
        raise RecordingError(f"metadata['settings']: not valid JSON ({err})") from err
    controller = settings.get("controller") if isinstance(settings, dict) else None
    gains = controller.get("gains") if isinstance(controller, dict) else None
    if bad_gain := _non_finite(gains, "gains"):
        raise RecordingError(f"metadata['settings'].controller.{bad_gain}: expected finite gains")
    return {k: metadata[k] for k in sorted(metadata)}
