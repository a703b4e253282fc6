"""The recorded topics: one row each, owning what the writer and the reader do with it.

A row names the topic, its ROS type and the QoS its publisher offered (what the writer
records); its ``fill`` makes its messages of an episode
(:class:`~pipeline.log.streams.EpisodeStreams` -> :class:`Fill`: stamps and the columns of
the message's leaves); a row the reader reads
has a role and, for a control-rate topic, a ``want``: the leaves it decodes into named
arrays (:class:`~pipeline.log.decode.Want`). The writer (:mod:`pipeline.log.bag`) encodes
every row's fill; the in-memory campaign path (:func:`pipeline.log.whole.episode_recording`)
takes the wanted leaves straight from the fills, and the reader
(:mod:`pipeline.log.collect`) decodes them from the messages: both feed the same second
half (:func:`pipeline.log.whole.assemble`).

A role takes the topic named by a remap
(``topics={"controller_state": "/arm_controller/controller_state"}``), else our topic
name, else (``by_type``) the one topic of its type.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline import transforms
from pipeline.constants import (
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
    TOPIC_PLANNED_TRAJECTORY,
    TOPIC_ROBOT_DESCRIPTION,
    TOPIC_TF,
    TYPE_CONTROLLER_STATE,
    TYPE_JOINT_STATE,
    TYPE_JOINT_TRAJECTORY,
    TYPE_STRING,
    TYPE_TF,
)
from pipeline.errors import RecordingError
from pipeline.log import cdr
from pipeline.log.decode import Want
from pipeline.log.schemas import QOS_LATCHED, QOS_STREAM, QOS_TF, Qos, message_types
from pipeline.log.streams import EpisodeStreams
from pipeline.model.frames import tf_edges
from pipeline.robots.chain import then_joint_motions
from pipeline.robots.spec import RobotSpec

__all__ = [
    "OUR_TOPICS",
    "PAIRED",
    "PAIRED_COLUMNS",
    "ROLES",
    "TOPICS",
    "WANT",
    "Fill",
    "Topic",
    "paired_columns",
    "tf_poses",
    "tf_sample_indices",
    "want_by_type",
]

I64 = NDArray[np.int64]


@dataclass(frozen=True)
class Fill:
    """A topic's messages of one episode, before encoding.

    Attributes:
        stamps: (M,) log times [ns], one per message.
        columns: leaf path (``position``, ``reference.positions``, ``header.stamp.sec``)
            -> (M, ...) column, one row per message; with ``sample`` None (one message),
            the message's whole value instead.
        sample: a message fixing the layout (sequence lengths, strings) the columns fill;
            None: one message, ``columns`` is its value.
    """

    stamps: I64
    columns: Mapping[str, Any]
    sample: Mapping[str, Any] | None = None


@dataclass(frozen=True)
class Topic:
    """A recorded topic.

    Attributes:
        name: our topic name.
        type: its ROS message type.
        qos: the QoS its publisher offered (recorded in the channel metadata).
        fill: its messages of an episode.
        role: what the reader reads it as (None: written only, not read).
        by_type: without a remap, the one topic of this type serves the role when ours is
            absent (not for generic types like std_msgs/String, or for our simulation-only
            topics).
        want: what the reader decodes of each message of a control-rate role (None: the
            first message is kept raw and decoded on demand).
        paired: the columns this role adds to both tidy frames (column -> ``want`` key),
            taken at each controller state's stamp (nearest within half a period; null
            where none, or without the topic).
    """

    name: str
    type: str
    qos: Qos
    fill: Callable[[EpisodeStreams], Fill]
    role: str | None = None
    by_type: bool = False
    want: Want | None = None
    paired: Mapping[str, str] | None = None


def _header_columns(stamps: I64, path: str = "header.stamp") -> dict[str, Any]:
    try:
        return dict(cdr.time_values(path, stamps))
    except ValueError as err:
        raise RecordingError(f"result.stamp_ns: {err}") from err


def _first(ep: EpisodeStreams) -> I64:
    return np.array([ep.t0_ns], np.int64)


def _robot_description(ep: EpisodeStreams) -> Fill:
    # Imported here: the URDF module pulls in Pinocchio, which readers of pipeline.log skip.
    from pipeline.robots.urdf import build_urdf

    return Fill(_first(ep), {"data": ep.spec.description or build_urdf(ep.spec)})


def _planned_trajectory(ep: EpisodeStreams) -> Fill:
    """trajectory_msgs/JointTrajectory of the planned samples (effort left empty), its
    header stamped at the motion start."""
    p = ep.planned
    value = {
        "header": {"stamp": cdr.time_value(ep.t0_ns + ep.motion_start_ns)},
        "joint_names": list(ep.joint_names),
        "points": [
            {
                "positions": p.positions[i],
                "velocities": p.velocities[i],
                "accelerations": p.accelerations[i],
                "time_from_start": cdr.time_value(p.time_from_start_ns[i]),
            }
            for i in range(len(p.time_from_start_ns))
        ],
    }
    return Fill(_first(ep), value)


def _joint_states(ep: EpisodeStreams, rows: slice, q: str, qd: str) -> Fill:
    stamps = ep.stamp_ns[rows]
    zeros = np.zeros(ep.spec.dof)
    sample = {"name": list(ep.joint_names), "position": zeros, "velocity": zeros, "effort": zeros}
    columns = _header_columns(stamps) | {
        "position": ep.columns[q][rows],
        "velocity": ep.columns[qd][rows],
        "effort": ep.columns["tau_nm"][rows],
    }
    return Fill(stamps, columns, sample)


def _measured_joint_states(ep: EpisodeStreams) -> Fill:
    """The measured q, qd and the applied effort, every k-th control step."""
    return _joint_states(ep, slice(None, None, ep.joint_state_decimation), "q", "qd")


def _true_joint_states(ep: EpisodeStreams) -> Fill:
    """The plant's true q, qd (no sensor noise) and the applied effort, every step."""
    return _joint_states(ep, slice(None), "q_true", "qd_true")


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


