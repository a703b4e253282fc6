"""The recording writer, checked with independent readers (mcap, mcap_ros2, rosbags).

Episodes are analytic signals (sines with known values) on the real UR5 spec; every decoded
field must equal its source bit for bit.
"""

from __future__ import annotations

import io
import json
import math
import struct
import zlib
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap.records import Chunk, Footer, Message
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from mcap_ros2.reader import read_ros2_messages
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability
from rosbags.typesys import Stores, get_typestore

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
from pipeline.log import bag, rosbag2
from pipeline.log.schemas import QOS_LATCHED, TYPE_HASHES, full_definition
from pipeline.log.topics import TOPICS
from pipeline.model.frames import tf_edges
from pipeline.robots import RobotSpec
from pipeline.robots.urdf import build_urdf
from pipeline.sim.result import EpisodeResult, TrajectorySamples

DT_NS = 1_000_000  # 1 kHz control
N_STEPS = 1500  # 1.5 s: header seconds roll over


def analytic_episode(
    spec: RobotSpec, *, n_steps: int = N_STEPS, t0_ns: int = 0, phase: float = 0.0
) -> tuple[EpisodeResult, TrajectorySamples]:
    """Sine references, a known tracking error and a saturating effort."""
    n = spec.dof
    stamp_ns = t0_ns + DT_NS * np.arange(n_steps, dtype=np.int64)
    t = (stamp_ns - t0_ns)[:, None] * 1e-9
    w = 0.5 + 0.25 * np.arange(n)
    q_ref = 0.3 * np.sin(w * t + phase)
    qd_ref = 0.3 * w * np.cos(w * t + phase)
    qdd_ref = -0.3 * w**2 * np.sin(w * t + phase)
    e = 1e-3 * np.sin(7.0 * t + np.arange(n))
    tau_cmd = 12.0 * np.cos(3.0 * t + np.arange(n))
    result = EpisodeResult(
        joint_names=spec.joint_names,
        stamp_ns=stamp_ns,
        q=q_ref - e + 1e-5,
        qd=qd_ref - 7e-3 * np.cos(7.0 * t),
        q_true=q_ref - e,
        qd_true=qd_ref,
        q_ref=q_ref,
        qd_ref=qd_ref,
        qdd_ref=qdd_ref,
        tau_cmd_nm=tau_cmd,
        tau_nm=np.clip(tau_cmd, -10.0, 10.0),
        saturated=np.abs(tau_cmd) > 10.0,
    )
    times_s = np.linspace(0.0, (n_steps - 1) * DT_NS * 1e-9, 151)
    ts = times_s[:, None]
    planned = TrajectorySamples(
        times_s=times_s,
        positions=0.3 * np.sin(w * ts + phase),
        velocities=0.3 * w * np.cos(w * ts + phase),
        accelerations=-0.3 * w**2 * np.sin(w * ts + phase),
    )
    return result, planned


def episode_metadata(**extra: str) -> dict[str, str]:
    settings = {"robot": "ur5", "gains": {"kp": [100.0] * 6}, "seed": 7, "status": "ok"}
    return {
        "episode": "ctc_paper",
        "scenario": "paper",
        "controller": "ctc",
        "robot": "ur5",
        "seed": "7",
        "settings": json.dumps(settings, sort_keys=True),
        **extra,
    }


@pytest.fixture(scope="module")
def episode(ur5: RobotSpec) -> tuple[EpisodeResult, TrajectorySamples]:
    return analytic_episode(ur5)


@pytest.fixture(scope="module")
def written(
    ur5: RobotSpec,
    episode: tuple[EpisodeResult, TrajectorySamples],
    tmp_path_factory: pytest.TempPathFactory,
) -> bag.BagSummary:
    result, planned = episode
    return bag.write_episode_bag(
        tmp_path_factory.mktemp("rec") / "ctc_paper",
        spec=ur5,
        result=result,
        planned=planned,
        metadata=episode_metadata(),
        joint_state_decimation=2,
        tf_rate_hz=50.0,
    )


def stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def arr(values: Any) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)


def assert_point(point: Any, expected: dict[str, np.ndarray], n: int, tfs_ns: int) -> None:
    for field in ("positions", "velocities", "accelerations", "effort"):
        got = arr(getattr(point, field))
        want = expected.get(field, np.zeros(0))
        assert got.shape == want.shape and np.array_equal(got, want), field
    assert stamp_ns(point.time_from_start) == tfs_ns


