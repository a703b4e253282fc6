"""Recordings written with an independent writer (``mcap_ros2.writer``) for tests.

Message definitions come from rosbags' Humble type store (and, for
control_msgs, the Humble ``JointTrajectoryControllerState.msg`` text below), so
nothing here shares code with ``pipeline.log``. Signals are given as arrays,
which lets tests put known analytic answers into a recording.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2.writer import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from pipeline.model.uncertainty import link_inertials
from pipeline.robots import load_spec
from pipeline.settings import (
    CampaignInfo,
    ControllerSettings,
    EpisodeSettings,
    ExecutionSafety,
    PlannerSettings,
    PlantSettings,
    ProtocolSettings,
    Uncertainty,
)

UR5_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)

# control_msgs/msg/JointTrajectoryControllerState as shipped with ROS 2 Humble.
JTCS_HUMBLE = """\
std_msgs/Header header
string[] joint_names
trajectory_msgs/JointTrajectoryPoint reference
trajectory_msgs/JointTrajectoryPoint feedback
trajectory_msgs/JointTrajectoryPoint error
trajectory_msgs/JointTrajectoryPoint output
trajectory_msgs/JointTrajectoryPoint desired
trajectory_msgs/JointTrajectoryPoint actual
string[] multi_dof_joint_names
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_reference
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_feedback
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_output
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual
"""
JTCS = "control_msgs/msg/JointTrajectoryControllerState"


def typestore() -> Any:
    """rosbags' Humble type store plus control_msgs' controller state."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(JTCS_HUMBLE, JTCS))
    return store


_STORE = typestore()


def msgdef(typename: str) -> str:
    """ros2msg schema text (with dependencies) for ``typename``."""
    text, _ = _STORE.generate_msgdef(typename, ros_version=2)
    return str(text)