def _controller_state(ep: EpisodeStreams) -> Fill:
    """``reference`` = q_ref, qd_ref, qdd_ref; ``feedback`` = measured q, qd; ``error`` =
    reference - feedback (positions, velocities); ``output.effort`` = the commanded effort;
    each point's ``time_from_start`` = time since the episode start; Humble's
    ``desired``/``actual`` repeat reference/feedback; Jazzy's ``speed_scaling_factor`` is 1;
    unused sequences and the ``multi_dof_*`` fields are empty."""
    a, stamps = ep.columns, ep.stamp_ns
    q, qd, q_ref, qd_ref = a["q"], a["qd"], a["q_ref"], a["qd_ref"]
    values = {
        "reference": (q_ref, qd_ref, a["qdd_ref"]),
        "feedback": (q, qd),
        "error": (q_ref - q, qd_ref - qd),
        "output": (a["tau_cmd_nm"],),
    }
    values["desired"], values["actual"] = values["reference"], values["feedback"]
    cs_types = message_types(TYPE_CONTROLLER_STATE, ep.ros_distro)
    points = [f.name for f in cs_types[TYPE_CONTROLLER_STATE].fields if f.name in _CS_POINT_FIELDS]
    zeros = np.zeros(ep.spec.dof)
    sample: dict[str, Any] = {"joint_names": list(ep.joint_names), "speed_scaling_factor": 1.0}
    columns = _header_columns(stamps)
    for point in points:
        fields = _CS_POINT_FIELDS[point]
        sample[point] = dict.fromkeys(fields, zeros)
        columns |= dict(zip((f"{point}.{f}" for f in fields), values[point], strict=True))
        columns |= _header_columns(stamps - ep.t0_ns, f"{point}.time_from_start")
    return Fill(stamps, columns, sample)


def _tf(ep: EpisodeStreams) -> Fill:
    """Every link's transform, at ``tf_rate_hz``, from the measured or true positions."""
    idx = tf_sample_indices(ep.stamp_ns, ep.tf_rate_hz)
    q_tf = ep.columns["q" if ep.tf_source == "measured" else "q_true"][idx]
    frames, translation, rotation = tf_poses(ep.spec, q_tf)
    tf_stamps = ep.stamp_ns[idx]
    sample = {
        "transforms": [
            {"header": {"frame_id": parent}, "child_frame_id": child} for parent, child in frames
        ]
    }
    columns: dict[str, Any] = {}
    for e in range(len(frames)):
        edge = f"transforms[{e}]"
        columns |= _header_columns(tf_stamps, f"{edge}.header.stamp")
        for k, axis in enumerate("xyz"):
            columns[f"{edge}.transform.translation.{axis}"] = translation[:, e, k]
        for k, axis in enumerate("xyzw"):
            columns[f"{edge}.transform.rotation.{axis}"] = rotation[:, e, k]
    return Fill(tf_stamps, columns, sample)


def tf_sample_indices(stamp_ns: I64, rate_hz: float) -> NDArray[np.intp]:
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


