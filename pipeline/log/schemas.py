"""ROS 2 message definitions embedded in our recordings, per ROS distribution, and QoS.

The definitions are those of ROS 2 **Jazzy** (common_interfaces 5.3, control_msgs >= 5.3) or
**Humble** (common_interfaces 4.2, control_msgs 4.8), reduced to their field lines (the
upstream ``.msg`` comments are left out; decoders and the RIHS01 type hashes do not depend on
them). ``tests/log/test_definitions.py`` checks every one against the upstream definitions of
its distro (rosbags' type stores, and the control_msgs files vendored under
``tests/log/data/``). ``full_definition`` concatenates a type and its dependencies the way
rosbag2's ``LocalMessageDefinitionSource`` does, so the MCAP ``ros2msg`` schemas look like the
ones ``ros2 bag record`` writes: the top-level text, then for every dependency (sorted names,
depth first, each once) a blank line, 80 ``=``, ``MSG: pkg/Type`` and its text.

``control_msgs/msg/JointTrajectoryControllerState`` is the one that differs between distros:

- Jazzy (control_msgs >= 5.3, Nov 2024): ``reference``/``feedback``/``error``/``output``, the
  four ``multi_dof_*`` points and ``float64 speed_scaling_factor``.
- Humble (control_msgs 4.8): the same points plus the deprecated ``desired``/``actual``, and
  six ``multi_dof_*`` points; no speed scaling.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from typing import Literal

from pipeline.constants import (
    TYPE_CONTROLLER_STATE,
    TYPE_JOINT_STATE,
    TYPE_JOINT_TRAJECTORY,
    TYPE_STRING,
    TYPE_TF,
)
from pipeline.log.msgdef import MsgTypes, parse_msgdef, short_name

RosDistro = Literal["jazzy", "humble"]
ROS_DISTROS: tuple[RosDistro, ...] = ("jazzy", "humble")
DEFAULT_ROS_DISTRO: RosDistro = "jazzy"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"

_POINTS_JAZZY = ("reference", "feedback", "error", "output")
_POINTS_HUMBLE = ("reference", "feedback", "error", "output", "desired", "actual")


def _controller_state(points: tuple[str, ...], tail: str) -> str:
    return (
        "std_msgs/Header header\n"
        "string[] joint_names\n"
        + "".join(f"trajectory_msgs/JointTrajectoryPoint {p}\n" for p in points)
        + "string[] multi_dof_joint_names\n"
        + "".join(f"trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_{p}\n" for p in points)
        + tail
    )


# Field lines of each .msg file, keyed by the name rosbag2 uses in "MSG: " lines. Type names
# are spelled as in the upstream files (same-package types unqualified), since rosbag2 copies
# the files verbatim and decoders must resolve them in the package of their section.
_COMMON: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "sensor_msgs/JointState": (
        "std_msgs/Header header\n"
        "string[] name\n"
        "float64[] position\n"
        "float64[] velocity\n"
        "float64[] effort\n"
    ),
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/Twist": "Vector3  linear\nVector3  angular\n",
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"
    ),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "trajectory_msgs/JointTrajectoryPoint": (
        "float64[] positions\n"
        "float64[] velocities\n"
        "float64[] accelerations\n"
        "float64[] effort\n"
        "builtin_interfaces/Duration time_from_start\n"
    ),
    "trajectory_msgs/JointTrajectory": (
        "std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points\n"
    ),
    "trajectory_msgs/MultiDOFJointTrajectoryPoint": (
        "geometry_msgs/Transform[] transforms\n"
        "geometry_msgs/Twist[] velocities\n"
        "geometry_msgs/Twist[] accelerations\n"
        "builtin_interfaces/Duration time_from_start\n"
    ),
}

MSG_TEXTS: dict[RosDistro, dict[str, str]] = {
    "jazzy": {
        **_COMMON,
        "control_msgs/JointTrajectoryControllerState": _controller_state(
            _POINTS_JAZZY, "float64 speed_scaling_factor\n"
        ),
    },
    "humble": {
        **_COMMON,
        "control_msgs/JointTrajectoryControllerState": _controller_state(_POINTS_HUMBLE, ""),
    },
}

# RIHS01 type hashes (rosidl type description hashes) of the definitions. rosbag2 >= Iron
# stores them as ``type_description_hash``; Humble predates them (its bags carry none), the
# Humble values are what rosidl computes for those definitions (tests recompute all of them).
TYPE_HASHES: dict[RosDistro, dict[str, str]] = {
    "jazzy": {
        TYPE_JOINT_STATE: (
            "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
        ),
        TYPE_CONTROLLER_STATE: (
            "RIHS01_51d8dd89cc624cbe9daaeeb4d80d6de9b86168ffdc3be41fefc0953e3c26e480"
        ),
        TYPE_JOINT_TRAJECTORY: (
            "RIHS01_179b33eba59d676f6d967ac71fe35e7ca2f64b2f3928f4a018cec115e213796e"
        ),
        TYPE_STRING: "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
        TYPE_TF: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    },
}
TYPE_HASHES["humble"] = {
    **TYPE_HASHES["jazzy"],
    TYPE_CONTROLLER_STATE: (
        "RIHS01_5e2fe5a025630ec82b5cc080e78b927ed0b230407fadee455a00cd59361bc573"
    ),
}

_DELIMITER = "=" * 80 + "\n"
# rosbag2's dependency scan: the first token of a line (after optional whitespace), minus an
# array suffix, when followed by whitespace.
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = frozenset(
    ["bool", "byte", "char", "float32", "float64", "string"]
    + [f"{sign}int{bits}" for sign in ("", "u") for bits in (8, 16, 32, 64)]
)


def controller_state_candidates() -> list[str]:
    """Full definitions of every JointTrajectoryControllerState generation, newest first
    (Jazzy >= 5.3, Humble 4.8, control_msgs 5.0-5.2, 4.0-4.3): for storage that does not
    carry definitions (Humble's sqlite3), the one a message's bytes fit is its layout."""
    jazzy = full_definition(TYPE_CONTROLLER_STATE, "jazzy")
    humble = full_definition(TYPE_CONTROLLER_STATE, "humble")
    old = _controller_state(("desired", "actual", "error"), "")
    return [
        jazzy,
        humble,
        jazzy.replace("float64 speed_scaling_factor\n", "", 1),
        humble.replace(humble.split("\n" + _DELIMITER)[0] + "\n", old, 1),
    ]


def check_distro(distro: str) -> RosDistro:
    """``distro`` if we write it, else a ValueError listing the valid ones."""
    for d in ROS_DISTROS:
        if distro == d:
            return d
    raise ValueError(f"ROS distro {distro!r}: expected one of {', '.join(ROS_DISTROS)}")


def _dependencies(texts: dict[str, str], short: str) -> list[str]:
    package = short.split("/")[0]
    deps = set()
    for match in _FIELD_TYPE.finditer(texts[short]):
        name = match.group(1)
        if name in _PRIMITIVES:
            continue
        deps.add(name if "/" in name else f"{package}/{name}")
    return sorted(deps)


@functools.cache
def full_definition(type_name: str, distro: RosDistro = DEFAULT_ROS_DISTRO) -> str:
    """Concatenated ``ros2msg`` definition of ``type_name`` and its dependencies.

    Args:
        type_name: ``pkg/msg/Type`` or ``pkg/Type``.
        distro: whose definitions.
    """
    texts = MSG_TEXTS[distro]
    seen: set[str] = set()

    def append(name: str) -> str:
        text = texts[name]
        for dep in _dependencies(texts, name):
            if dep not in seen:
                seen.add(dep)
                text += "\n" + _DELIMITER + f"MSG: {dep}\n" + append(dep)
        return text

    return append(short_name(type_name))


@functools.cache
def message_types(type_name: str, distro: RosDistro = DEFAULT_ROS_DISTRO) -> MsgTypes:
    """The parsed definitions of ``type_name`` (and its dependencies) for ``distro``."""
    return parse_msgdef(type_name, full_definition(type_name, distro))


@dataclass(frozen=True)
class Qos:
    """The QoS a recorded publisher offered, as rosbag2 stores it (rmw enum values).

    Durations of 0 s mean "unspecified" (no deadline, lifespan or lease).
    """

    depth: int
    durability: int  # 1 transient_local, 2 volatile
    history: int = 1  # keep_last
    reliability: int = 1  # reliable
    liveliness: int = 1  # automatic

    def to_yaml(self) -> str:
        """The QoS list as rosbag2 (metadata version <= 8) serializes it: a YAML string."""
        zero = "\n    sec: 0\n    nsec: 0"
        return (
            f"- history: {self.history}\n"
            f"  depth: {self.depth}\n"
            f"  reliability: {self.reliability}\n"
            f"  durability: {self.durability}\n"
            f"  deadline:{zero}\n"
            f"  lifespan:{zero}\n"
            f"  liveliness: {self.liveliness}\n"
            f"  liveliness_lease_duration:{zero}\n"
            "  avoid_ros_namespace_conventions: false"
        )


# Latched (transient_local, depth 1) topics are re-delivered by `ros2 bag play` to late
# subscribers, like robot_state_publisher's /robot_description; the rest are plain streams.
QOS_LATCHED = Qos(depth=1, durability=1)
QOS_STREAM = Qos(depth=10, durability=2)
QOS_TF = Qos(depth=100, durability=2)  # tf2_ros' TransformBroadcaster default depth
