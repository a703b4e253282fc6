"""Bags we did not write: rosbags' Writer (an independent implementation) with its Humble and
Jazzy type stores, MCAP and sqlite3 storage, other topic names, extra joints, several
publishers, no armlab metadata. Metrics are checked against the signals written into them.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from pipeline.errors import RecordingError
from pipeline.log.reader import ReadOptions, read_recording
from pipeline.stages.report import run_report
from tests.log.rosbags_msgs import EMPTY, RosMsgs

DATA = Path(__file__).parent / "data" / "control_msgs"
JOINTS = ("shoulder", "elbow", "wrist")
RATE_HZ = 500
N = 1000  # 2 s
WALL_T0_NS = 1_700_000_000_123_456_789  # wall-clock stamps, as a real robot's bag has


def signals(t0_ns: int = WALL_T0_NS) -> dict[str, np.ndarray]:
    """Known reference, error and effort per joint (N, 3), from ``t0_ns``."""
    t = (np.arange(N)[:, None] / RATE_HZ) + (t0_ns - WALL_T0_NS) * 1e-9
    k = np.arange(3)[None, :]
    ref = 0.5 * np.sin(2.0 * t + k)
    err = (1.0 + k) * 1e-3 * np.sin(9.0 * t)  # max |e| = 1e-3, 2e-3, 3e-3
    return {
        "t_ns": t0_ns + (np.arange(N) * (1e9 / RATE_HZ)).astype(np.int64),
        "ref": ref,
        "err": err,
        "q": ref - err,
        "effort": 5.0 * np.cos(t + k),
    }


def write_external_bag(
    path: Path,
    *,
    distro: str,
    storage: StoragePlugin,
    cs_topic: str = "/arm_controller/controller_state",
    extra_cs_topic: str | None = None,
    with_gripper: bool = True,
    drop_definitions: bool = False,
    t0_ns: int = WALL_T0_NS,
    joints: tuple[str, str, str] = JOINTS,
    robot_name: str = "my_arm",
    urdf_effort_nm: tuple[float, float, float] = (40.0, 50.0, 60.0),
    js_offset_ns: int = 0,
    js_every: int = 1,
    cs_flip_at: int | None = None,
    urdf: str | None = None,
) -> dict[str, np.ndarray]:
    """A Humble or Jazzy robot's bag: JTC state + joint_states (arm+gripper in shuffled order,
    plus a gripper-only publisher at a lower rate) + a URDF. ``js_offset_ns`` stamps the
    joint states that much after the controller state they go with; ``js_every``: joint
    states every k-th control step only; ``cs_flip_at``: the controller state lists its
    joints in reverse order from that message on."""
    m = RosMsgs(distro)
    store = m.store
    s = signals(t0_ns)
    JS, CS, Str = (
        m.type("sensor_msgs/msg/JointState"),
        m.type("control_msgs/msg/JointTrajectoryControllerState"),
        m.type("std_msgs/msg/String"),
    )
    urdf = urdf or (
        f'<robot name="{robot_name}">'
        + "".join(
            f'<joint name="{j}" type="revolute"><limit effort="{e:g}" velocity="3" '
            'lower="-3" upper="3"/></joint>'
            for j, e in zip(joints, urdf_effort_nm, strict=True)
        )
        + "</robot>"
    )
    js_order = (
        (joints[2], "gripper", joints[0], joints[1]) if with_gripper else (joints[2], *joints[:2])
    )
    with Writer(path, version=9 if distro == "jazzy" else 8, storage_plugin=storage) as w:
        c_cs = w.add_connection(cs_topic, CS.__msgtype__, typestore=store)
        c_js = w.add_connection("/joint_states", JS.__msgtype__, typestore=store)
        c_rd = w.add_connection("/robot_description", Str.__msgtype__, typestore=store)
        c_x = (
            w.add_connection(extra_cs_topic, CS.__msgtype__, typestore=store)
            if extra_cs_topic
            else None
        )
        w.write(c_rd, int(s["t_ns"][0]), store.serialize_cdr(Str(data=urdf), Str.__msgtype__))
        for k in range(N):
            ns = int(s["t_ns"][k])
            ref, q, err, eff_k = s["ref"][k], s["q"][k], s["err"][k], s["effort"][k]
            cs_joints = list(joints)
            if cs_flip_at is not None and k >= cs_flip_at:
                ref, q, err, eff_k = (np.ascontiguousarray(a[::-1]) for a in (ref, q, err, eff_k))
                cs_joints.reverse()
            msg = m.controller_state(
                ns=ns,
                joints=cs_joints,
                reference=m.point(ref),
                feedback=m.point(q),
                error=m.point(err),
                output=m.point(eff=eff_k),
            )
            w.write(c_cs, ns, store.serialize_cdr(msg, CS.__msgtype__))
            if c_x is not None:
                w.write(c_x, ns, store.serialize_cdr(msg, CS.__msgtype__))
            q = s["q"][k]
            pos = np.array([0.01 if j == "gripper" else q[joints.index(j)] for j in js_order])
            eff = np.array(
                [0.0 if j == "gripper" else s["effort"][k][joints.index(j)] for j in js_order]
            )
            js = m.joint_state(
                ns=ns + js_offset_ns,
                names=list(js_order),
                position=pos,
                velocity=pos * 0,
                effort=eff,
            )
            if k % js_every == 0:
                w.write(c_js, ns + js_offset_ns, store.serialize_cdr(js, JS.__msgtype__))
            if with_gripper and k % 5 == 0:  # a gripper driver publishing its own joint at 100 Hz
                g = m.joint_state(
                    ns=ns + 1000, names=["gripper"], position=np.array([0.02]), velocity=EMPTY,
                    effort=EMPTY,
                )  # fmt: skip
                w.write(c_js, ns + 1000, store.serialize_cdr(g, JS.__msgtype__))
    if drop_definitions:  # Humble's sqlite3 files carry no message definitions
        [db] = path.glob("*.db3")
        with sqlite3.connect(db) as con:
            con.execute("DROP TABLE message_definitions")
    return s


CASES = [
    ("humble", StoragePlugin.MCAP, False),
    ("jazzy", StoragePlugin.MCAP, False),
    ("humble", StoragePlugin.SQLITE3, True),
    ("jazzy", StoragePlugin.SQLITE3, False),
]


@pytest.mark.parametrize(("distro", "storage", "drop"), CASES, ids=lambda c: str(c))
def test_a_robots_bag_reads_with_its_known_signals(
    tmp_path: Path, distro: str, storage: StoragePlugin, drop: bool
) -> None:
    path = tmp_path / "my_robot_run"
    s = write_external_bag(path, distro=distro, storage=storage, drop_definitions=drop)
    rec = read_recording(path, ReadOptions(controller="jtc", scenario="pick"))
    assert rec.joint_names == JOINTS  # the controller's joints, picked by name
    assert (rec.controller, rec.scenario, rec.robot) == ("jtc", "pick", "my_arm")
    assert any("not recorded by armlab" in n for n in rec.notes)
    assert rec.samples["stamp_ns"].n_unique() == N  # the gripper-only messages left out
    for j, joint in enumerate(JOINTS):
        rows = rec.samples.filter(rec.samples["joint"] == joint).sort("stamp_ns")
        assert np.array_equal(rows["stamp_ns"].to_numpy(), s["t_ns"])
        np.testing.assert_array_equal(rows["position_rad"].to_numpy(), s["q"][:, j])
        np.testing.assert_array_equal(rows["reference_position_rad"].to_numpy(), s["ref"][:, j])
        np.testing.assert_array_equal(rows["error_rad"].to_numpy(), s["err"][:, j])
        np.testing.assert_array_equal(rows["effort_nm"].to_numpy(), s["effort"][:, j])


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_pipeline_report_on_a_robots_bag_finds_the_known_errors(
    tmp_path: Path, distro: str
) -> None:
    bags = tmp_path / "bags"
    s = write_external_bag(bags / "run1", distro=distro, storage=StoragePlugin.MCAP)
    result = run_report(
        recordings_dir=bags,
        out_dir=tmp_path / "out",
        baseline="jtc",
        options=ReadOptions(controller="jtc", scenario="pick"),
    )
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    text = json.dumps(metrics)
    assert "my_arm" in text and "jtc" in text
    rows = result.summary.to_dicts()
    assert len(rows) == 1 and rows[0]["controller"] == "jtc"
    # worst joint: max |e| of wrist = 3e-3 rad, exactly as written
    assert rows[0]["worst_max_abs_error"] == pytest.approx(np.abs(s["err"]).max(), rel=1e-12)


def test_several_controller_states_need_a_remap(tmp_path: Path) -> None:
    path = tmp_path / "two"
    write_external_bag(
        path, distro="jazzy", storage=StoragePlugin.MCAP, extra_cs_topic="/other/controller_state"
    )
    with pytest.raises(RecordingError, match="--topic controller_state=/name") as err:
        read_recording(path)
    assert "/arm_controller/controller_state" in str(err.value)
    rec = read_recording(path, ReadOptions(topics={"controller_state": "/other/controller_state"}))
    assert rec.joint_names == JOINTS
    with pytest.raises(RecordingError, match="no such topic"):
        read_recording(path, ReadOptions(topics={"controller_state": "/nope"}))


def test_a_split_bag_reads_file_after_file(tmp_path: Path) -> None:
    s1 = write_external_bag(tmp_path / "a", distro="jazzy", storage=StoragePlugin.MCAP)
    t1 = WALL_T0_NS + N * 2_000_000  # the second file continues where the first ends
    s2 = write_external_bag(tmp_path / "b", distro="jazzy", storage=StoragePlugin.MCAP, t0_ns=t1)
    split = tmp_path / "split"
    split.mkdir()
    for k, part in enumerate("ab"):
        [f] = (tmp_path / part).glob("*.mcap")
        f.rename(split / f"split_{k}.mcap")
    (split / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  relative_file_paths: [split_0.mcap, split_1.mcap]\n"
    )
    rec = read_recording(split)
    wrist = rec.samples.filter(rec.samples["joint"] == "wrist").sort("stamp_ns")
    assert np.array_equal(wrist["stamp_ns"].to_numpy(), np.concatenate([s1["t_ns"], s2["t_ns"]]))
    expected = np.concatenate([s1["err"][:, 2], s2["err"][:, 2]])
    np.testing.assert_array_equal(wrist["error_rad"].to_numpy(), expected)
