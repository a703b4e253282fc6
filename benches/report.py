"""Report-stage speed: recording decode throughput vs rosbags, and whole-report wall time.

Prints one JSON object:
- ``decode``: on one paper-like recording (10 s at 1 kHz, UR5, /joint_states and
  /controller_state every step, /tf at 50 Hz), in one run: our reader from file to the
  Polars sample frame (read, CRC checks, SHA-256, decompression, decoding; best of
  repeats) in messages/s, against rosbags' ``deserialize_cdr`` and mcap_ros2's decoder on
  the same two topics (raw message bytes loaded beforehand, so only their decoding is
  timed), and the ratio to rosbags (target >= 30).
- ``decode_generic``: a bag written by rosbags (Jazzy, MCAP; /joint_states and a
  controller state, 10 s at 1 kHz) where every message has another layout (frame_id
  lengths vary), so our reader takes the generic path for all: our read_recording from
  file vs rosbags' AnyReader + deserialize over the same file (target >= 10).
- ``report_two_episodes_s``: ``run_report`` on two paper-like episodes (PID, CTC; 10 s at
  1 kHz), figures and .rrd included (target <= 10 s).
- ``report_synthetic``: ``run_report`` on 10 and 100 short synthetic episodes (2 s at
  500 Hz, two controllers per scenario), to show the growth, and ``read_s``, the part
  that reads the recordings (figures are drawn for at most 6 scenarios, so they add a
  constant once there are more).
- ``campaign_sweep`` (``--campaign-sweep 100,300,1000``): ``run_report`` on one synthetic
  campaign of N episodes (pid and ctc x 3 payload conditions x N/6 seeds, 1 s at 500 Hz,
  written by tests/analysis/bagfactory.py), each N in a fresh process: wall time, time per
  episode, the reading part, peak RSS, and the sizes of report.md, recording.rrd and all
  outputs (the target: linear time, bounded report.md and .rrd).

The recording is written by the project's writer (pipeline.log.bag) when it is
importable, else by tests/analysis/bagfactory.py (mcap_ros2). ``--recording PATH``
measures the decode on an existing recording instead.

Usage: python benches/report.py [--repeat 5] [--skip-synthetic] [--recording PATH]
       [--campaign-sweep 100,300,1000] [--only-campaign-sweep]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from pipeline.log.reader import read_recording  # noqa: E402
from pipeline.stages.report import read_all, run_report  # noqa: E402
from tests.analysis.bagfactory import paper_like, write_bag  # noqa: E402

CONTROL_TOPICS = ("/joint_states", "/controller_state", "/ground_truth/joint_states")


def best_s(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def write_paper_like(root: Path, name: str, controller: str, *, scale: float) -> tuple[Path, str]:
    """A 10 s, 1 kHz paper-like episode; returns (recording, writer used)."""
    ep = paper_like(
        name, controller, duration_s=10.0, motion_end_s=6.0, period_s=1e-3, error_scale=scale
    )
    try:
        from pipeline.log.bag import write_episode_bag
        from pipeline.robots import load_spec
        from pipeline.sim.result import EpisodeResult, TrajectorySamples
        from tests.analysis.bagfactory import default_settings
    except ImportError:
        return write_bag(root, ep), "tests/analysis/bagfactory.py (mcap_ros2)"
    spec = load_spec("ur5")
    n = len(ep.stamp_ns)
    result = EpisodeResult(
        spec.joint_names,
        ep.stamp_ns,
        ep.q,
        ep.qd,
        ep.q,
        ep.qd,
        ep.q_ref,
        ep.qd_ref,
        np.zeros((n, 6)),
        ep.effort,
        ep.effort,
        np.zeros((n, 6), dtype=bool),
    )
    ts = np.linspace(0.0, 6.0, 601)
    idx = np.searchsorted(ep.stamp_ns / 1e9, ts).clip(0, n - 1)
    planned = TrajectorySamples(ts, ep.q_ref[idx], ep.qd_ref[idx], np.zeros((ts.size, 6)))
    meta = {
        "episode": name,
        "scenario": "paper",
        "controller": controller,
        "robot": "ur5",
        "seed": "0",
        "settings": json.dumps(default_settings(ep)),
    }
    path = root / name
    write_episode_bag(path, spec=spec, result=result, planned=planned, metadata=meta)
    return path, "pipeline.log.bag.write_episode_bag"


def decode_bench(recording: Path, repeat: int) -> dict[str, Any]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    rec = read_recording(recording)
    ours_s = best_s(lambda: read_recording(recording), repeat)
    raw: list[tuple[str, bytes, Any, Any]] = []
    with open(rec.mcap_path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(topics=CONTROL_TOPICS):
            raw.append((schema.name, message.data, schema, channel))
    # rosbags types from the schemas embedded in this recording (whatever ROS distro they are).
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    for _, _, schema, _ in {r[2].id: r for r in raw}.values():
        store.register(get_types_from_msg(schema.data.decode(), schema.name))
    rosbags_s = best_s(lambda: [store.deserialize_cdr(d, n) for n, d, _, _ in raw], repeat)
    factory = DecoderFactory()
    decoders = {}
    for _, _, schema, channel in raw:
        decoders.setdefault(schema.id, factory.decoder_for(channel.message_encoding, schema))
    mcap_ros2_s = best_s(lambda: [decoders[s.id](d) for _, d, s, _ in raw], max(1, repeat // 2))
    by_topic = {}
    for topic in CONTROL_TOPICS:
        msgs = [(name, d) for name, d, _, c in raw if c.topic == topic]
        secs = best_s(lambda msgs=msgs: [store.deserialize_cdr(d, n) for n, d in msgs], repeat)
        by_topic[topic] = round(len(msgs) / secs)
    n = len(raw)
    assert n == rec.decoded_messages, (n, rec.decoded_messages)
    return {
        "recording_bytes": rec.size_bytes,
        "messages": n,
        "rows": rec.samples.height,
        "ours_msgs_per_s": round(n / ours_s),
        "rosbags_msgs_per_s": round(n / rosbags_s),
        "rosbags_msgs_per_s_by_topic": by_topic,
        "mcap_ros2_msgs_per_s": round(n / mcap_ros2_s),
        "speedup_vs_rosbags": round(rosbags_s / ours_s, 1),
        "speedup_vs_mcap_ros2": round(mcap_ros2_s / ours_s, 1),
    }


def write_generic(path: Path, seconds: float) -> int:
    """A Jazzy robot's bag written by rosbags (MCAP) in which no two consecutive messages
    share a layout: every header.frame_id has another length, so our reader takes the
    generic path (walk_many) for all of them. Returns the message count."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from pipeline.log.schemas import full_definition

    store = get_typestore(Stores.ROS2_JAZZY)
    cs_type = "control_msgs/msg/JointTrajectoryControllerState"
    store.register(get_types_from_msg(full_definition(cs_type).split("\n" + "=" * 80)[0], cs_type))
    T = store.types
    names = [f"joint_{i}" for i in range(6)]
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Duration = T["builtin_interfaces/msg/Duration"]
    Point = T["trajectory_msgs/msg/JointTrajectoryPoint"]
    Multi = T["trajectory_msgs/msg/MultiDOFJointTrajectoryPoint"]
    multi = Multi(
        transforms=[], velocities=[], accelerations=[], time_from_start=Duration(sec=0, nanosec=0)
    )
    rng = np.random.default_rng(0)
    n = round(seconds * 1000)
    empty = np.zeros(0)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c_js = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        c_cs = w.add_connection("/arm/controller_state", cs_type, typestore=store)
        for k in range(n):
            ns = 1_700_000_000_000_000_000 + k * 1_000_000
            header = Header(
                stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="f" * (k % 13)
            )
            q = rng.normal(size=6)
            js = T["sensor_msgs/msg/JointState"](
                header=header, name=names, position=q, velocity=q, effort=q
            )
            w.write(c_js, ns, store.serialize_cdr(js, "sensor_msgs/msg/JointState"))
            pt = Point(
                positions=q,
                velocities=q,
                accelerations=empty,
                effort=empty,
                time_from_start=Duration(sec=0, nanosec=0),
            )
            cs = T[cs_type](
                header=header, joint_names=names, reference=pt, feedback=pt, error=pt, output=pt,
                multi_dof_joint_names=[], multi_dof_reference=multi, multi_dof_feedback=multi,
                multi_dof_error=multi, multi_dof_output=multi, speed_scaling_factor=1.0,
            )  # fmt: skip
            w.write(c_cs, ns, store.serialize_cdr(cs, cs_type))
    return 2 * n