def check_decoded(
    messages: Iterator[tuple[str, int, Any]],
    spec: RobotSpec,
    result: EpisodeResult,
    planned: TrajectorySamples,
    *,
    decimation: int,
    tf_rate_hz: float,
) -> None:
    """Compare every decoded message (topic, log time, msg) with the episode it came from."""
    by_topic: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    for topic, log_time, msg in messages:
        by_topic[topic].append((log_time, msg))
    names = list(spec.joint_names)
    st = result.stamp_ns
    t0 = int(st[0])

    [(t, desc)] = by_topic[TOPIC_ROBOT_DESCRIPTION]
    assert t == t0 and desc.data == build_urdf(spec)

    [(t, plan)] = by_topic[TOPIC_PLANNED_TRAJECTORY]
    assert t == t0 and stamp_ns(plan.header.stamp) == t0 and plan.header.frame_id == ""
    assert list(plan.joint_names) == names and len(plan.points) == planned.times_s.size
    for k, point in enumerate(plan.points):
        expected = {
            "positions": planned.positions[k],
            "velocities": planned.velocities[k],
            "accelerations": planned.accelerations[k],
        }
        assert_point(point, expected, spec.dof, round(planned.times_s[k] * 1e9))

    js = by_topic[TOPIC_JOINT_STATES]
    rows = np.arange(0, st.size, decimation)
    assert [t for t, _ in js] == st[rows].tolist()
    for (t, msg), k in zip(js, rows, strict=True):
        assert stamp_ns(msg.header.stamp) == t and msg.header.frame_id == ""
        assert list(msg.name) == names
        assert np.array_equal(arr(msg.position), result.q[k])
        assert np.array_equal(arr(msg.velocity), result.qd[k])
        assert np.array_equal(arr(msg.effort), result.tau_nm[k])

    cs = by_topic[TOPIC_CONTROLLER_STATE]
    assert [t for t, _ in cs] == st.tolist()
    for k, (t, msg) in enumerate(cs):
        assert stamp_ns(msg.header.stamp) == t and list(msg.joint_names) == names
        tfs = t - t0
        ref = {"positions": result.q_ref[k], "velocities": result.qd_ref[k]}
        assert_point(msg.reference, {**ref, "accelerations": result.qdd_ref[k]}, 6, tfs)
        assert_point(msg.feedback, {"positions": result.q[k], "velocities": result.qd[k]}, 6, tfs)
        err = {
            "positions": result.q_ref[k] - result.q[k],
            "velocities": result.qd_ref[k] - result.qd[k],
        }
        assert_point(msg.error, err, 6, tfs)
        assert_point(msg.output, {"effort": result.tau_cmd_nm[k]}, 6, tfs)
        assert list(msg.multi_dof_joint_names) == []
        for field in ("reference", "feedback", "error", "output"):
            point = getattr(msg, f"multi_dof_{field}")
            assert len(point.transforms) == len(point.velocities) == len(point.accelerations) == 0
            assert stamp_ns(point.time_from_start) == 0

    tf = by_topic[TOPIC_TF]
    period_ns = round(1e9 / tf_rate_hz)
    assert len(tf) == (int(st[-1]) - t0) // period_ns + 1  # control period divides tf period
    edges = tf_edges(spec, np.zeros(spec.dof))
    for t, msg in tf:
        assert t % period_ns == 0 and len(msg.transforms) == len(edges)
        for ts, edge in zip(msg.transforms, edges, strict=True):
            assert stamp_ns(ts.header.stamp) == t
            assert (ts.header.frame_id, ts.child_frame_id) == (edge.parent, edge.child)
    gt = by_topic[TOPIC_GROUND_TRUTH]
    assert [t for t, _ in gt] == st.tolist()  # every control step, never decimated
    for k, (t, msg) in enumerate(gt):
        assert stamp_ns(msg.header.stamp) == t and list(msg.name) == names
        np.testing.assert_array_equal(msg.position, result.q_true[k])
        np.testing.assert_array_equal(msg.velocity, result.qd_true[k])
        np.testing.assert_array_equal(msg.effort, result.tau_nm[k])
    # every row's topic, and the ones checked above among them
    assert (
        set(by_topic)
        == {t.name for t in TOPICS}
        >= {
            TOPIC_ROBOT_DESCRIPTION,
            TOPIC_PLANNED_TRAJECTORY,
            TOPIC_JOINT_STATES,
            TOPIC_CONTROLLER_STATE,
            TOPIC_TF,
            TOPIC_GROUND_TRUTH,
        }
    )


