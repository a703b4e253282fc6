"""The recorded episode's stream part: one typed value, :class:`EpisodeStreams`.

What an episode's bag holds, checked once: the robot, the ``armlab.episode`` metadata
(the settings as JSON strings), the per-step columns of the episode and of its planned
trajectory, and the recording options. The topic rows (:data:`pipeline.log.topics.TOPICS`)
fill their messages from it; the writer (:func:`pipeline.log.bag.write_episode_bag`)
encodes those, and the in-memory campaign path
(:func:`pipeline.log.whole.episode_recording`) decodes the same fills through the
reader's second half, without a file.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import RecordingError
from pipeline.log.schemas import DEFAULT_ROS_DISTRO, RosDistro, check_distro
from pipeline.robots.spec import RobotSpec
from pipeline.sim.result import EpisodeResult, TrajectorySamples

__all__ = [
    "REQUIRED_METADATA_KEYS",
    "RESULT_COLUMNS",
    "EpisodeStreams",
    "PlannedColumns",
    "check_metadata",
    "check_rates",
    "check_result",
    "planned_arrays",
]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

REQUIRED_METADATA_KEYS = ("episode", "scenario", "controller", "robot", "seed", "settings")

# The per-step columns of an episode the topics carry, (N, joints) each.
RESULT_COLUMNS = ("q", "qd", "q_true", "qd_true", "q_ref", "qd_ref", "qdd_ref", "tau_cmd_nm",
                  "tau_nm")  # fmt: skip


@dataclass(frozen=True)
class PlannedColumns:
    """The planned trajectory as recorded: each point's ``time_from_start`` [ns] and its
    positions, velocities, accelerations ((K, n) float64)."""

    time_from_start_ns: list[int]
    positions: F64
    velocities: F64
    accelerations: F64


@dataclass(frozen=True)
class EpisodeStreams:
    """One recorded episode's streams, checked: what its bag holds.

    Attributes:
        spec: the robot (URDF for /robot_description, frames for /tf).
        metadata: the ``armlab.episode`` record, keys sorted (:func:`check_metadata`); {}
            when only messages are encoded.
        stamp_ns: (N,) control-step stamps [ns], strictly increasing: log times and
            header stamps.
        columns: :data:`RESULT_COLUMNS` -> (N, joints) float64.
        planned: the planned trajectory, published once on /planned_trajectory.
        motion_start_ns: the planned trajectory's header stamp, after the first stamp [ns].
        joint_state_decimation: /joint_states carries every k-th control step.
        tf_rate_hz: /tf publication rate [Hz] (sampled from the control steps).
        tf_source: the joint positions /tf is computed from ("measured" or "true").
        ros_distro: whose message definitions the bag uses.
    """

    spec: RobotSpec
    metadata: dict[str, str]
    stamp_ns: I64
    columns: dict[str, F64]
    planned: PlannedColumns
    motion_start_ns: int = 0
    joint_state_decimation: int = 1
    tf_rate_hz: float = 50.0
    tf_source: Literal["measured", "true"] = "measured"
    ros_distro: RosDistro = DEFAULT_ROS_DISTRO

    @classmethod
    def of(
        cls,
        *,
        spec: RobotSpec,
        result: EpisodeResult,
        planned: TrajectorySamples,
        metadata: Mapping[str, str] | None,
        motion_start_ns: int = 0,
        joint_state_decimation: int = 1,
        tf_rate_hz: float = 50.0,
        tf_source: Literal["measured", "true"] = "measured",
        ros_distro: str = DEFAULT_ROS_DISTRO,
    ) -> EpisodeStreams:
        """The streams of an episode's arrays, checked (``metadata`` None: not recorded).

        Raises:
            RecordingError: naming the argument or field that is inconsistent.
        """
        try:
            distro = check_distro(ros_distro)
        except ValueError as err:
            raise RecordingError(f"ros_distro: {err}") from err
        meta = check_metadata(metadata) if metadata is not None else {}
        stamps, columns = check_result(spec, result)
        check_rates(joint_state_decimation=joint_state_decimation, tf_rate_hz=tf_rate_hz)
        if tf_source not in ("measured", "true"):
            raise RecordingError(f"tf_source: {tf_source!r}, expected 'measured' or 'true'")
        tfs_ns, pos, vel, acc = planned_arrays(spec.dof, planned)
        return cls(
            spec=spec,
            metadata=meta,
            stamp_ns=stamps,
            columns=columns,
            planned=PlannedColumns(tfs_ns, pos, vel, acc),
            motion_start_ns=int(motion_start_ns),
            joint_state_decimation=int(joint_state_decimation),
            tf_rate_hz=tf_rate_hz,
            tf_source=tf_source,
            ros_distro=distro,
        )

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.spec.joint_names)

    @property
    def t0_ns(self) -> int:
        """The first stamp [ns] (0 without steps)."""
        return int(self.stamp_ns[0]) if self.stamp_ns.size else 0


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
    for field in RESULT_COLUMNS:
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
