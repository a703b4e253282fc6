"""Task space: where the tool is, and how far it is from where the reference puts it.

The tool centre point (TCP) is the robot's flange (``tool0``) moved by a tool offset
(:class:`ToolOffset`, default none: the flange). Its pose is the forward kinematics (FK) of
the Pinocchio model the recording's robot builds (:func:`pipeline.robots.urdf.pinocchio_model`),
evaluated for a whole time slice at once: ``world_T_joint = world_T_parent @ placement @
motion(q)``, the motion a rotation about or a translation along the joint's axis
(:func:`pipeline.robots.chain.joint_motions`), is one batched matrix product per joint over
all samples of the slice.

The TCP errors compare the FK of the reference joint positions with the FK of the position
the joint metrics use (true where recorded, else measured: the protocol's
``feedback_position_rad``):

- position error [mm]: ``|p_ref - p|``;
- orientation error [mrad]: the angle of ``R_ref^T R`` (atan2 of its sine and cosine parts,
  accurate for small angles, unlike arccos of the trace).

A bag without our robot (a foreign bag) takes it from its ``/robot_description`` URDF
(:func:`pipeline.log.robot_facts.described_robot`); without one its task-space metrics are n/a.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl
from numpy.typing import NDArray

from pipeline import transforms as tf
from pipeline.analysis.catalog import TCP_JOINT
from pipeline.analysis.checks import joint_blocks_repeat
from pipeline.analysis.episodes import robot_spec
from pipeline.errors import ReportError
from pipeline.log.reader import Recording
from pipeline.robots.chain import FLANGE, joint_motions
from pipeline.robots.spec import JointSpec, RobotSpec

# The pseudo-joint the task-space rows of a metrics frame carry in their ``joint`` column.
TCP = TCP_JOINT
# The columns of a task-space error frame (before the protocol's per-row flags).
TCP_COLUMNS = ("episode", "joint", "time_s", "position_error_mm", "orientation_error_mrad")

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ToolOffset:
    """The TCP in the flange frame: ``flange_T_tcp`` = translation, then roll-pitch-yaw.

    Attributes:
        xyz_m: translation in the flange frame [m].
        rpy_rad: fixed-axis roll, pitch, yaw [rad].
    """

    xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def parse(cls, text: str) -> ToolOffset:
        """``"x,y,z"`` [m] or ``"x,y,z,roll,pitch,yaw"`` [m, rad] (a one-line error else)."""
        try:
            values = [float(v) for v in text.replace(" ", ",").split(",") if v]
        except ValueError:
            values = []
        if len(values) not in (3, 6):
            raise ReportError(
                f"--tool-offset: '{text}' is not x,y,z [m] or x,y,z,roll,pitch,yaw [m, rad]"
            )
        xyz = (values[0], values[1], values[2])
        rpy = (values[3], values[4], values[5]) if len(values) == 6 else (0.0, 0.0, 0.0)
        return cls(xyz, rpy)

    @property
    def flange_T_tcp(self) -> Array:
        t = np.eye(4)
        t[:3, :3] = tf.rpy_to_matrix(*self.rpy_rad)
        t[:3, 3] = self.xyz_m
        return t

    def describe(self) -> str:
        """How the report names the TCP."""
        if self.xyz_m == (0.0, 0.0, 0.0) and self.rpy_rad == (0.0, 0.0, 0.0):
            return f"the flange (`{FLANGE}`)"
        xyz = ", ".join(f"{v * 1000:g}" for v in self.xyz_m)
        rpy = ", ".join(f"{v:g}" for v in self.rpy_rad)
        return f"`{FLANGE}` offset by ({xyz}) mm, rpy ({rpy}) rad"


FLANGE_TOOL = ToolOffset()


@dataclass(frozen=True)
class _Chain:
    """The batched-FK data of one Pinocchio model: per joint its parent, placement, q index
    and the robot's joint (axis, kind); the flange frame's parent joint and placement."""

    parents: tuple[int, ...]
    placements: tuple[Array, ...]
    q_index: tuple[int, ...]
    joint_names: tuple[str, ...]
    joints: tuple[JointSpec | None, ...]
    flange_joint: int
    flange_placement: Array


@functools.lru_cache(maxsize=64)
def _chain(spec: RobotSpec) -> _Chain:
    # here, not at the top: importing this module (the report reads its types) loads no engine
    from pipeline.robots.urdf import pinocchio_model

    model = pinocchio_model(spec)
    by_name = {j.name: j for j in spec.joints}
    names = [str(model.names[k]) for k in range(1, model.njoints)]
    if sorted(names) != sorted(by_name) or any(
        model.joints[k].nq != 1 for k in range(1, model.njoints)
    ):
        raise ReportError(
            f"{spec.source}: the Pinocchio model's joints ({', '.join(names)}) are not the "
            f"robot's one-variable joints ({', '.join(by_name)})"
        )
    frame = model.frames[model.getFrameId(FLANGE)]
    return _Chain(
        parents=tuple(int(model.parents[k]) for k in range(model.njoints)),
        placements=tuple(
            np.array(model.jointPlacements[k].homogeneous) for k in range(model.njoints)
        ),
        q_index=tuple(int(model.joints[k].idx_q) for k in range(model.njoints)),
        joint_names=tuple(names),
        joints=(None, *(by_name[name] for name in names)),
        flange_joint=int(frame.parentJoint),
        flange_placement=np.array(frame.placement.homogeneous),
    )


@dataclass(frozen=True)
class TaskSpace:
    """The FK of one robot with a tool offset.

    Attributes:
        spec: the robot (as the recording carries it).
        tool: the TCP in the flange frame.
    """

    spec: RobotSpec
    tool: ToolOffset = FLANGE_TOOL

    @property
    def joint_names(self) -> tuple[str, ...]:
        return _chain(self.spec).joint_names

    def tcp_poses(self, q_rad: Array) -> Array:
        """``world_T_tcp`` for each row of ``q_rad`` ((N, n) in the model's joint order):
        (N, 4, 4) [m]."""
        ch = _chain(self.spec)
        q = np.asarray(q_rad, dtype=float).reshape(-1, len(ch.joint_names))
        n = q.shape[0]
        rot: list[Array] = [np.broadcast_to(np.eye(3), (n, 3, 3))]
        pos: list[Array] = [np.zeros((n, 3))]
        for k in range(1, len(ch.parents)):
            r, p = _then(rot[ch.parents[k]], pos[ch.parents[k]], ch.placements[k])
            joint = ch.joints[k]
            assert joint is not None  # the universe (k = 0) has none
            qk = q[:, ch.q_index[k]]
            if joint.kind == "prismatic":
                _, along = joint_motions(joint, qk)
                turned, p = r, p + np.einsum("nij,nj->ni", r, along)
            elif joint.axis == (0.0, 0.0, 1.0):
                # @ Rz(q): only the first two columns turn
                c, s_ = np.cos(qk)[:, None], np.sin(qk)[:, None]
                turned = np.empty_like(r)
                turned[:, :, 0] = c * r[:, :, 0] + s_ * r[:, :, 1]
                turned[:, :, 1] = c * r[:, :, 1] - s_ * r[:, :, 0]
                turned[:, :, 2] = r[:, :, 2]
            else:
                turned = r @ joint_motions(joint, qk)[0]
            rot.append(turned)
            pos.append(p)
        r, p = _then(
            rot[ch.flange_joint], pos[ch.flange_joint], ch.flange_placement @ self.tool.flange_T_tcp
        )
        out = np.zeros((n, 4, 4))
        out[:, :3, :3], out[:, :3, 3], out[:, 3, 3] = r, p, 1.0
        return out


def _then(rot: Array, pos: Array, placement: Array) -> tuple[Array, Array]:
    """(R, p) of ``world_T_a @ placement`` for a stack of ``world_T_a`` = (R, p): one GEMM
    each (a stacked 4x4 matmul per sample is several times slower)."""
    n = rot.shape[0]
    flat = rot.reshape(n * 3, 3)
    return (flat @ placement[:3, :3]).reshape(n, 3, 3), pos + (flat @ placement[:3, 3]).reshape(
        n, 3
    )


def pose_errors(reference: Array, actual: Array) -> tuple[Array, Array]:
    """Position error [mm] and orientation error [mrad] between (N, 4, 4) pose stacks."""
    dp = np.linalg.norm(reference[:, :3, 3] - actual[:, :3, 3], axis=1) * 1000.0
    rel = np.swapaxes(reference[:, :3, :3], 1, 2) @ actual[:, :3, :3]
    sin = 0.5 * np.linalg.norm(
        np.stack(
            (
                rel[:, 2, 1] - rel[:, 1, 2],
                rel[:, 0, 2] - rel[:, 2, 0],
                rel[:, 1, 0] - rel[:, 0, 1],
            ),
            axis=1,
        ),
        axis=1,
    )
    cos = 0.5 * (np.trace(rel, axis1=1, axis2=2) - 1.0)
    return dp, np.arctan2(sin, cos) * 1000.0


def _empty() -> pl.DataFrame:
    return pl.DataFrame(
        schema={
            "episode": pl.String,
            "joint": pl.String,
            "time_s": pl.Float64,
            "position_error_mm": pl.Float64,
            "orientation_error_mrad": pl.Float64,
        }
    )


def _wide(frame: pl.DataFrame, column: str, joints: Sequence[str]) -> pl.DataFrame:
    """One column per joint of ``column``, one row per time, times with every joint only."""
    out = frame.pivot(on="joint", index="time_s", values=column, aggregate_function="first")
    return out.select("time_s", *joints).drop_nulls().sort("time_s")


def _states(group: pl.DataFrame, joints: Sequence[str]) -> tuple[Array, Array, Array]:
    """(times, reference, actual) of one episode's frame, a row per time with every joint
    recorded (NaN and null rows left out): a reshape when the frame is a row per joint in
    ``joints`` order at every time (as recorded), else a pivot."""
    cols = ("reference_position_rad", "feedback_position_rad")
    n = len(joints)
    names = group.get_column("joint")
    if names.head(n).to_list() == list(joints) and joint_blocks_repeat(names, n):
        t = group.get_column("time_s").to_numpy()[::n]
        ref, act = (group.get_column(c).cast(pl.Float64).to_numpy().reshape(-1, n) for c in cols)
    else:
        sub = group.select("time_s", "joint", *cols)
        wide = [_wide(sub, c, joints) for c in cols]
        both = wide[0].join(wide[1], on="time_s", how="inner", suffix="_actual")
        t = both.get_column("time_s").to_numpy()
        ref = both.select(joints).to_numpy()
        act = both.select([f"{j}_actual" for j in joints]).to_numpy()
    keep = np.isfinite(ref).all(axis=1) & np.isfinite(act).all(axis=1)
    return t[keep], ref[keep], act[keep]


def tcp_errors(
    controller_states: pl.DataFrame, models: Mapping[str, TaskSpace] | None
) -> pl.DataFrame:
    """The TCP errors of every sample time of a (protocol-applied) ``/controller_state``
    frame, for the episodes ``models`` has a model of (columns :data:`TCP_COLUMNS`, joint
    :data:`TCP`, time order; a time with a joint missing or null is left out).

    Row-local: a time slice of the frame gives the rows of that slice.
    """
    parts = [_empty()]
    if not models or not controller_states.height:
        return parts[0]
    for (episode,), group in controller_states.group_by("episode", maintain_order=True):
        model = models.get(str(episode))
        if model is None:
            continue
        joints = model.joint_names
        if not set(joints) <= set(group.get_column("joint").unique().to_list()):
            continue
        t, ref, act = _states(group, joints)
        if not t.size:
            continue
        dp, dr = pose_errors(model.tcp_poses(ref), model.tcp_poses(act))
        parts.append(
            pl.DataFrame(
                {
                    "episode": [str(episode)] * t.size,
                    "joint": [TCP] * t.size,
                    "time_s": t,
                    "position_error_mm": dp,
                    "orientation_error_mrad": dr,
                }
            )
        )
    return pl.concat(parts, how="vertical")


def task_space_of(rec: Recording, tool: ToolOffset) -> dict[str, TaskSpace]:
    """``{episode: TaskSpace}`` when the recording carries its robot and the robot's joints
    are the recorded ones; empty (task-space metrics n/a) otherwise."""
    spec = robot_spec(rec)
    if spec is None or tuple(spec.joint_names) != tuple(rec.joint_names):
        return {}
    return {rec.episode: TaskSpace(spec, tool)}
