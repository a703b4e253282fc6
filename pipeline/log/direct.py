"""An episode's recording as its bag would read back, made in memory from its arrays.

:func:`episode_recording` takes what :func:`pipeline.log.bag.write_episode_bag` takes and
gives the :class:`~pipeline.log.recording.Recording` that
:func:`pipeline.log.reader.read_recording` gives of the bag it writes, without
encoding, compressing, writing or reading it: the arrays each topic carries
(:func:`pipeline.log.bag.encode_episode` says which) go through the reader's own second
half (:func:`pipeline.log.whole.assemble`: pairing, labels, notes, duration check, tidy
frames). Only the file's identity is missing: ``sha256`` is "" and ``size_bytes`` 0.
``tests/stages/test_partials_direct.py`` checks the rest against the bag, value for value.

A bag read in windows (larger than :data:`~pipeline.log.recording.STREAM_ABOVE_BYTES`)
reads back as decimated frames: :func:`reads_whole` says which results surely do not.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from pipeline.constants import (
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
    TOPIC_PLANNED_TRAJECTORY,
    TOPIC_ROBOT_DESCRIPTION,
    TOPIC_TF,
)
from pipeline.errors import RecordingError
from pipeline.log.bag import (
    check_metadata,
    check_rates,
    check_result,
    planned_arrays,
    tf_sample_indices,
)
from pipeline.log.labels import labels_of
from pipeline.log.recording import STREAM_ABOVE_BYTES, PlannedTrajectory, ReadOptions, Recording
from pipeline.log.schemas import DEFAULT_ROS_DISTRO, check_distro
from pipeline.log.whole import Decoded, assemble
from pipeline.robots.spec import RobotSpec
from pipeline.sim.result import EpisodeResult, TrajectorySamples

__all__ = ["MAX_BAG_BYTES_PER_JOINT_STEP", "episode_recording", "reads_whole"]

# Bag bytes per control step and joint, at most: every topic uncompressed (Humble's
# controller state repeats reference and feedback) is ~250; zstd only shrinks it.
MAX_BAG_BYTES_PER_JOINT_STEP = 400


def reads_whole(result: EpisodeResult) -> bool:
    """The bag of ``result`` is surely read whole (not in windows) by the reader."""
    steps = int(np.shape(result.stamp_ns)[0])
    return steps * len(result.joint_names) * MAX_BAG_BYTES_PER_JOINT_STEP < STREAM_ABOVE_BYTES


def episode_recording(
    bag_dir: Path,
    *,
    spec: RobotSpec,
    result: EpisodeResult,
    planned: TrajectorySamples,
    metadata: Mapping[str, str],
    motion_start_ns: int = 0,
    joint_state_decimation: int = 1,
    tf_rate_hz: float = 50.0,
    ros_distro: str = DEFAULT_ROS_DISTRO,
) -> Recording:
    """The recording ``read_recording(bag_dir)`` gives after
    ``write_episode_bag(bag_dir, ...)`` with the same arguments (``tf_source`` does not
    change what is read), but for the file's SHA-256 and size.

    Raises:
        RecordingError: what the writer refuses, or what the reader refuses of its bag.
    """
    from pipeline.robots.urdf import build_urdf  # Pinocchio, as the writer imports it

    del motion_start_ns  # the planned trajectory's header stamp: not read
    try:
        check_distro(ros_distro)  # either distro's messages carry the same arrays
    except ValueError as err:
        raise RecordingError(f"ros_distro: {err}") from err
    meta = check_metadata(metadata)
    stamps, arrays = check_result(spec, result)
    check_rates(joint_state_decimation=joint_state_decimation, tf_rate_hz=tf_rate_hz)
    names = tuple(spec.joint_names)
    tfs_ns, pos, vel, _ = planned_arrays(len(names), planned)
    sec, nsec = np.divmod(np.asarray(tfs_ns, dtype=np.int64), 1_000_000_000)
    plan = PlannedTrajectory(
        joint_names=names,
        # as the reader decodes time_from_start: sec + nanosec * 1e-9 in float64
        times_s=sec.astype(np.float64) + nsec.astype(np.float64) * 1e-9,
        positions=pos.copy(),
        velocities=vel.copy(),
    )
    js = slice(None, None, int(joint_state_decimation))
    q, q_ref = arrays["q"], arrays["q_ref"]
    js_t = stamps[js].copy()
    n_tf = tf_sample_indices(stamps, tf_rate_hz).size
    source = Path(bag_dir)
    return assemble(
        Decoded(
            source=source,
            mcap_path=source / f"{source.name}_0.mcap",
            sha256="",
            size_bytes=0,
            names=names,
            js_topic=TOPIC_JOINT_STATES,
            cs_topic=TOPIC_CONTROLLER_STATE,
            js_t=js_t,
            js_a={"position": q[js], "velocity": arrays["qd"][js], "effort": arrays["tau_nm"][js]},
            cs_t=stamps,
            cs_a={
                "reference_position": q_ref,
                "reference_velocity": arrays["qd_ref"],
                "feedback_position": q,
                "error": q_ref - q,
                "commanded_effort": arrays["tau_cmd_nm"],
            },
            truth=(
                stamps,
                {
                    "position": arrays["q_true"],
                    "velocity": arrays["qd_true"],
                    "effort": arrays["tau_nm"],
                },
            ),
            gt_perm=list(range(len(names))),
            notes=[],
            lost_pct=None,
            damaged=False,
            labels=labels_of(
                meta,
                spec.description or build_urdf(spec),
                source=source,
                options=ReadOptions(),
                urdf_topic=TOPIC_ROBOT_DESCRIPTION,
                names=names,
            ),
            planned=plan,
            planned_topic=TOPIC_PLANNED_TRAJECTORY,
            topic_counts={
                TOPIC_ROBOT_DESCRIPTION: 1,
                TOPIC_PLANNED_TRAJECTORY: 1,
                TOPIC_JOINT_STATES: js_t.size,
                TOPIC_CONTROLLER_STATE: stamps.size,
                TOPIC_TF: n_tf,
                TOPIC_GROUND_TRUTH: stamps.size,
            },
            decoded_messages=js_t.size + 2 * stamps.size,
        )
    )