def _stamp(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _point(
    pos: Sequence[float] = (),
    vel: Sequence[float] = (),
    acc: Sequence[float] = (),
    eff: Sequence[float] = (),
    t_ns: int = 0,
) -> dict[str, Any]:
    return {
        "positions": list(pos),
        "velocities": list(vel),
        "accelerations": list(acc),
        "effort": list(eff),
        "time_from_start": _stamp(t_ns),
    }


_EMPTY_MDOF = {
    "transforms": [],
    "velocities": [],
    "accelerations": [],
    "time_from_start": _stamp(0),
}


@dataclass
class Episode:
    """Signals of one synthetic episode; (N, n) arrays at ``stamp_ns``."""

    episode: str
    controller: str
    stamp_ns: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    effort: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    effort_cmd: np.ndarray | None = None
    scenario: str = "paper"
    robot: str = "ur5"
    joint_names: tuple[str, ...] = UR5_JOINTS
    motion_end_s: float | None = None
    hold_s: float = 1.0
    status: str = "ok"
    reason: str = ""
    seed: int = 0
    settings: dict[str, Any] | None = None
    frame_ids: Sequence[str] | None = None  # per-sample header.frame_id (varies -> slow path)
    raw_settings: str | None = None  # written verbatim instead of JSON(settings)
    extra: dict[str, Any] = field(default_factory=dict)
    # /joint_states arrays written empty (legal in ROS: "not recorded"), e.g. ("effort",).
    empty_joint_state_fields: Sequence[str] = ()
    joint_state_every: int = 1  # write /joint_states every k-th sample (decimation)
    # /joint_states not written in [start, end) [ns] (a publisher that paused)
    joint_state_gap_ns: tuple[int, int] | None = None
    joint_state_offset_ns: int = 0  # /joint_states stamped this much after its sample
    controller_state_until_ns: int | None = None  # /controller_state stops at this stamp
    # Schema text and name for /joint_states instead of the Humble sensor_msgs/msg/JointState.
    joint_state_msgdef: tuple[str, str] | None = None
    episode_metadata: bool = True  # False: no armlab.episode metadata record
    reproduces_paper: bool | None = None  # None: the scenario named "paper" does
    # the plant's true positions, written on /ground_truth/joint_states when given
    q_true: np.ndarray | None = None
    motion_start_s: float = 0.0  # the pre-roll recorded before the motion (settings)
    campaign: CampaignInfo | None = None  # where the episode sits in a campaign (settings)


def default_settings(ep: Episode) -> dict[str, Any]:
    """Settings as the record stage writes them: built through the same typed contract
    (:class:`pipeline.settings.EpisodeSettings`), so a fixture cannot carry keys production
    never writes. An unknown motion end (``motion_end_s=None``) drops the one key that
    says it, which the contract then refuses (as the report must tolerate)."""
    n = len(ep.joint_names)
    spec = load_spec("ur5")
    settings = EpisodeSettings(
        episode=ep.episode,
        robot=spec,
        scenario={
            "name": ep.scenario,
            "robot": "ur5",
            "start": [float(v) for v in ep.q_ref[0]],
            "goal": {"joints": [float(v) for v in ep.q_ref[-1]]},
            "obstacles": [],
            "hold_s": ep.hold_s,
        },
        controller=ControllerSettings(
            name=ep.controller, type=ep.controller, gains={"kp": [100.0] * n, "kd": [20.0] * n}
        ),
        plant=PlantSettings(
            exact=False,
            links=link_inertials(spec),
            armature=tuple(float(a) + 0.01 for a in spec.armature),
            nominal_armature=tuple(float(a) for a in spec.armature),
            damping=(0.1,) * n,
            frictionloss=(0.0,) * n,
            payload_kg=0.0,
            position_noise_std_rad=0.0,
            velocity_noise_std_rad_s=0.0,
            uncertainty=Uncertainty(),
            physics_dt_s=0.001,
            control_period_s=0.002,
        ),
        planner=PlannerSettings(
            planner="RRTConnect",
            seed=0,
            time_limit_s=5.0,
            simplify=True,
            direct=True,
            n_waypoints=2,
            n_states_before_simplify=2,
            path_length_rad=1.2,
            padding_m=0.02,
            check_step_rad=0.01,
            interpolation="toppra",
            trajectory_duration_s=(
                ep.motion_end_s - ep.motion_start_s if ep.motion_end_s is not None else 0.0
            ),
            velocity_scaling=1.0,
            acceleration_scaling=1.0,
            start=tuple(float(v) for v in ep.q_ref[0]),
            goal=tuple(float(v) for v in ep.q_ref[-1]),
        ),
        protocol=ProtocolSettings(
            motion_start_s=ep.motion_start_s,
            hold_s=ep.hold_s,
            start_abs_error_rad=(0.0,) * n,
            start_effort_nm=(0.0,) * n,
            reproduces_paper=(
                ep.scenario == "paper" if ep.reproduces_paper is None else ep.reproduces_paper
            ),
        ),
        safety=ExecutionSafety(
            padding_m=0.05, every=1, samples_checked=len(ep.stamp_ns), clearances=(), contacts=()
        ),
        seed=ep.seed,
        status=ep.status,
        reason=ep.reason,
        package_version="0.1.0",
        git_commit="0000000",
        campaign=ep.campaign,
    ).to_dict()
    if ep.motion_end_s is None:
        del settings["planner"]["trajectory_duration_s"]
    return settings


def write_bag(
    root: Path,
    ep: Episode,
    *,
    as_directory: bool = True,
    topics: Sequence[str] = ("/joint_states", "/controller_state", "/planned_trajectory", "/tf"),
    chunk_size: int = 256 * 1024,
    compression: CompressionType = CompressionType.ZSTD,
    mcap_options: dict[str, Any] | None = None,
) -> Path:
    """Write ``ep`` as a rosbag2 directory (default) or a bare ``.mcap``; return its path.

    ``mcap_options`` go to ``mcap.writer.Writer`` (e.g. ``use_chunking=False``,
    ``index_types=IndexType.NONE``, ``enable_data_crcs=True``).
    """
    if as_directory:
        folder = root / ep.episode
        folder.mkdir(parents=True, exist_ok=False)
        mcap_path = folder / f"{ep.episode}_0.mcap"
    else:
        root.mkdir(parents=True, exist_ok=True)
        mcap_path = root / f"{ep.episode}.mcap"
    settings = ep.settings if ep.settings is not None else default_settings(ep)
    names = list(ep.joint_names)
    counts: dict[str, int] = {}
    with open(mcap_path, "wb") as fh:
        w = Writer(fh, chunk_size=chunk_size, compression=compression)
        if mcap_options:
            # mcap_ros2's Writer fixes the mcap options; swap in a writer that takes them.
            fh.seek(0)
            fh.truncate()
            w._writer = McapWriter(
                fh, chunk_size=chunk_size, compression=compression, **mcap_options
            )
            w._writer.start(profile="ros2", library="tests")
        sch = {
            t: w.register_msgdef(t, msgdef(t))
            for t in (
                JTCS,
                "trajectory_msgs/msg/JointTrajectory",
                "std_msgs/msg/String",
                "tf2_msgs/msg/TFMessage",
            )
        }
        js_name, js_text = ep.joint_state_msgdef or (
            "sensor_msgs/msg/JointState",
            msgdef("sensor_msgs/msg/JointState"),
        )
        sch["sensor_msgs/msg/JointState"] = w.register_msgdef(js_name, js_text)
        if "/robot_description" in topics:
            w.write_message(
                "/robot_description",
                sch["std_msgs/msg/String"],
                {"data": "<robot name='ur5'/>"},
                log_time=0,
            )
            counts["/robot_description"] = 1
        if "/planned_trajectory" in topics:
            end_s = ep.motion_end_s if ep.motion_end_s is not None else 1.0
            # time_from_start counts from the motion start, as the record stage writes it
            times = np.linspace(0.0, end_s - ep.motion_start_s, 5)
            at = times + ep.motion_start_s
            idx = np.searchsorted(ep.stamp_ns / 1e9, at).clip(0, len(ep.stamp_ns) - 1)
            pts = [
                _point(ep.q_ref[i], ep.qd_ref[i], t_ns=round(t * 1e9))
                for i, t in zip(idx, times, strict=True)
            ]
            w.write_message(
                "/planned_trajectory",
                sch["trajectory_msgs/msg/JointTrajectory"],
                {
                    "header": {"stamp": _stamp(0), "frame_id": ""},
                    "joint_names": names,
                    "points": pts,
                },
                log_time=0,
            )
            counts["/planned_trajectory"] = 1
        cmd = ep.effort_cmd if ep.effort_cmd is not None else ep.effort
        for k, t_ns in enumerate(ep.stamp_ns.tolist()):
            frame = ep.frame_ids[k] if ep.frame_ids is not None else ""
            header = {"stamp": _stamp(t_ns), "frame_id": frame}
            gap = ep.joint_state_gap_ns
            paused = gap is not None and gap[0] <= t_ns < gap[1]
            if "/joint_states" in topics and k % ep.joint_state_every == 0 and not paused:
                js_msg: dict[str, Any] = {
                    "header": {"stamp": _stamp(t_ns + ep.joint_state_offset_ns), "frame_id": frame},
                    "name": names,
                    "position": ep.q[k].tolist(),
                    "velocity": ep.qd[k].tolist(),
                    "effort": ep.effort[k].tolist(),
                }
                for key in ep.empty_joint_state_fields:
                    js_msg[key] = []
                w.write_message(
                    "/joint_states", sch["sensor_msgs/msg/JointState"], js_msg, log_time=t_ns
                )
                counts["/joint_states"] = counts.get("/joint_states", 0) + 1
            if ep.q_true is not None:
                if "gt" not in sch:
                    sch["gt"] = w.register_msgdef(
                        "sensor_msgs/msg/JointState", msgdef("sensor_msgs/msg/JointState")
                    )
                gt_msg = {
                    "header": header,
                    "name": names,
                    "position": ep.q_true[k].tolist(),
                    "velocity": ep.qd[k].tolist(),
                    "effort": ep.effort[k].tolist(),
                }
                w.write_message("/ground_truth/joint_states", sch["gt"], gt_msg, log_time=t_ns)
                counts["/ground_truth/joint_states"] = (
                    counts.get("/ground_truth/joint_states", 0) + 1
                )
            until = ep.controller_state_until_ns
            if "/controller_state" in topics and (until is None or t_ns < until):
                err = ep.q_ref[k] - ep.q[k]
                w.write_message(
                    "/controller_state",
                    sch[JTCS],
                    {
                        "header": header,
                        "joint_names": names,
                        "reference": _point(ep.q_ref[k], ep.qd_ref[k], np.zeros(len(names))),
                        "feedback": _point(ep.q[k], ep.qd[k]),
                        "error": _point(err, ep.qd_ref[k] - ep.qd[k]),
                        "output": _point(eff=cmd[k]),
                        "desired": _point(ep.q_ref[k], ep.qd_ref[k]),
                        "actual": _point(ep.q[k], ep.qd[k]),
                        "multi_dof_joint_names": [],
                        "multi_dof_reference": _EMPTY_MDOF,
                        "multi_dof_feedback": _EMPTY_MDOF,
                        "multi_dof_error": _EMPTY_MDOF,
                        "multi_dof_output": _EMPTY_MDOF,
                        "multi_dof_desired": _EMPTY_MDOF,
                        "multi_dof_actual": _EMPTY_MDOF,
                    },
                    log_time=t_ns,
                )
                counts["/controller_state"] = counts.get("/controller_state", 0) + 1
            if "/tf" in topics and k % 20 == 0:
                tfs = [
                    {
                        "header": {"stamp": _stamp(t_ns), "frame_id": "base_link"},
                        "child_frame_id": f"link{j}",
                        "transform": {
                            "translation": {"x": 0.0, "y": 0.0, "z": float(ep.q[k, j])},
                            "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                        },
                    }
                    for j in range(len(names))
                ]
                w.write_message(
                    "/tf", sch["tf2_msgs/msg/TFMessage"], {"transforms": tfs}, log_time=t_ns
                )
                counts["/tf"] = counts.get("/tf", 0) + 1
        if ep.episode_metadata:
            w.add_metadata(
                "armlab.episode",
                {
                    "episode": ep.episode,
                    "scenario": ep.scenario,
                    "controller": ep.controller,
                    "robot": ep.robot,
                    "seed": str(ep.seed),
                    "settings": ep.raw_settings
                    if ep.raw_settings is not None
                    else json.dumps(settings),
                },
            )
        w.finish()
    if as_directory:
        _write_metadata_yaml(mcap_path, counts, int(ep.stamp_ns[-1]) if len(ep.stamp_ns) else 0)
        return mcap_path.parent
    return mcap_path


def _write_metadata_yaml(mcap_path: Path, counts: dict[str, int], duration_ns: int) -> None:
    types = {
        "/joint_states": "sensor_msgs/msg/JointState",
        "/controller_state": JTCS,
        "/planned_trajectory": "trajectory_msgs/msg/JointTrajectory",
        "/robot_description": "std_msgs/msg/String",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/ground_truth/joint_states": "sensor_msgs/msg/JointState",
    }
    info = {
        "rosbag2_bagfile_information": {
            "version": 5,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration_ns},
            "starting_time": {"nanoseconds_since_epoch": 0},
            "message_count": sum(counts.values()),
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": t,
                        "type": types[t],
                        "serialization_format": "cdr",
                        "offered_qos_profiles": "",
                    },
                    "message_count": c,
                }
                for t, c in counts.items()
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [mcap_path.name],
            "files": [
                {
                    "path": mcap_path.name,
                    "starting_time": {"nanoseconds_since_epoch": 0},
                    "duration": {"nanoseconds": duration_ns},
                    "message_count": sum(counts.values()),
                }
            ],
        }
    }
    (mcap_path.parent / "metadata.yaml").write_text(yaml.safe_dump(info), encoding="utf-8")