def generic_bench(path: Path, count: int, repeat: int) -> dict[str, Any]:
    """Our reader (file to frames, generic path) vs rosbags' AnyReader + deserialize_cdr on
    the same file (rosbags reads the file too)."""
    from rosbags.highlevel import AnyReader

    ours_s = best_s(lambda: read_recording(path), repeat)

    def with_rosbags() -> int:
        k = 0
        with AnyReader([path]) as reader:
            for connection, _, raw in reader.messages():
                reader.deserialize(raw, connection.msgtype)
                k += 1
        return k

    assert with_rosbags() == count
    rosbags_s = best_s(with_rosbags, max(1, repeat // 2))
    return {
        "messages": count,
        "ours_msgs_per_s": round(count / ours_s),
        "rosbags_msgs_per_s": round(count / rosbags_s),
        "speedup_vs_rosbags": round(rosbags_s / ours_s, 1),
    }


def synthetic(root: Path, count: int) -> Path:
    folder = root / f"synthetic_{count}"
    for k in range(count):
        scenario = f"s{k // 2:03d}"
        controller = ("pid", "ctc")[k % 2]
        ep = paper_like(
            f"{scenario}_{controller}",
            controller,
            duration_s=2.0,
            motion_end_s=1.5,
            period_s=2e-3,
            error_scale=(3e-3, 1.5e-3)[k % 2],
            scenario=scenario,
            seed=k,
        )
        write_bag(folder, ep)
    return folder


def campaign_point(count: int) -> dict[str, Any]:
    """One campaign size, measured in this process (run it in a fresh one)."""
    import gc
    import resource
    from dataclasses import replace

    from tests.report.campaignfactory import campaign_episodes, write_campaign

    seeds = max(1, count // 6)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        episodes = campaign_episodes(seeds=seeds)
        for ep in episodes:  # 1 s at 500 Hz instead of the tests' 0.3 s
            longer = paper_like(
                ep.episode, ep.controller, duration_s=1.0, motion_end_s=0.7, seed=ep.seed,
                error_scale=float(np.abs(ep.q_ref - ep.q).max()), scenario=ep.scenario,
            )  # fmt: skip
            longer.campaign = ep.campaign
            ep.__dict__.update(longer.__dict__)
        write_campaign(root / "recordings", episodes)
        count = len(episodes)
        del episodes, longer  # the fixtures' arrays are not the report's memory
        gc.collect()
        t0 = time.perf_counter()
        # reading alone, keeping no frames (as the report does for campaign episodes)
        read_all(
            root / "recordings",
            skip_bad=False,
            measure=lambda r: replace(
                r, samples=r.samples.clear(), controller_states=r.controller_states.clear()
            ),
        )
        read_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        out = root / "reports"
        run_report(recordings_dir=root / "recordings", out_dir=out)
        wall = time.perf_counter() - t0
        sizes = {
            p.relative_to(out).as_posix(): p.stat().st_size for p in out.rglob("*") if p.is_file()
        }
        return {
            "episodes": count,
            "s": round(wall, 2),
            "s_per_episode": round(wall / count, 4),
            "read_s": round(read_s, 2),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
            "report_md_bytes": sizes["report.md"],
            "rrd_bytes": sizes["recording.rrd"],
            "metrics_json_bytes": sizes["metrics.json"],
            "outputs_bytes": sum(sizes.values()),
        }


def campaign_sweep(counts: list[int]) -> list[dict[str, Any]]:
    import subprocess

    rows = []
    for count in counts:
        proc = subprocess.run(
            [sys.executable, __file__, "--campaign-point", str(count)],
            capture_output=True, text=True, check=True, cwd=REPO,
        )  # fmt: skip
        rows.append(json.loads(proc.stdout))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--skip-synthetic", action="store_true")
    parser.add_argument("--recording", type=Path, default=None)
    parser.add_argument("--campaign-sweep", default="", help="e.g. 100,300,1000")
    parser.add_argument("--only-campaign-sweep", action="store_true")
    parser.add_argument("--campaign-point", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.campaign_point:
        sys.stdout.write(json.dumps(campaign_point(args.campaign_point)) + "\n")
        return
    counts = [int(c) for c in args.campaign_sweep.split(",") if c.strip()]
    if args.only_campaign_sweep:
        sys.stdout.write(json.dumps({"campaign_sweep": campaign_sweep(counts)}, indent=2) + "\n")
        return
    out: dict[str, Any] = {
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count(),
            "python": platform.python_version(),
        },
    }
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        rec_dir = root / "recordings"
        pid, writer = write_paper_like(rec_dir, "pid_paper", "pid", scale=3.3e-3)
        write_paper_like(rec_dir, "ctc_paper", "ctc", scale=1.8e-3)
        out["writer"] = writer
        target = args.recording if args.recording is not None else pid
        out["decode"] = {"recording": str(args.recording or "paper-like 10 s, 1 kHz")}
        out["decode"] |= decode_bench(target, args.repeat)
        generic = root / "generic"
        count = write_generic(generic, 10.0)
        out["decode_generic"] = {"recording": "rosbags-written Jazzy MCAP, 10 s at 1 kHz, "
                                 "every message a different layout"}  # fmt: skip
        out["decode_generic"] |= generic_bench(generic, count, args.repeat)
        t0 = time.perf_counter()
        run_report(recordings_dir=rec_dir, out_dir=root / "reports")
        out["report_two_episodes_s"] = round(time.perf_counter() - t0, 2)
        if not args.skip_synthetic:
            rows = []
            for count in (10, 100):
                folder = synthetic(root, count)
                t0 = time.perf_counter()
                read_all(folder, skip_bad=False)
                read_s = time.perf_counter() - t0
                t0 = time.perf_counter()
                run_report(recordings_dir=folder, out_dir=root / f"reports_{count}")
                wall = time.perf_counter() - t0
                rows.append(
                    {
                        "episodes": count,
                        "s": round(wall, 2),
                        "s_per_episode": round(wall / count, 3),
                        "read_s": round(read_s, 2),
                    }
                )
            out["report_synthetic"] = rows
    if counts:
        out["campaign_sweep"] = campaign_sweep(counts)
    sys.stdout.write(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