def test_mcap_ros2_reader_recovers_every_field_exactly(
    written: bag.BagSummary, ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples]
) -> None:
    messages = (
        (m.channel.topic, m.log_time_ns, m.ros_msg)
        for m in read_ros2_messages(str(written.mcap_path))
    )
    check_decoded(messages, ur5, *episode, decimation=2, tf_rate_hz=50.0)


def test_rosbags_anyreader_opens_the_directory_and_recovers_every_field_exactly(
    written: bag.BagSummary, ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples]
) -> None:
    # An empty type store: every type must come from the definitions embedded in the bag.
    with AnyReader([written.path], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles[0].durability for c in reader.connections}
        assert qos[TOPIC_ROBOT_DESCRIPTION] == qos[TOPIC_PLANNED_TRAJECTORY]
        assert qos[TOPIC_ROBOT_DESCRIPTION] == QosDurability.TRANSIENT_LOCAL
        assert qos[TOPIC_JOINT_STATES] == QosDurability.VOLATILE
        assert {c.topic: c.digest for c in reader.connections}[TOPIC_CONTROLLER_STATE] == (
            TYPE_HASHES["jazzy"][TYPE_CONTROLLER_STATE]
        )
        messages = [
            (c.topic, t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()
        ]
    check_decoded(iter(messages), ur5, *episode, decimation=2, tf_rate_hz=50.0)


def test_tf_carries_the_link_poses_of_tf_edges(
    written: bag.BagSummary, ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples]
) -> None:
    result, _ = episode
    row_of = {int(t): k for k, t in enumerate(result.stamp_ns)}
    count = 0
    for m in read_ros2_messages(str(written.mcap_path), topics=[TOPIC_TF]):
        edges = tf_edges(ur5, result.q[row_of[m.log_time_ns]])
        for ts, edge in zip(m.ros_msg.transforms, edges, strict=True):
            tr, rot = ts.transform.translation, ts.transform.rotation
            assert np.allclose([tr.x, tr.y, tr.z], edge.parent_T_child[:3, 3], atol=1e-12)
            assert math.isclose(rot.x**2 + rot.y**2 + rot.z**2 + rot.w**2, 1.0, rel_tol=1e-12)
            r = transforms.quat_to_matrix(np.array([rot.w, rot.x, rot.y, rot.z]))
            assert np.allclose(r, edge.parent_T_child[:3, :3], atol=1e-12)
        count += 1
    assert count == written.message_counts[TOPIC_TF] > 10


