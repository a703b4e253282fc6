"""Recording-writer speed: our vectorized CDR/MCAP path vs mcap_ros2's generic one, same run.

Prints one JSON object:
- ``encode_us_per_msg``: per message type, our template encoder (all N messages in one call)
  and mcap_ros2's dynamic encoder (one call per message, message dicts built beforehand, so
  only encoding is timed), and their ratio;
- ``mcap_add_message_us``: ``mcap.writer.Writer.add_message`` per message (bytes already
  encoded, same chunk size and zstd) vs our ``write_mcap`` per message;
- ``episode``: a 10 s, 1 kHz, 6-joint UR5 episode with full logging (JointState and controller
  state every step, /tf at 50 Hz, plan, URDF): ``write_episode_bag`` wall time (median of
  repeats, fsync included), its per-control-step cost, the same messages through
  ``mcap_ros2.writer.Writer``, and file sizes.

Usage: python benches/log_encode.py [--repeat 5] [--seconds 10]
"""

from __future__ import annotations

import argparse
import io
import json
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mcap.writer import CompressionType  # noqa: E402
from mcap.writer import Writer as McapWriter  # noqa: E402
from mcap_ros2._dynamic import serialize_dynamic  # noqa: E402
from mcap_ros2.writer import Writer as Ros2Writer  # noqa: E402

from pipeline.constants import (  # noqa: E402
    TOPIC_CONTROLLER_STATE,
    TOPIC_JOINT_STATES,
    TYPE_CONTROLLER_STATE,
    TYPE_JOINT_STATE,
)
from pipeline.log import bag  # noqa: E402
from pipeline.log.mcap import write_mcap  # noqa: E402
from pipeline.log.schemas import full_definition  # noqa: E402
from pipeline.robots import load_spec  # noqa: E402
from pipeline.sim.result import EpisodeResult, TrajectorySamples  # noqa: E402

DT_NS = 1_000_000


def episode(seconds: float) -> tuple[Any, EpisodeResult, TrajectorySamples]:
    spec = load_spec("ur5")
    n_steps = round(seconds * 1e9 / DT_NS)
    st = DT_NS * np.arange(n_steps, dtype=np.int64)
    t = st[:, None] * 1e-9
    w = 0.5 + 0.25 * np.arange(spec.dof)
    q_ref = 0.3 * np.sin(w * t)
    qd_ref = 0.3 * w * np.cos(w * t)
    noise = np.random.default_rng(0).normal(scale=1e-4, size=q_ref.shape)
    tau = 20.0 * np.cos(3 * t + np.arange(spec.dof))
    result = EpisodeResult(
        spec.joint_names, st, q_ref + noise, qd_ref, q_ref, qd_ref, q_ref, qd_ref,
        -0.3 * w**2 * np.sin(w * t), tau, np.clip(tau, -15, 15), np.abs(tau) > 15,
    )  # fmt: skip
    ts = np.linspace(0.0, seconds, round(seconds * 100) + 1)[:, None]
    planned = TrajectorySamples(
        ts[:, 0], 0.3 * np.sin(w * ts), 0.3 * w * np.cos(w * ts), -0.3 * w**2 * np.sin(w * ts)
    )
    return spec, result, planned


