"""Task-space (TCP) metrics against an independent FK of the bag's states.

The bag is written by an independent writer from known joint arrays; the check evaluates
Pinocchio's own per-sample ``framesForwardKinematics`` (not the batched FK the metrics use)
on those arrays, with the tool offset added as a Pinocchio frame, and MuJoCo's flange site.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import polars as pl
import pytest

from pipeline.analysis.episodes import episode_table, limits_table
from pipeline.analysis.metrics import finish_metrics, joint_metrics, metric_partials
from pipeline.analysis.protocol import protocol_view
from pipeline.analysis.task_space import TCP, TaskSpace, ToolOffset, task_space_of
from pipeline.constants import FINAL_WINDOW_S
from pipeline.log.reader import read_recording
from pipeline.model.mjcf import build_mjcf
from pipeline.robots import load_spec
from pipeline.robots.chain import FLANGE
from pipeline.robots.urdf import build_urdf
from tests.analysis.bagfactory import Episode, paper_like, write_bag

TOL_M = 1e-9


def _independent_errors(ep: Episode, tool: ToolOffset) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample position error [m] and orientation error [rad] by Pinocchio directly."""
    model = pin.buildModelFromXML(build_urdf(load_spec("ur5")))
    flange = model.getFrameId(FLANGE)
    placement = pin.SE3(tool.flange_T_tcp)
    tcp = model.addFrame(
        pin.Frame(
            "tcp",
            model.frames[flange].parentJoint,
            model.frames[flange].placement * placement,
            pin.FrameType.OP_FRAME,
        )
    )
    data = model.createData()
    dp, dr = [], []
    actual = ep.q if ep.q_true is None else ep.q_true
    for q_ref, q in zip(ep.q_ref, actual, strict=True):
        pin.framesForwardKinematics(model, data, q_ref)
        ref = data.oMf[tcp].copy()
        pin.framesForwardKinematics(model, data, q)
        now = data.oMf[tcp]
        dp.append(np.linalg.norm(ref.translation - now.translation))
        dr.append(np.linalg.norm(pin.log3(ref.rotation.T @ now.rotation)))
    return np.array(dp), np.array(dr)


def _metrics(path: Path, tool: ToolOffset) -> pl.DataFrame:
    rec = read_recording(path)
    view, _ = protocol_view(rec)
    r = view.recording
    row = episode_table([r], {r.episode: view})
    return joint_metrics(
        r.samples,
        r.controller_states,
        row,
        limits_table([r]),
        task_space=task_space_of(r, tool),
    )


@pytest.mark.parametrize(
    "tool",
    [ToolOffset(), ToolOffset((0.02, -0.01, 0.15), (0.1, -0.2, 0.3))],
    ids=["flange", "offset"],
)
def test_tcp_errors_equal_pinocchio_fk_of_the_bags_states(tmp_path: Path, tool: ToolOffset) -> None:
    ep = paper_like("e1", "pid", error_scale=5e-3)
    m = _metrics(write_bag(tmp_path, ep), tool).filter(pl.col("joint") == TCP).row(0, named=True)
    dp, dr = _independent_errors(ep, tool)
    t = ep.stamp_ns / 1e9
    final = t >= t[-1] - min(FINAL_WINDOW_S, (t[-1] - ep.motion_end_s) / 2) - 1e-9
    assert dp.max() > 1e-4  # a real error, not two zeros
    assert m["tcp_max_position_error"] / 1000 == pytest.approx(dp.max(), abs=TOL_M)
    assert m["tcp_rms_position_error"] / 1000 == pytest.approx(np.sqrt(np.mean(dp**2)), abs=TOL_M)
    assert m["tcp_final_position_error"] / 1000 == pytest.approx(dp[final].mean(), abs=TOL_M)
    assert m["tcp_max_orientation_error"] / 1000 == pytest.approx(dr.max(), abs=1e-9)
    assert m["tcp_rms_orientation_error"] / 1000 == pytest.approx(np.sqrt(np.mean(dr**2)), abs=1e-9)
    assert m["tcp_final_orientation_error"] / 1000 == pytest.approx(dr[final].mean(), abs=1e-9)


def test_the_tcp_without_offset_is_mujocos_flange_site() -> None:
    spec = load_spec("ur5")
    model = mujoco.MjModel.from_xml_string(build_mjcf(spec))
    data = mujoco.MjData(model)
    site = model.site(FLANGE).id
    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, (20, spec.dof))
    poses = TaskSpace(spec).tcp_poses(q)
    for k in range(q.shape[0]):
        data.qpos[: spec.dof] = q[k]
        mujoco.mj_kinematics(model, data)
        np.testing.assert_allclose(poses[k, :3, 3], data.site_xpos[site], atol=TOL_M)


def test_tcp_metrics_of_time_slices_equal_the_whole_read(tmp_path: Path) -> None:
    ep = paper_like("e1", "pid", error_scale=5e-3)
    rec = read_recording(write_bag(tmp_path, ep))
    view, _ = protocol_view(rec)
    r = view.recording
    row = episode_table([r], {r.episode: view})
    ts = task_space_of(r, ToolOffset())
    whole = joint_metrics(r.samples, r.controller_states, row, task_space=ts)
    t = pl.col("time_s")
    parts = [
        metric_partials(
            r.samples.filter((t >= lo) & (t < hi)),
            r.controller_states.filter((t >= lo) & (t < hi)),
            row,
            task_space=ts,
        )
        for lo, hi in ((-1.0, 0.7), (0.7, 0.71), (0.71, 2.5), (2.5, 99.0))
    ]
    sliced = finish_metrics(pl.concat(parts, how="vertical_relaxed"))
    a = whole.filter(pl.col("joint") == TCP).row(0, named=True)
    b = sliced.filter(pl.col("joint") == TCP).row(0, named=True)
    for key, value in a.items():
        if key.startswith("tcp_"):
            assert b[key] == pytest.approx(value, rel=1e-12), key


def test_a_bag_without_our_robot_has_no_tcp_row(tmp_path: Path) -> None:
    ep = paper_like("e1", "pid")
    ep.episode_metadata = False
    rec = read_recording(write_bag(tmp_path, ep))
    assert task_space_of(rec, ToolOffset()) == {}
    m = _metrics(write_bag(tmp_path / "again", ep), ToolOffset())
    assert TCP not in m.get_column("joint").to_list()