def test_tf_source_true_uses_the_noise_free_positions(
    ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples]
) -> None:
    result, planned = episode
    decode = generate_dynamic("tf2_msgs/msg/TFMessage", full_definition("tf2_msgs/msg/TFMessage"))
    for source, q in (("true", result.q_true), ("measured", result.q)):
        blocks = bag.encode_episode(ur5, result, planned, tf_rate_hz=10.0, tf_source=source)
        [tf] = [b for b in blocks if b.topic == TOPIC_TF]
        for t, row in zip(tf.log_time_ns.tolist(), tf.payload, strict=True):
            msg = decode["tf2_msgs/msg/TFMessage"](bytes(row))
            edge = tf_edges(ur5, q[t // DT_NS])[2]  # elbow: depends on q[2]
            rot = msg.transforms[2].transform.rotation
            r = transforms.quat_to_matrix(np.array([rot.w, rot.x, rot.y, rot.z]))
            assert np.allclose(r, edge.parent_T_child[:3, :3], atol=1e-12)


@pytest.mark.parametrize("distro", ["jazzy", "humble"])
def test_encoders_match_mcap_ros2_encoder_byte_for_byte(
    ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples], distro: str
) -> None:
    result, planned = episode
    names = list(ur5.joint_names)

    def encoder(type_name: str) -> Any:
        return serialize_dynamic(type_name, full_definition(type_name, distro))[type_name]

    def time(ns: int) -> dict[str, int]:
        return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}

    def point(tfs: int, **fields: np.ndarray) -> dict[str, Any]:
        seqs = {f: fields.get(f, np.zeros(0)).tolist() for f in ("positions", "velocities")}
        seqs |= {f: fields.get(f, np.zeros(0)).tolist() for f in ("accelerations", "effort")}
        return {**seqs, "time_from_start": time(tfs)}

    blocks = {b.topic: b for b in bag.encode_episode(ur5, result, planned, ros_distro=distro)}
    js, cs, tf = (blocks[t] for t in (TOPIC_JOINT_STATES, TOPIC_CONTROLLER_STATE, TOPIC_TF))
    tf_row = {int(t): i for i, t in enumerate(tf.log_time_ns)}
    frames, translation, rotation = bag.tf_poses(ur5, result.q)
    empty_multi = {"transforms": [], "velocities": [], "accelerations": [], **point(0)}
    multi = ["reference", "feedback", "error", "output"]
    if distro == "humble":
        multi += ["desired", "actual"]
    for k in [0, 1, 999, 1001, result.stamp_ns.size - 1]:
        t = int(result.stamp_ns[k])
        header = {"stamp": time(t), "frame_id": ""}
        assert bytes(js.payload[k]) == encoder("sensor_msgs/msg/JointState")(
            {
                "header": header,
                "name": names,
                "position": result.q[k].tolist(),
                "velocity": result.qd[k].tolist(),
                "effort": result.tau_nm[k].tolist(),
            }
        )
        reference = point(
            t,
            positions=result.q_ref[k],
            velocities=result.qd_ref[k],
            accelerations=result.qdd_ref[k],
        )
        feedback = point(t, positions=result.q[k], velocities=result.qd[k])
        state = {
            "header": header,
            "joint_names": names,
            "reference": reference,
            "feedback": feedback,
            "error": point(
                t,
                positions=result.q_ref[k] - result.q[k],
                velocities=result.qd_ref[k] - result.qd[k],
            ),
            "output": point(t, effort=result.tau_cmd_nm[k]),
            "multi_dof_joint_names": [],
            **{f"multi_dof_{p}": empty_multi for p in multi},
        }
        if distro == "humble":
            state |= {"desired": reference, "actual": feedback}
        else:
            state |= {"speed_scaling_factor": 1.0}
        assert bytes(cs.payload[k]) == encoder(TYPE_CONTROLLER_STATE)(state)
        if t not in tf_row:
            continue
        transforms_msg = [
            {
                "header": {"stamp": time(t), "frame_id": parent},
                "child_frame_id": child,
                "transform": {
                    "translation": dict(zip("xyz", translation[k, e].tolist(), strict=True)),
                    "rotation": dict(zip("xyzw", rotation[k, e].tolist(), strict=True)),
                },
            }
            for e, (parent, child) in enumerate(frames)
        ]
        assert bytes(tf.payload[tf_row[t]]) == encoder("tf2_msgs/msg/TFMessage")(
            {"transforms": transforms_msg}
        )

    tfs_ns = np.round(planned.times_s * 1e9).astype(np.int64)
    t0 = int(result.stamp_ns[0])
    trajectory = encoder("trajectory_msgs/msg/JointTrajectory")(
        {
            "header": {"stamp": time(t0), "frame_id": ""},
            "joint_names": names,
            "points": [
                point(
                    int(tfs_ns[k]),
                    positions=planned.positions[k],
                    velocities=planned.velocities[k],
                    accelerations=planned.accelerations[k],
                )
                for k in range(tfs_ns.size)
            ],
        }
    )
    assert bytes(blocks[TOPIC_PLANNED_TRAJECTORY].payload[0]) == trajectory
    urdf = build_urdf(ur5)
    string = encoder("std_msgs/msg/String")({"data": urdf})
    assert bytes(blocks[TOPIC_ROBOT_DESCRIPTION].payload[0]) == string