def best_s(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def ros_time(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def message_dicts(spec: Any, result: EpisodeResult, rows: range) -> dict[str, list[Any]]:
    """The same messages as plain dicts, the input mcap_ros2's encoder takes."""
    names = list(spec.joint_names)

    def point(t: int, **f: np.ndarray) -> dict[str, Any]:
        seqs = ("positions", "velocities", "accelerations", "effort")
        return {s: f.get(s, np.zeros(0)).tolist() for s in seqs} | {"time_from_start": ros_time(t)}

    multi = {"transforms": [], "velocities": [], "accelerations": [], **point(0)}
    js, cs = [], []
    for k in rows:
        t = int(result.stamp_ns[k])
        header = {"stamp": ros_time(t), "frame_id": ""}
        js.append(
            {
                "header": header,
                "name": names,
                "position": result.q[k].tolist(),
                "velocity": result.qd[k].tolist(),
                "effort": result.tau_nm[k].tolist(),
            }
        )
        cs.append(
            {
                "header": header,
                "joint_names": names,
                "reference": point(
                    t,
                    positions=result.q_ref[k],
                    velocities=result.qd_ref[k],
                    accelerations=result.qdd_ref[k],
                ),
                "feedback": point(t, positions=result.q[k], velocities=result.qd[k]),
                "error": point(
                    t,
                    positions=result.q_ref[k] - result.q[k],
                    velocities=result.qd_ref[k] - result.qd[k],
                ),
                "output": point(t, effort=result.tau_cmd_nm[k]),
                "multi_dof_joint_names": [],
                "speed_scaling_factor": 1.0,
            }
            | {f"multi_dof_{p}": multi for p in ("reference", "feedback", "error", "output")}
        )
    return {"sensor_msgs/msg/JointState": js, "control_msgs/msg/JointTrajectoryControllerState": cs}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()

    spec, result, planned = episode(args.seconds)
    n = result.stamp_ns.size
    st = result.stamp_ns

    # --- per-message encoding: the whole episode's blocks vs mcap_ros2, message by message ---
    def ours_blocks() -> dict[str, Any]:
        return {b.topic: b for b in bag.encode_episode(spec, result, planned)}

    blocks_by_topic = ours_blocks()
    ours_episode_s = best_s(ours_blocks, args.repeat)
    n_generic = min(n, 2000)
    dicts = message_dicts(spec, result, range(n_generic))
    encode: dict[str, Any] = {
        "ours_encode_episode_us_per_msg": round(
            ours_episode_s / sum(b.log_time_ns.size for b in blocks_by_topic.values()) * 1e6, 3
        )
    }
    for topic, type_name in (
        (TOPIC_JOINT_STATES, TYPE_JOINT_STATE),
        (TOPIC_CONTROLLER_STATE, TYPE_CONTROLLER_STATE),
    ):
        enc = serialize_dynamic(type_name, full_definition(type_name))[type_name]
        msgs = dicts[type_name]
        # same bytes, or the comparison is moot
        assert enc(msgs[1]) == bytes(blocks_by_topic[topic].payload[1])
        generic_us = best_s(
            lambda enc=enc, msgs=msgs: [enc(m) for m in msgs], max(1, args.repeat // 2)
        )
        encode[type_name] = {"mcap_ros2_us": round(generic_us / n_generic * 1e6, 2)}

    # --- MCAP record writing: mcap.Writer.add_message vs write_mcap ---
    blocks = bag.encode_episode(spec, result, planned)
    payloads = [(i + 1, b.log_time_ns.tolist(), [r.tobytes() for r in b.payload])
                for i, b in enumerate(blocks)]  # fmt: skip
    total_msgs = sum(len(p[2]) for p in payloads)
    order = sorted(
        (t, ch, data) for ch, times, datas in payloads for t, data in zip(times, datas, strict=True)
    )

    def with_mcap_writer() -> None:
        w = McapWriter(io.BytesIO(), chunk_size=bag.CHUNK_BYTES, compression=CompressionType.ZSTD)
        w.start("ros2", "bench")
        sid = w.register_schema("x", "ros2msg", b"")
        for ch in range(len(payloads)):
            w.register_channel(f"/t{ch}", "cdr", sid)
        for t, ch, data in order:
            w.add_message(ch, t, data, t)
        w.finish()

    meta = {k: "x" for k in bag.REQUIRED_METADATA_KEYS} | {"settings": "{}"}
    mcap_writer_s = best_s(with_mcap_writer, max(1, args.repeat // 2))
    channels = bag.channel_specs("jazzy")
    ours_mcap_s = best_s(
        lambda: write_mcap(io.BytesIO(), channels, blocks, metadata={"armlab.episode": meta}),
        args.repeat,
    )

    # --- whole episode ---
    with tempfile.TemporaryDirectory() as tmp:
        walls, encode_walls = [], []
        # Warm-up: first-call imports (the URDF builder pulls in Pinocchio) and template caches.
        summary = bag.write_episode_bag(
            Path(tmp) / "warmup", spec=spec, result=result, planned=planned, metadata=meta
        )
        for i in range(args.repeat):
            t0 = time.perf_counter()
            bag.encode_episode(spec, result, planned)
            encode_walls.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            summary = bag.write_episode_bag(
                Path(tmp) / f"ep{i}", spec=spec, result=result, planned=planned, metadata=meta
            )
            walls.append(time.perf_counter() - t0)

        def with_ros2_writer() -> None:
            with open(Path(tmp) / "generic.mcap", "wb") as f:
                writer = Ros2Writer(f, chunk_size=bag.CHUNK_BYTES)
                schemas = {
                    t: writer.register_msgdef(t, full_definition(t))
                    for t in ("sensor_msgs/msg/JointState", bag.TOPICS[3].type)
                }
                for k in range(n_generic):
                    t = int(st[k])
                    for topic, type_name in (
                        ("/js", bag.TOPICS[2].type),
                        ("/cs", bag.TOPICS[3].type),
                    ):
                        writer.write_message(topic, schemas[type_name], dicts[type_name][k], t, t)
                writer.finish()

        ros2_writer_s = best_s(with_ros2_writer, 1) / (2 * n_generic) * total_msgs

    wall = statistics.median(walls)
    print(
        json.dumps(
            {
                "bench": "log_encode",
                "python": platform.python_version(),
                "machine": platform.machine(),
                "encode_us_per_msg": encode,
                "mcap_add_message_us": {
                    "mcap_writer_us": round(mcap_writer_s / total_msgs * 1e6, 2),
                    "ours_write_mcap_us": round(ours_mcap_s / total_msgs * 1e6, 2),
                },
                "episode": {
                    "seconds": args.seconds,
                    "control_rate_hz": 1e9 / DT_NS,
                    "joints": spec.dof,
                    "messages": dict(summary.message_counts),
                    "write_episode_bag_s": round(wall, 4),
                    "write_episode_bag_s_min": round(min(walls), 4),
                    "encode_s": round(statistics.median(encode_walls), 4),
                    "us_per_control_step": round(wall / n * 1e6, 2),
                    "us_per_message": round(wall / total_msgs * 1e6, 2),
                    "mcap_ros2_writer_s_estimate": round(ros2_writer_s, 3),
                    "speedup_vs_mcap_ros2_writer": round(ros2_writer_s / wall, 1),
                    "bag_bytes": summary.size_bytes,
                    "uncompressed_payload_bytes": int(sum(b.payload.nbytes for b in blocks)),
                },
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
