"""The 3D scene of recording.rrd: each episode's arm (the robot's capsules posed by FK of
the recorded joints; a URDF robot's meshes, :mod:`pipeline.report.rrd_meshes`), on its own
base, and the camera that frames them all."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from pipeline.analysis.episodes import robot_spec
from pipeline.analysis.measure import times_s, wide
from pipeline.log.reader import Recording
from pipeline.model.dh import link_frames
from pipeline.report import entities as ent
from pipeline.report.rrd_meshes import LinkMeshes, link_meshes, send_link_meshes
from pipeline.robots import RobotSpec
from pipeline.robots.chain import chain

ARM_RATE_HZ = 30.0
# Episodes stand this far apart in the 3D view [m] (a UR5 reaches ~0.85 m).
SPACING_M = 1.6
# A group's episodes stand in rows of at most this many (a narrow 3D panel fits a squarish
# block of arms better than one long row).
ROW_LENGTH = 3
# Every other episode's label sits this much lower [m], so neighbours' labels stay apart.
LABEL_STAGGER_M = 0.3
# The 3D camera looks at the arms from this side (x right, -y front, z up) ...
VIEW_DIRECTION = (0.2, -1.0, 0.55)
# ... and fits them within this angle of its axis [deg] (Rerun's default field of view is
# 55 deg high; a narrow panel sees less across, hence the margin) ...
VIEW_HALF_ANGLE_DEG = 22.0
# ... with this much room around them.
FRAME_MARGIN = 1.05


def z_to(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quaternions (x, y, z, w) turning +Z onto each row of unit vectors ``v``."""
    z = np.array([0.0, 0.0, 1.0])
    q = np.concatenate([np.cross(z, v), 1.0 + v @ z[:, None]], axis=1)
    flip = q[:, 3] < 1e-9  # v = -Z: half a turn about X
    q[flip] = [1.0, 0.0, 0.0, 0.0]
    out: NDArray[np.float64] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return out


def arm_capsules(
    spec: RobotSpec, q: NDArray[np.float64]
) -> tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float32],
    NDArray[np.float64],
]:
    """Link capsules in world (robot base) coordinates for each row of ``q``.

    Returns:
        translations (F*S, 3), quaternions (F*S, 4), lengths (F*S,), radii (F*S,) and the
        flange positions (F, 3); S segments per frame.
    """
    links = chain(spec)
    segs = [
        (i, s)
        for i, link in enumerate(links)
        for s in link.segments
        if np.linalg.norm(np.subtract(s.end, s.start)) > 1e-9
    ]
    starts = np.array([[*s.start, 1.0] for _, s in segs]).reshape(-1, 4)
    ends = np.array([[*s.end, 1.0] for _, s in segs]).reshape(-1, 4)
    owner = [i for i, _ in segs]
    radii = np.array([s.radius for _, s in segs], dtype=np.float32)
    a = np.empty((q.shape[0], len(segs), 3))
    b = np.empty_like(a)
    flange = np.empty((q.shape[0], 3))
    for f, qf in enumerate(q):
        frames = link_frames(spec, qf)
        for k, i in enumerate(owner):
            a[f, k] = (frames[i] @ starts[k])[:3]
            b[f, k] = (frames[i] @ ends[k])[:3]
        flange[f] = frames[-1][:3, 3]
    starts_w, ends_w = a.reshape(-1, 3), b.reshape(-1, 3)
    lengths = np.linalg.norm(ends_w - starts_w, axis=1)
    quats = z_to((ends_w - starts_w) / lengths[:, None])
    return starts_w, quats, lengths, np.tile(radii, q.shape[0]), flange


@dataclass(frozen=True)
class Arm:
    """An episode's arm, posed at :data:`ARM_RATE_HZ`, on its own base."""

    episode: str
    offset: NDArray[np.float64]
    label: str
    label_z_m: float
    color: tuple[int, int, int]
    t: NDArray[np.float64]
    translations: NDArray[np.float64]
    quaternions: NDArray[np.float64]
    lengths: NDArray[np.float64]
    radii: NDArray[np.float32]
    flange: NDArray[np.float64]
    meshes: LinkMeshes | None = None  # a URDF robot's, drawn instead of the capsules

    def corners(self) -> list[NDArray[np.float64]]:
        """Two corners of a box around everything drawn for it, in world coordinates."""
        pts = np.vstack([self.translations, self.flange, [[0.0, 0.0, self.label_z_m]]])
        pad = float(self.radii.max()) if self.radii.size else 0.0
        return [pts.min(axis=0) - pad + self.offset, pts.max(axis=0) + pad + self.offset]


