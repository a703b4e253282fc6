"""The recorded topics: one row each, read by the writer (:mod:`pipeline.log.bag`) and the
reader (:mod:`pipeline.log.collect`).

A row names the topic, its ROS type and the QoS its publisher offered (what the writer
records), and the role the reader finds it by. A role takes the topic named by a remap
(``topics={"controller_state": "/arm_controller/controller_state"}``), else our topic
name, else (``by_type``) the one topic of its type. Adding a topic today takes its name in
:mod:`pipeline.constants`, one row here, the code that fills it
(:func:`pipeline.log.bag.encode_episode`) and its in-memory twin in :mod:`pipeline.log.direct`
(tested equal by ``tests/stages/test_partials_direct.py``); a topic the report reads also
needs its decode in :mod:`pipeline.log.collect`.
"""

from __future__ import annotations

from dataclasses import dataclass

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
from pipeline.log.schemas import QOS_LATCHED, QOS_STREAM, QOS_TF, Qos

__all__ = ["OUR_TOPICS", "ROLES", "TOPICS", "Topic"]


@dataclass(frozen=True)
class Topic:
    """A recorded topic.

    Attributes:
        name: our topic name.
        type: its ROS message type.
        qos: the QoS its publisher offered (recorded in the channel metadata).
        role: what the reader reads it as (None: written only, not read).
        by_type: without a remap, the one topic of this type serves the role when ours is
            absent (not for generic types like std_msgs/String, or for our simulation-only
            topics).
    """

    name: str
    type: str
    qos: Qos
    role: str | None = None
    by_type: bool = False


# Order = channel ids 1.. and the order of messages that share a log time.
TOPICS: tuple[Topic, ...] = (
    Topic(TOPIC_ROBOT_DESCRIPTION, TYPE_STRING, QOS_LATCHED, "robot_description"),
    Topic(TOPIC_PLANNED_TRAJECTORY, TYPE_JOINT_TRAJECTORY, QOS_LATCHED, "planned_trajectory", True),
    Topic(TOPIC_JOINT_STATES, TYPE_JOINT_STATE, QOS_STREAM, "joint_states", True),
    Topic(TOPIC_CONTROLLER_STATE, TYPE_CONTROLLER_STATE, QOS_STREAM, "controller_state", True),
    Topic(TOPIC_TF, TYPE_TF, QOS_TF),
    Topic(TOPIC_GROUND_TRUTH, TYPE_JOINT_STATE, QOS_STREAM, "ground_truth"),
)

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
