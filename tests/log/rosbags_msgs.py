"""ROS 2 messages for the bags tests write with rosbags (an independent writer): a distro's
type store with control_msgs' ``JointTrajectoryControllerState`` registered, and the
builders every such bag needs (a header from a stamp, a trajectory point, a controller
state with Humble's or Jazzy's fields, a joint state). One copy, no pipeline code."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

DATA = Path(__file__).parent / "data" / "control_msgs"
EMPTY = np.zeros(0)


def store_for(distro: str) -> Typestore:
    """rosbags' type store of ``distro`` ("humble" or "jazzy") with its control_msgs."""
    store = get_typestore(Stores.ROS2_HUMBLE if distro == "humble" else Stores.ROS2_JAZZY)
    version = "4.8.0" if distro == "humble" else "5.3.0"
    text = (DATA / version / "JointTrajectoryControllerState.msg").read_text()
    store.register(get_types_from_msg(text, "control_msgs/msg/JointTrajectoryControllerState"))
    return store


@dataclass(frozen=True)
class RosMsgs:
    """Message builders of one distro ("humble" or "jazzy")."""

    distro: str
    store: Typestore = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "store", store_for(self.distro))

    def type(self, name: str) -> Any:
        """The message class ``name`` (e.g. ``"std_msgs/msg/String"``)."""
        return self.store.types[name]

    def header(self, ns: int) -> Any:
        """A header stamped ``ns`` [ns since the epoch], no frame."""
        time_t = self.type("builtin_interfaces/msg/Time")
        stamp = time_t(sec=int(ns // 10**9), nanosec=int(ns % 10**9))
        return self.type("std_msgs/msg/Header")(stamp=stamp, frame_id="")

    def point(
        self, pos: np.ndarray = EMPTY, vel: np.ndarray = EMPTY, eff: np.ndarray = EMPTY
    ) -> Any:
        """A trajectory point (no accelerations, zero time from start)."""
        return self.type("trajectory_msgs/msg/JointTrajectoryPoint")(
            positions=pos, velocities=vel, accelerations=EMPTY, effort=eff,
            time_from_start=self._zero(),
        )  # fmt: skip

    def controller_state(
        self, *, ns: int, joints: list[str], reference: Any, feedback: Any, error: Any, output: Any
    ) -> Any:
        """A JTC state stamped ``ns``; on Humble ``desired``/``actual`` repeat ``reference``/
        ``feedback``, on Jazzy the speed scaling is 1; multi-DOF parts are empty."""
        points = {"reference": reference, "feedback": feedback, "error": error, "output": output}
        fields: dict[str, Any] = {"header": self.header(ns), "joint_names": list(joints)}
        if self.distro == "humble":
            points |= {"desired": reference, "actual": feedback}
        else:
            fields["speed_scaling_factor"] = 1.0
        multi = self.type("trajectory_msgs/msg/MultiDOFJointTrajectoryPoint")(
            transforms=[], velocities=[], accelerations=[], time_from_start=self._zero()
        )
        fields |= points
        fields["multi_dof_joint_names"] = []
        fields |= {f"multi_dof_{p}": multi for p in points}
        return self.type("control_msgs/msg/JointTrajectoryControllerState")(**fields)

    def joint_state(
        self, *, ns: int, names: list[str], position: Any, velocity: Any, effort: Any
    ) -> Any:
        """A ``sensor_msgs/JointState`` stamped ``ns``."""
        return self.type("sensor_msgs/msg/JointState")(
            header=self.header(ns), name=list(names), position=position, velocity=velocity,
            effort=effort,
        )  # fmt: skip

    def cdr(self, msg: Any) -> bytes:
        """``msg`` serialized as CDR."""
        return bytes(self.store.serialize_cdr(msg, msg.__msgtype__))

    def _zero(self) -> Any:
        return self.type("builtin_interfaces/msg/Duration")(sec=0, nanosec=0)
