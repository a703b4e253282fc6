"""The arm in recording.rrd is the robot's geometry: its capsules are MuJoCo's capsule geoms."""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.model.mjcf import build_mujoco_model
from pipeline.report.rrd_scene import VIEW_HALF_ANGLE_DEG, arm_capsules, eye
from pipeline.robots import load_spec


def _endpoints_rrd(q: np.ndarray) -> set[tuple[float, ...]]:
    spec = load_spec("ur5")
    trans, quats, lengths, radii, _ = arm_capsules(spec, q[None, :])
    # Rerun's capsule runs from its origin along +Z for `length`, posed by (translation, quaternion)
    tips = trans + Rotation.from_quat(quats).apply(np.c_[np.zeros((len(lengths), 2)), lengths])
    return {
        tuple(np.round(np.r_[np.sort(np.r_[a, b].reshape(2, 3), axis=0).ravel(), r], 6))
        for a, b, r in zip(trans, tips, radii, strict=True)
    }


def _endpoints_mujoco(q: np.ndarray) -> set[tuple[float, ...]]:
    model = build_mujoco_model(load_spec("ur5"))
    data = mujoco.MjData(model)
    data.qpos[: q.size] = q
    mujoco.mj_kinematics(model, data)
    out = set()
    for g in range(model.ngeom):
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_CAPSULE or model.geom_bodyid[g] == 0:
            continue
        axis = data.geom_xmat[g].reshape(3, 3)[:, 2]
        half = model.geom_size[g][1]
        a, b = data.geom_xpos[g] - axis * half, data.geom_xpos[g] + axis * half
        r = model.geom_size[g][0]
        out.add(tuple(np.round(np.r_[np.sort(np.r_[a, b].reshape(2, 3), axis=0).ravel(), r], 6)))
    return out


def test_rrd_capsules_are_the_mujoco_capsules_at_random_poses() -> None:
    rng = np.random.default_rng(3)
    spec = load_spec("ur5")
    for _ in range(5):
        q = rng.uniform(np.maximum(spec.lower, -3), np.minimum(spec.upper, 3))
        assert _endpoints_rrd(q) == _endpoints_mujoco(q)


def test_camera_frames_every_corner_tightly() -> None:
    corners = [np.array([-1.0, -1.0, 0.0]), np.array([4.0, 1.0, 1.0])]
    position, target = eye(corners)
    np.testing.assert_allclose(target, [1.5, 0.0, 0.5])
    axis = (target - position) / np.linalg.norm(target - position)
    half = np.radians(VIEW_HALF_ANGLE_DEG)
    angles = []
    for x in (-1.0, 4.0):
        for y in (-1.0, 1.0):
            for z in (0.0, 1.0):
                ray = np.array([x, y, z]) - position
                angles.append(np.arccos(ray @ axis / np.linalg.norm(ray)))
    # every corner in view, and the farthest near the edge (the arms fill the view)
    assert max(angles) <= half
    assert max(angles) >= 0.6 * half