def test_mcap_file_is_ros2_profile_with_embedded_schemas(written: bag.BagSummary) -> None:
    with open(written.mcap_path, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
    assert summary is not None
    assert header.profile == "ros2"
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
        assert schema.data.decode() == full_definition(schema.name)
        assert channel.metadata["topic_type_hash"] == TYPE_HASHES["jazzy"][schema.name]
        assert yaml.safe_load(channel.metadata["offered_qos_profiles"])[0]["reliability"] == 1


def test_metadata_yaml_counts_and_times_match_the_mcap_file(written: bag.BagSummary) -> None:
    info = yaml.safe_load((written.path / "metadata.yaml").read_text())[
        "rosbag2_bagfile_information"
    ]
    counts: dict[str, int] = defaultdict(int)
    times = []
    with open(written.mcap_path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            counts[channel.topic] += 1
            times.append(message.log_time)
    assert info["version"] == 8 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == [written.mcap_path.name]
    assert info["message_count"] == len(times) == sum(written.message_counts.values())
    assert info["starting_time"]["nanoseconds_since_epoch"] == min(times) == written.start_ns
    assert info["duration"]["nanoseconds"] == max(times) - min(times) == written.duration_ns
    recorded = {
        t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]
    }
    assert recorded == dict(counts) == dict(written.message_counts)
    [file_info] = info["files"]
    assert file_info["path"] == written.mcap_path.name
    assert file_info["message_count"] == len(times)
    assert file_info["duration"] == info["duration"]
    assert info["custom_data"] == episode_metadata()
    assert info["compression_mode"] == info["compression_format"] == ""
    for topic in info["topics_with_message_count"]:
        meta = topic["topic_metadata"]
        assert meta["serialization_format"] == "cdr"
        assert isinstance(meta["offered_qos_profiles"], str)  # version <= 8: a YAML string
        durability = yaml.safe_load(meta["offered_qos_profiles"])[0]["durability"]
        latched = meta["name"] in (TOPIC_ROBOT_DESCRIPTION, TOPIC_PLANNED_TRAJECTORY)
        assert durability == (1 if latched else 2)
    assert written.size_bytes == sum(p.stat().st_size for p in written.path.iterdir())


def test_every_crc_validates_and_chunks_stay_small(written: bag.BagSummary) -> None:
    data = written.mcap_path.read_bytes()
    # Breaking chunks up, StreamReader checks every chunk CRC and the data-section CRC.
    records = list(StreamReader(io.BytesIO(data), validate_crcs=True).records)
    assert sum(isinstance(r, Message) for r in records) == sum(written.message_counts.values())
    chunks = [r for r in StreamReader(io.BytesIO(data), emit_chunks=True).records]
    chunks = [r for r in chunks if isinstance(r, Chunk)]
    assert len(chunks) > 2 and all(c.uncompressed_crc != 0 for c in chunks)
    assert max(c.uncompressed_size for c in chunks) < bag.CHUNK_BYTES + 8192
    assert {c.compression for c in chunks} == {"zstd"}
    with open(written.mcap_path, "rb") as f:
        assert sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages()) == sum(
            written.message_counts.values()
        )
    # Summary CRC: summary section up to and including the footer's summary_offset_start.
    [footer] = [r for r in records if isinstance(r, Footer)]
    footer_at = len(data) - 8 - (1 + 8 + 20)
    assert struct.unpack_from("<BQ", data, footer_at) == (2, 20)
    assert footer.summary_crc == zlib.crc32(data[footer.summary_start : footer_at + 1 + 8 + 16])
    # The checks can fail: a wrong chunk CRC, and a flipped byte outside chunks (the episode
    # name inside the metadata record) that only the data-section CRC covers.
    with open(written.mcap_path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    crc_at = summary.chunk_indexes[0].chunk_start_offset + 1 + 8 + 8 + 8 + 8
    bad_chunk = bytearray(data)
    bad_chunk[crc_at] ^= 0x01
    with pytest.raises(CRCValidationError):
        list(StreamReader(io.BytesIO(bytes(bad_chunk)), validate_crcs=True).records)
    bad_data = bytearray(data)
    name_at = data.index(b"ctc_paper")
    bad_data[name_at] = ord("C")
    with pytest.raises(CRCValidationError):
        list(StreamReader(io.BytesIO(bytes(bad_data)), validate_crcs=True).records)


def test_episode_metadata_record_round_trips(written: bag.BagSummary) -> None:
    with open(written.mcap_path, "rb") as f:
        records = list(make_reader(f).iter_metadata())
    assert [(r.name, r.metadata) for r in records] == [(METADATA_EPISODE, episode_metadata())]


def test_same_inputs_write_identical_bytes(
    ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples], tmp_path: Path
) -> None:
    result, planned = episode
    dirs = [tmp_path / "a" / "ep", tmp_path / "b" / "ep"]
    for d in dirs:
        bag.write_episode_bag(
            d, spec=ur5, result=result, planned=planned, metadata=episode_metadata()
        )
    for name in ("ep_0.mcap", "metadata.yaml"):
        assert (dirs[0] / name).read_bytes() == (dirs[1] / name).read_bytes()