def time_grid(duration_s: float, *, period_s: float = 0.002) -> np.ndarray:
    """Stamps [ns] from 0 to ``duration_s`` inclusive at ``period_s``."""
    n = round(duration_s / period_s) + 1
    return np.arange(n, dtype=np.int64) * round(period_s * 1e9)


def paper_like(
    episode: str,
    controller: str,
    *,
    duration_s: float = 3.0,
    motion_end_s: float = 2.0,
    period_s: float = 0.002,
    error_scale: float = 1e-3,
    scenario: str = "paper",
    seed: int = 0,
) -> Episode:
    """A smooth move from 0 to the paper's goal with a lagging, decaying error."""
    goal = np.array([-0.15, -0.5, 0.785, -1.15, -0.3925, 0.0])
    stamp = time_grid(duration_s, period_s=period_s)
    t = stamp / 1e9
    s = np.clip(t / motion_end_s, 0.0, 1.0)
    blend = 10 * s**3 - 15 * s**4 + 6 * s**5
    dblend = (30 * s**2 - 60 * s**3 + 30 * s**4) / motion_end_s * (t <= motion_end_s)
    q_ref = blend[:, None] * goal[None, :]
    qd_ref = dblend[:, None] * goal[None, :]
    rng = np.random.default_rng(seed)
    lag = error_scale * np.sin(np.pi * s)[:, None] * np.sign(goal + 1e-12)[None, :]
    decay = np.exp(-np.clip(t - motion_end_s, 0, None) / 0.1)[:, None]
    err = lag + error_scale * 0.05 * decay * (t > motion_end_s)[:, None]
    err[:, 5] = 0.0
    q = q_ref - err + rng.normal(0.0, 1e-7, q_ref.shape) * (t > 0)[:, None]
    qd = np.gradient(q, t, axis=0)
    effort = 10.0 * np.sin(2 * np.pi * t)[:, None] * np.array([1, 2, 1, 0.2, 0.2, 0.1])
    return Episode(
        episode=episode,
        controller=controller,
        stamp_ns=stamp,
        q=q,
        qd=qd,
        effort=effort,
        q_ref=q_ref,
        qd_ref=qd_ref,
        motion_end_s=motion_end_s,
        hold_s=max(duration_s - motion_end_s, 0.0),
        scenario=scenario,
        seed=seed,
    )