# What the reader decodes of a joint state and of a controller state (Jazzy's
# reference/feedback or Humble's desired/actual, whichever the schema has).
_JOINT_STATE_WANT = Want(
    names=("name",),
    arrays={"position": ("position",), "velocity": ("velocity",), "effort": ("effort",)},
    required=(("position",),),
)
_CONTROLLER_STATE_WANT = Want(
    names=("joint_names",),
    arrays={
        "reference_position": ("reference.positions", "desired.positions"),
        "reference_velocity": ("reference.velocities", "desired.velocities"),
        "feedback_position": ("feedback.positions", "actual.positions"),
        "error": ("error.positions",),
        "commanded_effort": ("output.effort",),
    },
    required=(
        ("reference.positions", "desired.positions"),
        ("error.positions", "feedback.positions", "actual.positions"),
    ),
)

# Order = channel ids 1.. and the order of messages that share a log time.
TOPICS: tuple[Topic, ...] = (
    Topic(TOPIC_ROBOT_DESCRIPTION, TYPE_STRING, QOS_LATCHED, _robot_description,
          "robot_description"),
    Topic(TOPIC_PLANNED_TRAJECTORY, TYPE_JOINT_TRAJECTORY, QOS_LATCHED, _planned_trajectory,
          "planned_trajectory", by_type=True),
    Topic(TOPIC_JOINT_STATES, TYPE_JOINT_STATE, QOS_STREAM, _measured_joint_states,
          "joint_states", by_type=True, want=_JOINT_STATE_WANT),
    Topic(TOPIC_CONTROLLER_STATE, TYPE_CONTROLLER_STATE, QOS_STREAM, _controller_state,
          "controller_state", by_type=True, want=_CONTROLLER_STATE_WANT),
    Topic(TOPIC_TF, TYPE_TF, QOS_TF, _tf),
    Topic(TOPIC_GROUND_TRUTH, TYPE_JOINT_STATE, QOS_STREAM, _true_joint_states,
          "ground_truth", want=_JOINT_STATE_WANT,
          paired={"true_position_rad": "position", "true_velocity_rad_s": "velocity"}),
)  # fmt: skip


def want_by_type(rows: tuple[Topic, ...]) -> dict[str, Want]:
    """What the reader decodes of each control-rate message type: its rows' ``want``.

    The reader decodes a channel by its type (a role's topic may be found by type, before
    any role is chosen), so every row of one type must want the same leaves: a second
    row of a type already read that asks for others is refused here, at import, naming
    both rows (else the last row's decode would silently serve both).

    Raises:
        ValueError: two rows of one type with different wants.
    """
    wants: dict[str, tuple[str, Want]] = {}
    for t in rows:
        if t.want is None:
            continue
        first = wants.setdefault(t.type, (t.name, t.want))
        if first[1] != t.want:
            raise ValueError(
                f"pipeline/log/topics.py: {t.name} wants other leaves of {t.type} than "
                f"{first[0]}; the reader decodes a message type one way: give both rows "
                "one want (a superset of both)"
            )
    return {type_name: want for type_name, (_, want) in wants.items()}


def paired_columns(rows: tuple[Topic, ...]) -> tuple[str, ...]:
    """The frame columns the rows' ``paired`` add, in row order.

    Raises:
        ValueError: a column added twice, or taken from an array its row does not decode.
    """
    columns: dict[str, str] = {}
    for t in rows:
        for column, key in (t.paired or {}).items():
            if column in columns:
                raise ValueError(
                    f"pipeline/log/topics.py: {t.name} pairs column {column!r}, "
                    f"already paired by {columns[column]}"
                )
            if t.want is None or key not in t.want.arrays:
                raise ValueError(
                    f"pipeline/log/topics.py: {t.name} pairs {column!r} from {key!r}, "
                    "not an array its want decodes"
                )
            columns[column] = t.name
    return tuple(columns)


# What to decode of each control-rate message type (one per type: :func:`want_by_type`).
WANT: dict[str, Want] = want_by_type(TOPICS)

# The order the reader picks roles in and lists them (errors, ``--topic`` help): the
# control-rate ones first. A role not listed here comes after these.
_ROLE_ORDER = (
    "joint_states",
    "controller_state",
    "planned_trajectory",
    "robot_description",
    "ground_truth",
)


def _rank(t: Topic) -> int:
    return _ROLE_ORDER.index(str(t.role)) if t.role in _ROLE_ORDER else len(_ROLE_ORDER)


# role name -> its topic (the rows with a role, in the reader's order)
ROLES: dict[str, Topic] = {
    str(t.role): t for t in sorted((t for t in TOPICS if t.role is not None), key=_rank)
}

# Our names of the roles' topics: never a by-type candidate for another role.
OUR_TOPICS = frozenset(t.name for t in ROLES.values())

# The roles read at the controller state's stamps, and the frame columns they add.
PAIRED: dict[str, Topic] = {r: t for r, t in ROLES.items() if t.paired is not None}
PAIRED_COLUMNS: tuple[str, ...] = paired_columns(tuple(PAIRED.values()))