@pytest.mark.parametrize(
    ("decimation", "tf_rate_hz", "expected_js", "expected_tf"),
    [
        (1, 50.0, 1500, 75),  # 1.499 s: ticks at 0, 20, ..., 1480 ms
        (4, 10.0, 375, 15),
        (7, 33.0, 215, 50),  # period 30.303 ms: ticks land between control steps
        (1, 5000.0, 1500, 1500),  # faster than control: every step, once
    ],
)
def test_decimation_and_tf_rate_give_expected_counts(
    ur5: RobotSpec,
    episode: tuple[EpisodeResult, TrajectorySamples],
    decimation: int,
    tf_rate_hz: float,
    expected_js: int,
    expected_tf: int,
) -> None:
    result, planned = episode
    blocks = {
        b.topic: b
        for b in bag.encode_episode(
            ur5, result, planned, joint_state_decimation=decimation, tf_rate_hz=tf_rate_hz
        )
    }
    assert (
        blocks[TOPIC_JOINT_STATES].log_time_ns.size == expected_js == math.ceil(1500 / decimation)
    )
    tf_times = blocks[TOPIC_TF].log_time_ns
    assert tf_times.size == expected_tf
    assert blocks[TOPIC_CONTROLLER_STATE].log_time_ns.size == 1500
    # Each /tf message is the first control step at or after its clock tick.
    if tf_rate_hz < 1000:
        ticks = np.arange(expected_tf) * (1e9 / tf_rate_hz)
        assert np.all(tf_times >= np.round(ticks) - 1) and np.all(tf_times - ticks < DT_NS)


def test_writer_refuses_to_overwrite_existing_bag(
    ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples], tmp_path: Path
) -> None:
    result, planned = episode
    target = tmp_path / "ep"
    bag.write_episode_bag(
        target, spec=ur5, result=result, planned=planned, metadata=episode_metadata()
    )
    before = {p.name: p.read_bytes() for p in target.iterdir()}
    other, other_plan = analytic_episode(ur5, phase=0.5)
    with pytest.raises(RecordingError, match=r"ep: recording already exists; use --force"):
        bag.write_episode_bag(
            target, spec=ur5, result=other, planned=other_plan, metadata=episode_metadata()
        )
    assert {p.name: p.read_bytes() for p in target.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ep"]


@pytest.mark.parametrize("atomic_exchange", [True, False])
def test_force_replaces_existing_bag(
    ur5: RobotSpec,
    episode: tuple[EpisodeResult, TrajectorySamples],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    atomic_exchange: bool,
) -> None:
    if not atomic_exchange:  # the two-rename fallback for file systems without renameat2
        monkeypatch.setattr(rosbag2, "_renameat2", lambda src, dst, flags: False)
    result, planned = episode
    target = tmp_path / "ep"
    bag.write_episode_bag(
        target, spec=ur5, result=result, planned=planned, metadata=episode_metadata()
    )
    other, other_plan = analytic_episode(ur5, n_steps=300, phase=0.5)
    summary = bag.write_episode_bag(
        target,
        spec=ur5,
        result=other,
        planned=other_plan,
        metadata=episode_metadata(controller="pid"),
        force=True,
    )
    assert summary.message_counts[TOPIC_CONTROLLER_STATE] == 300
    with open(target / "ep_0.mcap", "rb") as f:
        [record] = make_reader(f).iter_metadata()
    assert record.metadata["controller"] == "pid"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ep"]  # no temp or old copies


def test_stale_partial_directories_of_dead_writers_are_removed(
    ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples], tmp_path: Path
) -> None:
    result, planned = episode
    stale = tmp_path / ".ep.partial-999999999"  # above any pid_max: a dead process
    stale.mkdir()
    (stale / "ep_0.mcap").write_bytes(b"\x89MCAP0\r\n")
    other = tmp_path / ".other.partial-999999999"
    other.mkdir()
    bag.write_episode_bag(
        tmp_path / "ep", spec=ur5, result=result, planned=planned, metadata=episode_metadata()
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.partial-999999999", "ep"]


def test_episode_without_samples_still_records_description_and_plan(
    ur5: RobotSpec, episode: tuple[EpisodeResult, TrajectorySamples], tmp_path: Path
) -> None:
    _, planned = episode
    empty, _ = analytic_episode(ur5, n_steps=0)
    summary = bag.write_episode_bag(
        tmp_path / "ep", spec=ur5, result=empty, planned=planned, metadata=episode_metadata()
    )
    # the latched topics' one message each, no message of the others
    assert summary.message_counts == {t.name: int(t.qos == QOS_LATCHED) for t in TOPICS}
    assert {t.name for t in TOPICS if t.qos == QOS_LATCHED} == {
        TOPIC_ROBOT_DESCRIPTION,
        TOPIC_PLANNED_TRAJECTORY,
    }
    with AnyReader([summary.path]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == summary.message_counts
        assert sum(1 for _ in reader.messages()) == 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"metadata": {"episode": "x"}}, r"metadata: missing \['scenario'"),
        ({"metadata": {**episode_metadata(), "settings": "{"}}, r"metadata\['settings'\]"),
        ({"metadata": {**episode_metadata(), "seed": 7}}, r"must be strings"),
        ({"joint_state_decimation": 0}, r"joint_state_decimation: 0"),
        ({"tf_rate_hz": 0.0}, r"tf_rate_hz: 0.0"),
        ({"tf_rate_hz": float("nan")}, r"tf_rate_hz: nan"),
        ({"result_field": ("q", np.zeros((3, 6)))}, r"result.q: shape \(3, 6\)"),
        ({"result_field": ("joint_names", ("a",) * 6)}, r"result.joint_names"),
        ({"result_field": ("stamp_ns", np.zeros(1500, np.int64))}, r"strictly increasing"),
        ({"planned_field": ("positions", np.zeros((2, 6)))}, r"planned.positions: shape"),
    ],
)
def test_bad_inputs_raise_recording_error_and_write_nothing(
    ur5: RobotSpec,
    episode: tuple[EpisodeResult, TrajectorySamples],
    tmp_path: Path,
    change: dict[str, Any],
    message: str,
) -> None:
    import dataclasses

    result, planned = episode
    kwargs: dict[str, Any] = {"metadata": episode_metadata()}
    for key, value in change.items():
        if key == "result_field":
            result = dataclasses.replace(result, **{value[0]: value[1]})
        elif key == "planned_field":
            planned = dataclasses.replace(planned, **{value[0]: value[1]})
        else:
            kwargs[key] = value
    with pytest.raises(RecordingError, match=message):
        bag.write_episode_bag(tmp_path / "ep", spec=ur5, result=result, planned=planned, **kwargs)
    assert list(tmp_path.iterdir()) == []


