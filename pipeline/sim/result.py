"""What an episode produces: the contract between the simulator and the log writer."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.trajectory import F64, Reference, TrajectorySamples

# Reference and TrajectorySamples live in pipeline.trajectory (planning produces them, the
# simulator and the log writer consume them); re-exported here for the episode contract.
__all__ = ["F64", "EpisodeResult", "Reference", "TrajectorySamples"]


@dataclass(frozen=True)
class EpisodeResult:
    """Everything a control episode produced, sampled at the control rate.

    Row k of every (N, n) array belongs to ``stamp_ns[k]`` (simulated time
    since the episode start). ``q``/``qd`` are what the controller measured
    (sensor noise included), ``tau_nm`` what the actuators applied (after
    saturation), ``tau_cmd_nm`` what the controller asked for.

    Attributes:
        joint_names: joint order of every array.
        stamp_ns: (N,) int64 simulated time [ns].
        q, qd: measured position [rad], velocity [rad/s].
        q_true, qd_true: plant state without sensor noise.
        q_ref, qd_ref, qdd_ref: reference at the same instants.
        tau_cmd_nm, tau_nm: commanded and applied effort [N m].
        saturated: (N, n) bool, |commanded| exceeded the effort limit.
        status: "ok", or "diverged" when the episode was ended early.
        reason: why it diverged ("" when ok).
        mujoco_warnings: MuJoCo warning counters by name, non-zero ones only.
    """

    joint_names: tuple[str, ...]
    stamp_ns: NDArray[np.int64]
    q: F64
    qd: F64
    q_true: F64
    qd_true: F64
    q_ref: F64
    qd_ref: F64
    qdd_ref: F64
    tau_cmd_nm: F64
    tau_nm: F64
    saturated: NDArray[np.bool_]
    status: Literal["ok", "diverged"] = "ok"
    reason: str = ""
    mujoco_warnings: dict[str, int] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"
