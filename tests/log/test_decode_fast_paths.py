"""The decoder's fast paths against the slow general ones they replace, on bytes written by
our encoder and by rosbags (an independent writer), including shapes that must fall back:

- ``cdr.walk`` reuses one element's layout for a run of same-shaped array elements
  (``repeat=True``) -- equal to walking every element (``repeat=False``);
- the planned trajectory is gathered per field at once -- equal to reading it point by point
  and to rosbags' own decoding;
- ``Group.same_shape`` compares 4-byte words -- equal to comparing the check bytes one by one;
- ``walk_many`` skips alignments it knows hold and checks bounds before each length read and
  at the end -- equal to walking message by message, and refusing the same truncated messages.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from pipeline.log import cdr
from pipeline.log.decode import Group
from pipeline.log.msgdef import MsgTypes, parse_msgdef
from pipeline.log.reader import read_recording
from pipeline.log.schemas import message_types
from tests.log.rosbags_msgs import RosMsgs, store_for
from tests.log.test_external_bags import JOINTS

JT = "trajectory_msgs/msg/JointTrajectory"
TF = "tf2_msgs/msg/TFMessage"
JAZZY = get_typestore(Stores.ROS2_JAZZY)

# Elements whose size is not a multiple of their alignment (Odd: 1 + 7 pad + 8 + 2 = 18 bytes
# from an 8-aligned start, 16 from a 4-aligned one), 4-byte-only ones (Vec3f: 12 bytes), and
# sequences that are sometimes empty: the shift of a run must respect all of them.
MIXED = "test_msgs/msg/Mixed"
MIXED_TEXT = "\n".join(
    [
        "uint8 flag",
        "Odd[] odds",
        "Vec3f[] vecs",
        "string label",
        "Item[] items",
        "uint16 tag",
        "=" * 80,
        "MSG: test_msgs/Odd",
        "uint8 a",
        "float64 b",
        "uint16 c",
        "=" * 80,
        "MSG: test_msgs/Vec3f",
        "float32 x",
        "float32 y",
        "float32 z",
        "=" * 80,
        "MSG: test_msgs/Item",
        "bool on",
        "float64[] values",
        "string name",
        "int32 k",
    ]
)


def mixed_types() -> MsgTypes:
    return parse_msgdef(MIXED, MIXED_TEXT)


def mixed_value(rng: np.random.Generator, n: int) -> dict[str, Any]:
    """A Mixed message whose array elements come in runs of equal shape, then differ."""
    same_items = int(rng.integers(0, n + 1))
    return {
        "flag": int(rng.integers(0, 255)),
        "odds": [
            {"a": int(rng.integers(0, 255)), "b": float(rng.normal()), "c": 7} for _ in range(n)
        ],
        "vecs": [{"x": 1.5, "y": float(rng.normal()), "z": -2.0} for _ in range(n)],
        "label": "l" * int(rng.integers(0, 6)),
        "items": [
            {
                "on": k % 2 == 0,
                "values": rng.normal(size=3 if k < same_items else int(rng.integers(0, 4))),
                "name": "joint" if k < same_items else "j" * int(rng.integers(0, 9)),
                "k": k,
            }
            for k in range(n)
        ],
        "tag": 513,
    }


def trajectory(rng: np.random.Generator, store: Typestore | None = None) -> Any:
    """A JointTrajectory (a mapping, or a rosbags message if ``store``) whose points mostly
    have 3 positions and velocities, with runs broken by points of other shapes."""
    points = []
    for k in range(40):
        n_pos = 3 if k not in (11, 30) else 2
        n_vel = 0 if k in (5, 6, 25) else 3
        n_acc = 3 if 15 <= k < 22 else 0
        points.append(
            {
                "positions": rng.normal(size=n_pos),
                "velocities": rng.normal(size=n_vel),
                "accelerations": rng.normal(size=n_acc),
                "effort": np.zeros(0),
                "time_from_start": {"sec": k // 10, "nanosec": (k % 10) * 100_000_000},
            }
        )
    value = {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "base"},
        "joint_names": list(JOINTS),
        "points": points,
    }
    if store is None:
        return value
    T = store.types
    return T[JT](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="base"
        ),
        joint_names=list(JOINTS),
        points=[
            T["trajectory_msgs/msg/JointTrajectoryPoint"](
                positions=p["positions"],
                velocities=p["velocities"],
                accelerations=p["accelerations"],
                effort=p["effort"],
                time_from_start=T["builtin_interfaces/msg/Duration"](**p["time_from_start"]),
            )
            for p in points
        ],
    )


def tf_value(rng: np.random.Generator) -> dict[str, Any]:
    return {
        "transforms": [
            {
                "header": {"frame_id": "world" if k % 9 else "w" * int(rng.integers(0, 7))},
                "child_frame_id": "tool" if k < 20 else "flange",
                "transform": {"translation": {"x": float(k)}, "rotation": {"w": 1.0}},
            }
            for k in range(30)
        ]
    }


def samples() -> list[tuple[str, MsgTypes, str, bytes]]:
    rng = np.random.default_rng(7)
    jt, tf, mixed = message_types(JT), message_types(TF), mixed_types()
    out = [
        ("JointTrajectory, our encoder", jt, JT, cdr.encode(jt, JT, trajectory(rng))[0]),
        (
            "JointTrajectory, rosbags",
            jt,
            JT,
            bytes(JAZZY.serialize_cdr(trajectory(rng, JAZZY), JT)),
        ),
        ("TFMessage, our encoder", tf, TF, cdr.encode(tf, TF, tf_value(rng))[0]),
    ]
    for n in (9, 12, 20):
        out.append((f"Mixed x{n}", mixed, MIXED, cdr.encode(mixed, MIXED, mixed_value(rng, n))[0]))
    return out


SAMPLES = samples()


@pytest.mark.parametrize(("label", "types", "root", "data"), SAMPLES, ids=[s[0] for s in SAMPLES])
def test_walk_reusing_element_layouts_equals_walking_each(
    label: str, types: MsgTypes, root: str, data: bytes, monkeypatch: pytest.MonkeyPatch
) -> None:
    reused: list[int] = []
    repeats = cdr._repeats

    def counting(*args: Any) -> int:
        reused.append(repeats(*args))
        return reused[-1]

    monkeypatch.setattr(cdr, "_repeats", counting)
    fast = cdr.walk(types, root, data)
    slow = cdr.walk(types, root, data, repeat=False)
    assert fast == slow
    assert sum(reused) > 4  # the fast path was taken...
    assert len(reused) > 1  # ...and a run was broken by an element of another shape


@pytest.mark.parametrize(("label", "types", "root", "data"), SAMPLES, ids=[s[0] for s in SAMPLES])
def test_walk_fast_path_refuses_the_same_truncated_messages(
    label: str, types: MsgTypes, root: str, data: bytes
) -> None:
    for cut in range(4, len(data), max(1, len(data) // 97)):
        part = data[:cut]
        try:
            slow: cdr.Layout | str = cdr.walk(types, root, part, repeat=False)
        except ValueError as err:
            slow = str(err)
        try:
            fast: cdr.Layout | str = cdr.walk(types, root, part)
        except ValueError as err:
            fast = str(err)
        assert fast == slow, cut


def test_rosbags_decodes_the_sampled_trajectory_like_the_fast_walk() -> None:
    """Ground truth from an independent decoder, for the bytes rosbags wrote."""
    _, types, root, data = SAMPLES[1]
    msg = JAZZY.deserialize_cdr(data, JT)
    layout = cdr.walk(types, root, data)
    for k, point in enumerate(msg.points):
        for key in ("positions", "velocities", "accelerations"):
            np.testing.assert_array_equal(
                layout.values(data, f"points[{k}].{key}"), getattr(point, key)
            )


def planned_point_by_point(data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reader's former planned-trajectory decoding: every point walked and read alone."""
    layout = cdr.walk(message_types(JT), JT, data, repeat=False)
    names = layout.texts["joint_names"]
    n = len(names)
    times, pos, vel = [], [], []
    k = 0
    while f"points[{k}].time_from_start.sec" in layout.leaves:
        p = f"points[{k}]."
        sec = float(layout.values(data, p + "time_from_start.sec")[0])
        nsec = float(layout.values(data, p + "time_from_start.nanosec")[0])
        times.append(sec + nsec * 1e-9)
        for out, key in ((pos, "positions"), (vel, "velocities")):
            v = layout.values(data, p + key).astype(float)
            out.append(v if v.size == n else np.full(n, np.nan))
        k += 1
    return np.array(times), np.array(pos).reshape(k, n), np.array(vel).reshape(k, n)