# --- damaged recordings -------------------------------------------------------------------


def mcap_file(recording: Path) -> Path:
    """The .mcap inside a rosbag2 directory (or the file itself)."""
    return recording if recording.is_file() else next(recording.glob("*.mcap"))


def first_chunk_records(path: Path) -> tuple[int, int]:
    """(offset, length) in the file of the first chunk's (possibly compressed) records."""
    _, off, n = first_chunk(path)
    return off, n


def first_chunk(path: Path) -> tuple[int, int, int]:
    """(record offset, records offset, records length) of the first chunk in ``path``."""
    data = path.read_bytes()
    pos = 8
    while pos < len(data):
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if op == 0x06:
            body = pos + 9
            (n,) = struct.unpack_from("<I", data, body + 28)
            off = body + 32 + n
            (records_len,) = struct.unpack_from("<Q", data, off)
            return pos, off + 8, records_len
        pos += 9 + length
    raise ValueError(f"{path}: no chunk")


def flip_byte(path: Path, offset: int) -> None:
    """Invert every bit of one byte of ``path``."""
    data = bytearray(path.read_bytes())
    data[offset] ^= 0xFF
    path.write_bytes(bytes(data))


def damage(recording: Path, kind: str) -> None:
    """Damage a recording: "truncated", "bitflip" (a byte inside a chunk), "empty",
    "not_mcap"."""
    path = mcap_file(recording)
    if kind == "truncated":
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif kind == "bitflip":
        off, n = first_chunk_records(path)
        flip_byte(path, off + n // 2)
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "not_mcap":
        path.write_bytes(b"this is not a recording\n" * 10)
    else:
        raise ValueError(kind)