def test_metadata_custom_data_written_as_json_strings_reads_back_as_pyyaml_writes_it():
    """The fast path (JSON strings as YAML double-quoted scalars) and PyYAML's own
    emitter give the same document for awkward printable-ASCII values."""
    import yaml

    from pipeline.log import rosbag2

    values = {
        "settings": json.dumps({"a": [1, 2.5e-3, None], "b": "x: y # z", "c": "'\"\\"}),
        "quote'd": 'it\'s "quoted" \\ back\\slash',
        "empty": "",
        "spaces": "  lead and trail  ",
        "yaml-ish": "- [not, a, list]: {no}",
        "number": "0123",
        "bool": "yes",
    }
    topic = rosbag2.TopicInfo("/t", "std_msgs/msg/String", "- history: 1", "RIHS01_00", 3)
    args = {"topics": [topic], "start_ns": 5, "end_ns": 9, "ros_distro": "jazzy"}
    fast = rosbag2.metadata_yaml("x.mcap", custom_data=values, **args)
    assert '"quote\'d": "it\'s \\"quoted\\" \\\\ back\\\\slash"' in fast  # the fast path ran
    assert yaml.safe_load(fast)["rosbag2_bagfile_information"]["custom_data"] == values
    # non-ASCII takes PyYAML's path; both parse to what was given
    slow = rosbag2.metadata_yaml("x.mcap", custom_data={**values, "ü": "naïve"}, **args)
    info = yaml.safe_load(slow)["rosbag2_bagfile_information"]
    assert info["custom_data"] == {**values, "ü": "naïve"}
    fast_info = yaml.safe_load(fast)["rosbag2_bagfile_information"]
    assert {k: v for k, v in info.items() if k != "custom_data"} == {
        k: v for k, v in fast_info.items() if k != "custom_data"
    }
    assert list(fast_info)[-2:] == ["custom_data", "ros_distro"]
