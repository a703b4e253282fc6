"""Metrics where recordings are unusual: cut short, missing arrays, wall-clock stamps,
decimated /joint_states, near-zero baselines, rows out of order.

Expected values are computed here with numpy from the arrays written into the recording.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import polars as pl
import pytest

from pipeline.analysis.episodes import episode_table, limits_table
from pipeline.analysis.metrics import (
    ERROR_FLOOR_RAD,
    METRIC_COLUMNS,
    comparisons,
    joint_metrics,
    reduction_pct,
)
from pipeline.log.reader import Recording, read_recording
from tests.analysis.bagfactory import UR5_JOINTS, Episode, paper_like, write_bag

N_JOINTS = len(UR5_JOINTS)


def _metrics(recs: list[Recording]) -> pl.DataFrame:
    return joint_metrics(
        pl.concat([r.samples for r in recs]),
        pl.concat([r.controller_states for r in recs]),
        episode_table(recs),
        limits_table(recs),
    )


def _row(m: pl.DataFrame, episode: str, joint: int) -> dict:
    return m.filter((pl.col("episode") == episode) & (pl.col("joint") == UR5_JOINTS[joint])).row(
        0, named=True
    )


def _cut(ep: Episode, end_s: float) -> Episode:
    """The episode's first ``end_s`` seconds only (the recording stops early)."""
    keep = ep.stamp_ns <= round(end_s * 1e9)
    for name in ("stamp_ns", "q", "qd", "effort", "q_ref", "qd_ref"):
        setattr(ep, name, getattr(ep, name)[keep])
    return ep


# --- 1: episodes that end before the motion does -----------------------------------------


@pytest.mark.parametrize("status", ["ok", "diverged"])
def test_episode_ending_before_the_motion_end_gets_no_final_error_settling_or_overshoot(
    tmp_path: Path, status: str
) -> None:
    ep = _cut(paper_like("cut", "pid", duration_s=3.0, motion_end_s=2.0, error_scale=5e-2), 0.8)
    ep.status = status
    rec = read_recording(write_bag(tmp_path, ep))
    m = _metrics([rec])
    err = ep.q_ref - ep.q
    assert episode_table([rec]).get_column("motion_completed").to_list() == [False]
    for j in range(N_JOINTS):
        row = _row(m, "cut", j)
        assert row["final_error"] is None
        assert row["settling_time"] is None
        assert row["overshoot"] is None
        # What exists still counts.
        assert row["max_abs_error"] == pytest.approx(np.abs(err[:, j]).max())
        assert row["rms_error"] == pytest.approx(np.sqrt(np.mean(err[:, j] ** 2)))


def test_diverged_episode_that_ran_past_the_motion_end_gets_no_final_error(tmp_path: Path) -> None:
    ep = paper_like("div", "pid", duration_s=3.0, motion_end_s=2.0)
    ep.status, ep.reason = "diverged", "joint velocity above 50 rad/s"
    m = _metrics([read_recording(write_bag(tmp_path, ep))])
    row = _row(m, "div", 0)
    assert row["final_error"] is None and row["settling_time"] is None
    assert row["max_abs_error"] == pytest.approx(np.abs(ep.q_ref - ep.q)[:, 0].max())


def test_complete_episode_keeps_final_error_from_the_last_window(tmp_path: Path) -> None:
    ep = paper_like("full", "pid", duration_s=3.0, motion_end_s=2.0)
    rec = read_recording(write_bag(tmp_path, ep))
    t = ep.stamp_ns / 1e9
    final = t >= 2.5 - 1e-9
    assert episode_table([rec]).get_column("motion_completed").to_list() == [True]
    row = _row(_metrics([rec]), "full", 1)
    assert row["final_error"] == pytest.approx(np.abs(ep.q_ref - ep.q)[final, 1].mean())


# --- 2: arrays not recorded ------------------------------------------------------------------


def test_empty_velocity_and_effort_arrays_give_null_metrics_not_nan(tmp_path: Path) -> None:
    ep = paper_like("novel", "pid", duration_s=1.0, motion_end_s=0.5)
    ep.empty_joint_state_fields = ("velocity", "effort")
    rec = read_recording(write_bag(tmp_path, ep))
    assert rec.samples.get_column("velocity_rad_s").null_count() == rec.samples.height
    assert rec.samples.get_column("effort_nm").is_nan().sum() == 0
    m = _metrics([rec])
    for j in range(N_JOINTS):
        row = _row(m, "novel", j)
        for key in ("peak_velocity", "peak_velocity_time", "rms_effort", "saturation_fraction"):
            assert row[key] is None, key
        assert row["max_abs_error"] == pytest.approx(np.abs(ep.q_ref - ep.q)[:, j].max())
    assert any("no effort values" in note for note in rec.notes)
    assert any("no velocity values" in note for note in rec.notes)


# --- 3: wall-clock stamps --------------------------------------------------------------------