def make_arm(
    rec: Recording,
    color: tuple[int, int, int],
    *,
    offset: NDArray[np.float64],
    label: str,
    label_z_m: float,
) -> Arm | None:
    """The episode's arm (None: no robot spec or no samples)."""
    spec = robot_spec(rec)
    if spec is None or spec.joint_names != rec.joint_names:
        return None
    t = times_s(rec)
    if t.size == 0:
        return None
    wanted = np.arange(t[0], t[-1], 1.0 / ARM_RATE_HZ)
    idx = np.unique(np.append(np.searchsorted(t, wanted).clip(0, t.size - 1), t.size - 1))
    q = wide(rec, "position_rad")[idx]
    if not np.isfinite(q).all():
        q = np.nan_to_num(q)
    trans, quats, lengths, radii, flange = arm_capsules(spec, q)
    if lengths.size // max(idx.size, 1) == 0:
        return None
    return Arm(rec.episode, offset, label, label_z_m, color, t[idx], trans, quats, lengths,
                radii, flange, link_meshes(spec, q))  # fmt: skip


def send_arm(stream: rr.RecordingStream, arm: Arm) -> None:
    """Draw the episode's arm on its own base, with its flange path and its label."""
    root = ent.episode_root(arm.episode)
    stream.log(root, rr.Transform3D(translation=arm.offset.tolist()), static=True)
    per_frame = arm.lengths.size // arm.t.size
    if arm.meshes is not None and arm.meshes.geometry:
        send_link_meshes(stream, arm.episode, arm.t, arm.meshes, arm.color)
    else:
        _send_capsules(stream, arm, per_frame)
        if arm.meshes is not None and arm.meshes.note:  # why the meshes are not drawn
            send_link_meshes(stream, arm.episode, arm.t, arm.meshes, arm.color)
    stream.log(
        ent.ee_path_path(arm.episode),
        rr.LineStrips3D([arm.flange], radii=[0.004], colors=[arm.color]),
        static=True,
    )
    stream.log(
        ent.label_path(arm.episode),
        rr.Points3D(
            [[0.0, 0.0, arm.label_z_m]], radii=[0.02], colors=[arm.color], labels=[arm.label]
        ),
        static=True,
    )


def _send_capsules(stream: rr.RecordingStream, arm: Arm, per_frame: int) -> None:
    stream.send_columns(
        ent.arm_path(arm.episode),
        indexes=[rr.TimeColumn(ent.TIMELINE, duration=arm.t)],
        columns=rr.Capsules3D.columns(
            translations=arm.translations,
            quaternions=arm.quaternions,
            lengths=arm.lengths,
            radii=arm.radii,
            colors=np.tile(np.array(arm.color, dtype=np.uint8), (arm.lengths.size, 1)),
        ).partition(lengths=[per_frame] * arm.t.size),
    )


def offset(row: int, column: int) -> NDArray[np.float64]:
    """An episode's base: rows :data:`SPACING_M` apart, front to back, and so are the
    episodes in a row."""
    return np.array([column * SPACING_M, -row * SPACING_M, 0.0])


def eye(points: list[NDArray[np.float64]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A camera that frames every arm (``points``: corners of what is drawn): looking at
    the centre of their box from the front-right and above (:data:`VIEW_DIRECTION`), just
    far enough for every corner of the box to be inside :data:`VIEW_HALF_ANGLE_DEG` of
    the view's axis, sideways and up-down."""
    if not points:
        return np.array([2.0, -2.0, 1.5]), np.zeros(3)
    allp = np.vstack(points)
    low, high = allp.min(axis=0), allp.max(axis=0)
    centre = (low + high) / 2
    back = np.asarray(VIEW_DIRECTION, dtype=np.float64)
    back /= np.linalg.norm(back)  # from the target towards the camera
    right = np.cross(back, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, back)
    tan = np.tan(np.radians(VIEW_HALF_ANGLE_DEG))
    box = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                    for z in (low[2], high[2])]) - centre  # fmt: skip
    # a corner p is in view from distance D when max(|p.right|, |p.up|) <= (D - p.back) tan
    need = box @ back + np.maximum(np.abs(box @ right), np.abs(box @ up)) / tan
    distance = max(float(need.max()) * FRAME_MARGIN, 0.5)
    return centre + back * distance, centre
