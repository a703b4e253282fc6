"""The generic path (messages of differing shapes, walked all at once) equals a per-message
independent decoder (rosbags), including a second publisher's joint list on the same topic."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_typestore

from pipeline.log import cdr
from pipeline.log.collect import WANT
from pipeline.log.decode import TopicDecoder
from pipeline.log.mcap import MESSAGE_PREFIX, RECORD_HEADER
from pipeline.log.schemas import message_types

JS = "sensor_msgs/msg/JointState"


def records(payloads: list[bytes]) -> tuple[bytes, np.ndarray]:
    parts, starts, pos = [], [], 0
    for k, data in enumerate(payloads):
        head = (5).to_bytes(1, "little") + (MESSAGE_PREFIX + len(data)).to_bytes(8, "little")
        head += (1).to_bytes(2, "little") + k.to_bytes(4, "little") + bytes(16)
        parts += [head, data]
        starts.append(pos + RECORD_HEADER)
        pos += len(head) + len(data)
    return b"".join(parts), np.array(starts, dtype=np.int64)


def test_messages_of_every_shape_decode_like_rosbags(tmp_path: Path) -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    T = store.types
    rng = np.random.default_rng(3)
    msgs, payloads = [], []
    for k in range(3000):
        arm = k % 7 != 0
        names = ["b", "a", "c"] if arm else ["gripper"]
        n = len(names)
        msg = T[JS](
            header=T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=k, nanosec=k * 1000),
                frame_id="f" * int(rng.integers(0, 12)),
            ),
            name=names,
            position=rng.normal(size=n),
            velocity=rng.normal(size=n) if k % 3 else np.zeros(0),  # sometimes absent
            effort=rng.normal(size=n),
        )
        msgs.append(msg)
        payloads.append(bytes(store.serialize_cdr(msg, JS)))
    buf, starts = records(payloads)
    dec = TopicDecoder("/joint_states", JS, message_types(JS), WANT[JS])
    dec.add(buf, starts)
    by_names = {g.names: g for g in dec.groups}
    assert set(by_names) == {("b", "a", "c"), ("gripper",)}
    for names, group in by_names.items():
        stamps, arrays = group.concat()
        expected = [m for m in msgs if tuple(m.name) == names]
        assert stamps.tolist() == [
            m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in expected
        ]
        for key in ("position", "velocity", "effort"):
            for row, m in zip(arrays[key], expected, strict=True):
                values = getattr(m, key)
                if values.size:
                    np.testing.assert_array_equal(row, values)
                else:
                    assert np.isnan(row).all()


def test_walk_many_equals_walk_message_by_message() -> None:
    types = message_types("tf2_msgs/msg/TFMessage")
    rng = np.random.default_rng(1)
    payloads = []
    for _ in range(50):
        value = {
            "transforms": [
                {"header": {"frame_id": "p" * int(rng.integers(0, 5))}, "child_frame_id": "c"}
                for _ in range(int(rng.integers(0, 4)))
            ]
        }
        payloads.append(cdr.encode(types, "tf2_msgs/msg/TFMessage", value)[0])
    buf = b"".join(payloads)
    sizes = np.array([len(p) for p in payloads])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    many = cdr.walk_many(
        types, "tf2_msgs/msg/TFMessage", np.frombuffer(buf, np.uint8), starts, sizes
    )
    for i, data in enumerate(payloads):
        one = cdr.walk(types, "tf2_msgs/msg/TFMessage", data)
        for path, (off, dtype, count) in one.leaves.items():
            m_off, m_dtype, m_count = many.leaves[path]
            assert (m_off[i] - starts[i], m_dtype, m_count[i]) == (off, dtype, count), path
