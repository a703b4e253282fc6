"""What an episode produces: the contract between the simulator and the log writer."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.settings import LoopSettings
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
        controller: the controller's registry name (``Controller.name``).
        gains_in_effect: every gain the controller ran with (``gains_in_effect()``).
        seed: the sensor-noise seed.
        physics_dt_s, control_period_steps, control_period_s: MuJoCo step [s], physics
            steps per control update, and their product [s].
        integrator: MuJoCo's integrator; friction_model: the joint friction law it ran.
        motion_start_row, motion_start_s: where the reference starts (after the pre-roll).
        preroll_settled: the pre-roll ended settled, before its cap.
        hold_settled: the hold's last window is settled.
        rows_planned: rows the episode would have had without diverging.
        loop: the loop between plant and controller as run.

    The run's facts default to a hand-built result's (tests, benches): no pre-roll.
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
    controller: str = ""
    gains_in_effect: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    physics_dt_s: float = 0.001
    control_period_steps: int = 1
    control_period_s: float = 0.001
    integrator: str = "RK4"
    friction_model: str = ""
    motion_start_row: int = 0
    motion_start_s: float = 0.0
    preroll_settled: bool = True
    hold_settled: bool = True
    rows_planned: int = 0
    loop: LoopSettings = field(default_factory=LoopSettings)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def saturation_counts(self) -> list[int]:
        """Rows per joint whose commanded effort exceeded the limit."""
        counts: list[int] = self.saturated.sum(axis=0).astype(int).tolist()
        return counts