def test_wall_clock_stamps_give_the_same_metrics_as_simulated_ones(tmp_path: Path) -> None:
    sim = paper_like("sim", "pid", duration_s=3.0, motion_end_s=2.0, error_scale=5e-3)
    wall = paper_like("wall", "pid", duration_s=3.0, motion_end_s=2.0, error_scale=5e-3)
    wall.stamp_ns = wall.stamp_ns + 1_700_000_000_123_456_789
    recs = [read_recording(write_bag(tmp_path, e)) for e in (sim, wall)]
    rec_wall = recs[1]
    assert rec_wall.samples.get_column("time_s").min() == 0.0
    np.testing.assert_array_equal(
        rec_wall.samples.get_column("stamp_ns").to_numpy()[::N_JOINTS], wall.stamp_ns
    )
    table = episode_table(recs)
    assert table.get_column("end_s").to_list() == pytest.approx([3.0, 3.0])
    m = _metrics(recs)
    t = sim.stamp_ns / 1e9
    for j in range(N_JOINTS):
        a, b = _row(m, "sim", j), _row(m, "wall", j)
        for key in METRIC_COLUMNS:
            if a[key] is None:
                assert b[key] is None, key
            else:
                assert b[key] == pytest.approx(a[key], rel=1e-9, abs=1e-12), key
        assert b["peak_velocity_time"] == pytest.approx(t[np.argmax(np.abs(wall.qd[:, j]))])
    assert _row(m, "wall", 2)["settling_time"] is not None


# --- 7: decimated /joint_states ---------------------------------------------------------------


def test_error_metrics_use_every_controller_state_when_joint_states_are_decimated(
    tmp_path: Path,
) -> None:
    ep = paper_like("dec", "pid", duration_s=2.0, motion_end_s=1.0, period_s=1e-3)
    ep.joint_state_every = 10
    # A spike the decimated /joint_states never see (sample 1503 is not a multiple of 10).
    ep.q[1503, 2] -= 0.05
    rec = read_recording(write_bag(tmp_path, ep))
    assert rec.samples.height * 10 == pytest.approx(rec.controller_states.height, abs=60)
    m = _metrics([rec])
    err = ep.q_ref - ep.q
    t = ep.stamp_ns / 1e9
    final = t >= 2.0 - 0.5 - 1e-9
    for j in range(N_JOINTS):
        row = _row(m, "dec", j)
        assert row["max_abs_error"] == pytest.approx(np.abs(err[:, j]).max())
        assert row["rms_error"] == pytest.approx(np.sqrt(np.mean(err[:, j] ** 2)))
        assert row["final_error"] == pytest.approx(np.abs(err[final, j]).mean())
        # Velocity metrics from the /joint_states that exist (every 10th sample).
        qd = ep.qd[::10, j]
        assert row["peak_velocity"] == qd[np.argmax(np.abs(qd))]
    assert _row(m, "dec", 2)["max_abs_error"] > 0.049  # the spike, seen at the full rate


# --- 8: reductions against noise -------------------------------------------------------------


def test_reduction_against_a_baseline_below_the_noise_floor_is_null() -> None:
    frame = pl.DataFrame(
        {"b": [1e-13, -5e-10, 2e-9, 4e-3, None], "c": [1e-4, 1e-4, 1e-9, 1e-3, 1.0]}
    )
    got = frame.select(reduction_pct(pl.col("b"), pl.col("c"))).to_series().to_list()
    assert got[:2] == [None, None]
    assert got[2] == pytest.approx((2e-9 - 1e-9) / 2e-9 * 100)
    assert got[3] == pytest.approx(75.0)
    assert got[4] is None
    assert ERROR_FLOOR_RAD == 1e-9


def test_comparisons_with_a_near_perfect_baseline_give_null_not_huge_percentages(
    tmp_path: Path,
) -> None:
    perfect = paper_like("ctc", "ctc", duration_s=1.0, motion_end_s=0.5, error_scale=0.0)
    perfect.q = perfect.q_ref + 1e-13  # numerical noise only
    pid = paper_like("pid", "pid", duration_s=1.0, motion_end_s=0.5, error_scale=2e-3)
    recs = [read_recording(write_bag(tmp_path, e)) for e in (perfect, pid)]
    cmp = comparisons(_metrics(recs), episode_table(recs), baseline="ctc")
    for key in ("max_abs_error", "rms_error", "final_error"):
        assert cmp.get_column(f"{key}_reduction_pct").null_count() == cmp.height


# --- 12: row order -----------------------------------------------------------------------------


def test_metrics_do_not_depend_on_row_order(tmp_path: Path) -> None:
    eps = [
        paper_like("a", "pid", duration_s=1.5, motion_end_s=1.0, error_scale=3e-3, seed=1),
        paper_like("b", "ctc", duration_s=1.5, motion_end_s=1.0, error_scale=1e-3, seed=2),
    ]
    recs = [read_recording(write_bag(tmp_path, e)) for e in eps]
    samples = pl.concat([r.samples for r in recs])
    states = pl.concat([r.controller_states for r in recs])
    table, limits = episode_table(recs), limits_table(recs)
    ordered = joint_metrics(samples, states, table, limits).sort("episode", "joint")
    shuffled = joint_metrics(
        samples.sample(fraction=1.0, shuffle=True, seed=7),
        states.sample(fraction=1.0, shuffle=True, seed=8),
        table,
        limits.reverse(),
    ).sort("episode", "joint")
    assert shuffled.equals(ordered)
    # And the values are the numpy ones (the order-sensitive metrics in particular).
    t = eps[0].stamp_ns / 1e9
    for j in range(N_JOINTS):
        row = _row(ordered, "a", j)
        peak = np.argmax(np.abs(eps[0].qd[:, j]))
        assert row["peak_velocity_time"] == pytest.approx(t[peak])
