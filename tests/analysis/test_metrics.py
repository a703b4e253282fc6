"""Metrics on recordings written from analytic signals with known answers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from pipeline.analysis.episodes import episode_table, limits_table
from pipeline.analysis.metrics import comparisons, joint_metrics, pairs
from pipeline.errors import ReportError
from pipeline.log.reader import Recording, read_recording
from tests.analysis.bagfactory import UR5_JOINTS, Episode, paper_like, time_grid, write_bag

N_JOINTS = len(UR5_JOINTS)


def _episode(name: str, controller: str, stamp_ns: np.ndarray, **signals: np.ndarray) -> Episode:
    zeros = np.zeros((len(stamp_ns), N_JOINTS))
    fields = {k: signals.get(k, zeros.copy()) for k in ("q", "qd", "effort", "q_ref", "qd_ref")}
    return Episode(
        episode=name,
        controller=controller,
        stamp_ns=stamp_ns,
        effort_cmd=signals.get("effort_cmd"),
        motion_end_s=float(signals["motion_end_s"]) if "motion_end_s" in signals else 1.0,
        **fields,
    )


def _metrics(recs: list[Recording]) -> pl.DataFrame:
    eps = episode_table(recs)
    return joint_metrics(
        pl.concat([r.samples for r in recs]),
        pl.concat([r.controller_states for r in recs]),
        eps,
        limits_table(recs),
    )


def _value(m: pl.DataFrame, episode: str, joint: int, column: str) -> float | None:
    row = m.filter((pl.col("episode") == episode) & (pl.col("joint") == UR5_JOINTS[joint]))
    return row.get_column(column)[0]


def test_sine_error_gives_amplitude_as_max_and_amplitude_over_root2_as_rms(
    tmp_path: Path,
) -> None:
    amplitude, hz = 2e-3, 2.0
    stamp = time_grid(2.0, period_s=1e-3)
    t = stamp / 1e9
    q = np.zeros((t.size, N_JOINTS))
    q[:, 0] = -amplitude * np.sin(2 * np.pi * hz * t)  # error = ref - q = A sin(wt)
    rec = read_recording(write_bag(tmp_path, _episode("sine", "pid", stamp, q=q)))
    m = _metrics([rec])
    assert _value(m, "sine", 0, "max_abs_error") == pytest.approx(amplitude, rel=1e-12)
    assert _value(m, "sine", 0, "rms_error") == pytest.approx(amplitude / math.sqrt(2), rel=1e-3)
    assert _value(m, "sine", 1, "max_abs_error") == 0.0


def test_peak_velocity_keeps_its_sign_and_time(tmp_path: Path) -> None:
    stamp = time_grid(2.0, period_s=1e-3)
    t = stamp / 1e9
    qd = np.zeros((t.size, N_JOINTS))
    qd[:, 3] = -2.3 * np.exp(-(((t - 1.0) / 0.1) ** 2)) + 0.5 * np.exp(-(((t - 0.5) / 0.1) ** 2))
    qd[:, 0] = 0.3 * np.sin(np.pi * t / 2.0)  # positive peak at t = 1
    rec = read_recording(write_bag(tmp_path, _episode("vel", "ctc", stamp, qd=qd)))
    m = _metrics([rec])
    assert _value(m, "vel", 3, "peak_velocity") == pytest.approx(-2.3, abs=1e-9)
    assert _value(m, "vel", 3, "peak_velocity_time") == pytest.approx(1.0)
    assert _value(m, "vel", 0, "peak_velocity") == pytest.approx(0.3, abs=1e-9)


def test_saturation_fraction_counts_samples_at_the_limit_or_clipped(tmp_path: Path) -> None:
    stamp = time_grid(0.999, period_s=1e-3)  # exactly 1000 samples
    n = stamp.size
    effort = np.full((n, N_JOINTS), 10.0)
    cmd = effort.copy()
    # Joint 1 (limit 150 N m in the ur5 spec): 25 % at +limit, 10 % at -limit,
    # 15 % commanded 200 but 100 applied; the rest unsaturated.
    effort[:250, 0] = cmd[:250, 0] = 150.0
    effort[250:350, 0] = cmd[250:350, 0] = -150.0
    effort[350:500, 0], cmd[350:500, 0] = 100.0, 200.0
    effort[:, 4] = cmd[:, 4] = 27.9  # just under wrist_2's 28 N m limit
    rec = read_recording(
        write_bag(tmp_path, _episode("sat", "pid", stamp, effort=effort, effort_cmd=cmd))
    )
    m = _metrics([rec])
    assert _value(m, "sat", 0, "saturation_fraction") == pytest.approx(0.5)
    assert _value(m, "sat", 4, "saturation_fraction") == 0.0
    assert _value(m, "sat", 4, "rms_effort") == pytest.approx(27.9)


def test_an_effort_that_lags_its_command_is_not_saturation(tmp_path: Path) -> None:
    """With an actuation delay (``loop.delay_s``) a row's effort is an earlier command:
    a growing command then exceeds it without any clipping."""
    stamp = time_grid(0.999, period_s=1e-3)
    cmd = np.tile(np.linspace(0.0, 20.0, stamp.size)[:, None], (1, N_JOINTS))
    effort = np.vstack([np.zeros((1, N_JOINTS)), cmd[:-1]])  # one row late
    rec = read_recording(
        write_bag(tmp_path, _episode("late", "pid", stamp, effort=effort, effort_cmd=cmd))
    )
    m = _metrics([rec])
    assert all(_value(m, "late", j, "saturation_fraction") == 0.0 for j in range(N_JOINTS))


def test_final_error_and_settling_time_after_the_motion_end(tmp_path: Path) -> None:
    stamp = time_grid(2.0, period_s=1e-3)
    t = stamp / 1e9
    err = np.zeros((t.size, N_JOINTS))
    after = t >= 1.0 - 1e-12
    # Joint 1: 0.01 rad until 1.3 s, then 1e-4: settles 0.3 s after the motion end (1 s).
    err[:, 0] = np.where(after & (t < 1.3 - 1e-9), 0.01, 1e-4)
    err[~after, 0] = 0.02
    err[:, 1] = 0.01  # never settles within 1e-3 rad
    err[:, 2] = np.where(t < 1.75, 5e-4, 2e-4)  # final window (last 0.5 s) mixes both
    q = -err
    rec = read_recording(write_bag(tmp_path, _episode("fin", "pid", stamp, q=q)))
    m = _metrics([rec])
    assert _value(m, "fin", 0, "settling_time") == pytest.approx(0.3, abs=1e-9)
    assert _value(m, "fin", 0, "final_error") == pytest.approx(1e-4)
    assert _value(m, "fin", 1, "settling_time") is None
    assert _value(m, "fin", 3, "settling_time") == pytest.approx(0.0)
    # Window [1.5, 2.0]: 250 samples at 5e-4 (1.5..1.749), 251 at 2e-4 (1.75..2.0).
    assert _value(m, "fin", 2, "final_error") == pytest.approx((250 * 5e-4 + 251 * 2e-4) / 501)


def test_error_at_the_target_still_decaying_is_flagged_not_settled(tmp_path: Path) -> None:
    """Joint 1 decays with a 0.2 s time constant through the final window (a transient,
    not a steady state); joint 2 holds a constant offset (stuck by friction: settled);
    joint 3 is numerical noise (below the floor: settled)."""
    from pipeline.analysis.catalog import not_settled

    stamp = time_grid(2.0, period_s=1e-3)
    t = stamp / 1e9
    err = np.zeros((t.size, N_JOINTS))
    err[:, 0] = 1e-3 * np.exp(-np.clip(t - 1.0, 0.0, None) / 0.2)
    err[:, 1] = 3e-3
    err[:, 2] = 1e-9 * np.exp(-np.clip(t - 1.0, 0.0, None) / 0.2)
    rec = read_recording(write_bag(tmp_path, _episode("tail", "pid", stamp, q=-err)))
    m = _metrics([rec]).with_columns(flag=not_settled(pl.col("final_error"), pl.col("final_drift")))
    early = (t >= 1.5 - 1e-9) & (t < 1.75 - 1e-9)
    late = t >= 1.75 - 1e-9
    drift = err[late, 0].mean() - err[early, 0].mean()
    assert _value(m, "tail", 0, "final_drift") == pytest.approx(drift, rel=1e-9)
    assert drift < -0.5 * _value(m, "tail", 0, "final_error")
    assert [_value(m, "tail", j, "flag") for j in range(3)] == [True, False, False]
    assert _value(m, "tail", 1, "final_drift") == pytest.approx(0.0, abs=1e-15)


def test_final_window_is_half_the_hold_when_the_hold_is_short(tmp_path: Path) -> None:
    stamp = time_grid(1.2, period_s=1e-3)
    t = stamp / 1e9
    err = np.zeros((t.size, N_JOINTS))
    err[:, 0] = np.where(t < 1.1 - 1e-9, 1e-2, 3e-5)  # hold 0.2 s -> window 0.1 s
    rec = read_recording(write_bag(tmp_path, _episode("short", "pid", stamp, q=-err)))
    assert _value(_metrics([rec]), "short", 0, "final_error") == pytest.approx(3e-5)


def test_overshoot_is_measured_past_the_goal_in_the_direction_of_travel(tmp_path: Path) -> None:
    stamp = time_grid(2.0, period_s=1e-3)
    t = stamp / 1e9
    s = np.clip(t, 0.0, 1.0)
    q_ref = np.zeros((t.size, N_JOINTS))
    q_ref[:, 0] = s
    q_ref[:, 1] = -0.5 * s
    q = q_ref.copy()
    bump = np.exp(-(((t - 1.2) / 0.05) ** 2))
    q[:, 0] += 0.02 * bump
    q[:, 1] -= 0.03 * bump
    q[:, 2] = 0.01 * bump  # joint 3 does not move: no overshoot defined
    rec = read_recording(write_bag(tmp_path, _episode("over", "pid", stamp, q=q, q_ref=q_ref)))
    m = _metrics([rec])
    assert _value(m, "over", 0, "overshoot") == pytest.approx(0.02, rel=1e-9)
    assert _value(m, "over", 1, "overshoot") == pytest.approx(0.03, rel=1e-9)
    assert _value(m, "over", 2, "overshoot") is None


def test_metrics_agree_with_a_direct_numpy_computation(tmp_path: Path) -> None:
    ep = paper_like("np", "pid", duration_s=3.0, motion_end_s=2.0, error_scale=2e-3)
    rec = read_recording(write_bag(tmp_path, ep))
    m = _metrics([rec])
    err = ep.q_ref - ep.q
    t = ep.stamp_ns / 1e9
    final = t >= 3.0 - 0.5 - 1e-9
    for j in range(N_JOINTS):
        peak = np.argmax(np.abs(ep.qd[:, j]))
        assert _value(m, "np", j, "max_abs_error") == pytest.approx(np.abs(err[:, j]).max())
        assert _value(m, "np", j, "rms_error") == pytest.approx(np.sqrt(np.mean(err[:, j] ** 2)))
        assert _value(m, "np", j, "final_error") == pytest.approx(np.abs(err[final, j]).mean())
        assert _value(m, "np", j, "peak_velocity") == ep.qd[peak, j]
        rms_effort = np.sqrt(np.mean(ep.effort[:, j] ** 2))
        assert _value(m, "np", j, "rms_effort") == pytest.approx(rms_effort)


# --- comparisons ------------------------------------------------------------------------------


def _sine_episode(
    name: str, controller: str, amplitude: float, *, scenario: str, status: str = "ok"
) -> Episode:
    stamp = time_grid(1.0, period_s=1e-3)
    t = stamp / 1e9
    q = np.zeros((t.size, N_JOINTS))
    q[:, 0] = -amplitude * np.sin(2 * np.pi * 2.0 * t)  # max |e| = A on the grid
    ep = _episode(name, controller, stamp, q=q)
    ep.scenario = scenario
    ep.status = status
    ep.reason = "" if status == "ok" else "joint velocity above 100 rad/s"
    return ep


@pytest.fixture(scope="module")
def compared(tmp_path_factory: pytest.TempPathFactory) -> tuple[pl.DataFrame, pl.DataFrame]:
    root = tmp_path_factory.mktemp("cmp")
    eps = [
        _sine_episode("s1_pid", "pid", 2e-3, scenario="s1"),
        _sine_episode("s1_ctc", "ctc", 1e-3, scenario="s1"),
        _sine_episode("s1_lqr", "lqr", 3e-3, scenario="s1"),
        _sine_episode("s1_bad", "ctc2", 1e-3, scenario="s1", status="diverged"),
        _sine_episode("s2_ctc", "ctc", 1e-3, scenario="s2"),
    ]
    recs = [read_recording(write_bag(root, e)) for e in eps]
    table = episode_table(recs)
    return table, comparisons(_metrics(recs), table, baseline="pid")


def test_pairs_share_a_scenario_and_skip_failed_episodes(
    compared: tuple[pl.DataFrame, pl.DataFrame],
) -> None:
    table, _ = compared
    assert pairs(table, baseline="pid") == [("s1", "s1_pid", "s1_ctc"), ("s1", "s1_pid", "s1_lqr")]


def test_reduction_is_relative_to_the_baseline(
    compared: tuple[pl.DataFrame, pl.DataFrame],
) -> None:
    _, cmp = compared
    j1 = cmp.filter(pl.col("joint") == UR5_JOINTS[0]).sort("candidate")
    # ctc halves the error: +50 %; lqr has 1.5x the error: -50 %.
    assert j1.get_column("max_abs_error_reduction_pct").to_list() == pytest.approx([50.0, -50.0])
    assert j1.get_column("rms_error_reduction_pct").to_list() == pytest.approx([50.0, -50.0])


def test_reduction_against_a_zero_baseline_is_null(
    compared: tuple[pl.DataFrame, pl.DataFrame],
) -> None:
    _, cmp = compared
    j2 = cmp.filter(pl.col("joint") == UR5_JOINTS[1])
    assert j2.height == 2
    assert j2.get_column("max_abs_error_reduction_pct").null_count() == 2


def test_unknown_baseline_lists_the_controllers_present(
    compared: tuple[pl.DataFrame, pl.DataFrame],
) -> None:
    from pipeline.analysis.metrics import check_baseline

    table, _ = compared
    with pytest.raises(
        ReportError, match=r"unknown baseline controller 'mpc'.*ctc, ctc2, lqr, pid"
    ):
        check_baseline(table, "mpc")


def test_a_paired_topic_column_reaches_the_metric_frames_from_the_topic_rows() -> None:
    """A metric may read any column a topic row pairs with the controller state
    (:data:`pipeline.log.topics.PAIRED_COLUMNS`): frames made without it (not by the
    reader) get it as nulls, frames with it keep it as recorded."""
    from pipeline.analysis.metrics import _prepared_controller_states, _prepared_joint_states
    from pipeline.log.topics import PAIRED_COLUMNS, TOPICS

    assert set(PAIRED_COLUMNS) == {c for t in TOPICS for c in (t.paired or {})}
    times = [0.0, 0.5, 1.0]
    base = {"episode": ["e"] * 3, "joint": ["j1"] * 3, "time_s": times}
    samples = pl.DataFrame(
        base
        | {"velocity_rad_s": [0.0] * 3, "effort_nm": [1.0] * 3, "commanded_effort_nm": [1.0] * 3}
    )
    states = pl.DataFrame(
        base
        | {"error_rad": [0.0] * 3, "reference_position_rad": [0.0] * 3}
        | {"feedback_position_rad": [0.0] * 3}
    )
    table = pl.DataFrame(
        {"episode": ["e"], "motion_end_s": [0.5], "end_s": [1.0], "motion_completed": [True]}
    )
    prepared = (
        _prepared_joint_states(samples, None),
        _prepared_controller_states(states, table, settling_tolerance_rad=1e-3, final_window_s=0.5),
    )
    for frame in prepared:
        for column in PAIRED_COLUMNS:
            assert frame.schema[column] == pl.Float64, column
            assert frame.get_column(column).null_count() == frame.height, column
    recorded = samples.with_columns(true_velocity_rad_s=pl.Series([3.0, -4.0, 1.0]))
    peak = _prepared_joint_states(recorded, None).select(pl.col("true_velocity_rad_s").abs().max())
    assert peak.item() == 4.0