def write_rosbags_bag_with_plan(path: Path) -> bytes:
    """A Jazzy robot's bag written by rosbags: joint states, a controller state and a planned
    trajectory whose points differ in shape. Returns the trajectory's CDR bytes."""
    ros = RosMsgs("jazzy")
    rng = np.random.default_rng(11)
    plan = ros.cdr(trajectory(rng, ros.store))
    cs_type, js_type = (
        "control_msgs/msg/JointTrajectoryControllerState",
        "sensor_msgs/msg/JointState",
    )
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c_plan = w.add_connection("/planned_trajectory", JT, typestore=ros.store)
        c_js = w.add_connection("/joint_states", js_type, typestore=ros.store)
        c_cs = w.add_connection("/controller_state", cs_type, typestore=ros.store)
        w.write(c_plan, 1, plan)
        for k in range(200):
            ns = 1_000_000_000 + k * 2_000_000
            q = np.sin(k * 0.01 + np.arange(3))
            js = ros.joint_state(ns=ns, names=list(JOINTS), position=q, velocity=q, effort=q)
            w.write(c_js, ns, ros.cdr(js))
            pt = ros.point(q, q, q)
            cs = ros.controller_state(
                ns=ns, joints=list(JOINTS), reference=pt, feedback=pt, error=pt, output=pt
            )
            w.write(c_cs, ns, ros.cdr(cs))
    return plan


def test_planned_trajectory_from_a_rosbags_bag_equals_the_point_by_point_decode(
    tmp_path: Path,
) -> None:
    plan = write_rosbags_bag_with_plan(tmp_path / "robot")
    rec = read_recording(tmp_path / "robot")
    assert rec.planned is not None
    times, pos, vel = planned_point_by_point(plan)
    assert rec.planned.joint_names == JOINTS
    np.testing.assert_array_equal(rec.planned.times_s, times)
    np.testing.assert_array_equal(rec.planned.positions, pos)
    np.testing.assert_array_equal(rec.planned.velocities, vel)
    # and against rosbags' decoding: points of another width are NaN rows
    msg = store_for("jazzy").deserialize_cdr(plan, JT)
    for k, point in enumerate(msg.points):
        for got, want in ((pos[k], point.positions), (vel[k], point.velocities)):
            if want.size == len(JOINTS):
                np.testing.assert_array_equal(got, want)
            else:
                assert np.isnan(got).all()
    assert np.isnan(rec.planned.positions).any() and np.isnan(rec.planned.velocities).any()


def test_planned_trajectory_from_our_bag_equals_the_point_by_point_decode(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    from pipeline.log.bag import write_episode_bag
    from pipeline.robots import load_spec
    from tests.log.test_reader_writer import _episode

    result, planned = _episode(300)
    spec = load_spec("ur5")
    meta = {"episode": "e", "scenario": "s", "controller": "pid", "robot": "ur5", "seed": "0",
            "settings": json.dumps({})}  # fmt: skip
    write_episode_bag(tmp_path / "e", spec=spec, result=result, planned=planned, metadata=meta)
    rec = read_recording(tmp_path / "e")
    [path] = (tmp_path / "e").glob("*.mcap")
    with path.open("rb") as fh:
        [(_, _, message)] = list(make_reader(fh).iter_messages(topics=["/planned_trajectory"]))
    times, pos, vel = planned_point_by_point(message.data)
    assert rec.planned is not None and pos.shape[0] == planned.times_s.size > 8
    np.testing.assert_array_equal(rec.planned.times_s, times)
    np.testing.assert_array_equal(rec.planned.positions, pos)
    np.testing.assert_array_equal(rec.planned.velocities, vel)
    np.testing.assert_array_equal(rec.planned.positions, planned.positions)


@pytest.mark.parametrize("size", [316, 318])  # a multiple of 4 (words) and not (bytes)
def test_same_shape_by_words_equals_the_bytewise_check(size: int) -> None:
    rng = np.random.default_rng(5)
    template = rng.integers(0, 256, size, dtype=np.uint8)
    check = ((12, 17), (20, 24), (24, 47), (101, 106), (size - 5, size - 1))
    layout = cdr.Layout(size, {}, {}, check)
    cols = layout.check_cols()
    group = Group(("a",), layout, cols, template[cols].copy())
    rows = np.repeat(template[None, :], 400, axis=0)
    hit = rng.integers(0, size, 400)  # one byte changed per row (some outside the checks)
    rows[np.arange(400), hit] ^= rng.integers(1, 256, 400, dtype=np.uint8)
    expected = (rows[:, cols] == template[cols]).all(axis=1)
    assert 0 < expected.sum() < 400
    np.testing.assert_array_equal(group.same_shape(rows), expected)


def _batch(payloads: list[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Messages one after another at odd offsets (so no alignment comes for free)."""
    parts, starts, pos = [], [], 0
    for k, data in enumerate(payloads):
        gap = bytes(1 + k % 3)
        parts += [gap, data]
        starts.append(pos + len(gap))
        pos += len(gap) + len(data)
    buf = np.frombuffer(b"".join(parts), dtype=np.uint8)
    return buf, np.array(starts, dtype=np.int64), np.array([len(p) for p in payloads])


def test_walk_many_equals_walk_on_mixed_alignments() -> None:
    rng = np.random.default_rng(9)
    types = mixed_types()
    payloads = [cdr.encode(types, MIXED, mixed_value(rng, int(rng.integers(0, 6))))[0]
                for _ in range(60)]  # fmt: skip
    buf, starts, sizes = _batch(payloads)
    many = cdr.walk_many(types, MIXED, buf, starts, sizes)
    for i, data in enumerate(payloads):
        one = cdr.walk(types, MIXED, data)
        for path, (off, dtype, count) in one.leaves.items():
            m_off, m_dtype, m_count = many.leaves[path]
            assert (m_off[i] - starts[i], m_dtype, m_count[i]) == (off, dtype, count), path
        for path, value in one.texts.items():
            a, b = many.regions[path]
            assert bytes(buf[a[i] : b[i]]).count(b"\x00") >= (
                len(value) if isinstance(value, tuple) else 1
            )


def test_walk_many_refuses_a_batch_with_any_truncated_message() -> None:
    rng = np.random.default_rng(10)
    types = mixed_types()
    payloads = [cdr.encode(types, MIXED, mixed_value(rng, 4))[0] for _ in range(8)]
    victim = payloads[5]
    refused = 0
    for cut in range(4, len(victim)):
        part = victim[:cut]
        try:
            cdr.walk(types, MIXED, part)
            fits = True
        except ValueError:
            fits = False
        # in the middle (its bytes run into the next message) and last (off the buffer)
        for batch in ([*payloads[:5], part, *payloads[6:]], [*payloads[:5], part]):
            buf, starts, sizes = _batch(batch)
            if fits:
                cdr.walk_many(types, MIXED, buf, starts, sizes)
            else:
                refused += 1
                with pytest.raises(ValueError):
                    cdr.walk_many(types, MIXED, buf, starts, sizes)
    assert refused > len(victim)
