"""The reader against the project's own writer (pipeline.log.bag): exact round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.log.bag import write_episode_bag
from pipeline.log.reader import read_recording
from pipeline.robots import load_spec
from pipeline.sim.result import EpisodeResult, TrajectorySamples


def _episode(n: int) -> tuple[EpisodeResult, TrajectorySamples]:
    spec = load_spec("ur5")
    stamp = np.arange(n, dtype=np.int64) * 2_000_000
    t = stamp[:, None] * 1e-9
    w = 0.5 + 0.25 * np.arange(6)
    q_ref, qd_ref = 0.3 * np.sin(w * t), 0.3 * w * np.cos(w * t)
    rng = np.random.default_rng(1)
    q = q_ref + rng.normal(scale=1e-4, size=q_ref.shape)
    qd = qd_ref + rng.normal(scale=1e-3, size=q_ref.shape)
    tau_cmd = 20.0 * np.cos(3 * t + np.arange(6))
    tau = np.clip(tau_cmd, -15, 15)
    result = EpisodeResult(
        spec.joint_names, stamp, q, qd, q_ref, qd_ref, q_ref, qd_ref,
        -0.3 * w**2 * np.sin(w * t), tau_cmd, tau, np.abs(tau_cmd) > 15,
    )  # fmt: skip
    ts = np.linspace(0.0, stamp[-1] * 1e-9, 41)[:, None]
    planned = TrajectorySamples(
        ts[:, 0], 0.3 * np.sin(w * ts), 0.3 * w * np.cos(w * ts), -0.3 * w**2 * np.sin(w * ts)
    )
    return result, planned


def _write(path: Path, result: EpisodeResult, planned: TrajectorySamples, **kw: object) -> Path:
    meta = {
        "episode": path.name,
        "scenario": "paper",
        "controller": "ctc",
        "robot": "ur5",
        "seed": "3",
        "settings": "{}",  # none: the writer's round trip, not the recording contract
    }
    write_episode_bag(
        path, spec=load_spec("ur5"), result=result, planned=planned, metadata=meta, **kw
    )
    return path


def _wide(rec: object, column: str) -> np.ndarray:
    samples = rec.samples  # type: ignore[attr-defined]
    return samples.get_column(column).to_numpy().reshape(-1, 6)


def test_reader_returns_exactly_what_the_writer_was_given(tmp_path: Path) -> None:
    result, planned = _episode(400)
    rec = read_recording(_write(tmp_path / "rt", result, planned))
    assert rec.joint_names == load_spec("ur5").joint_names
    assert (rec.episode, rec.controller, rec.meta("seed")) == ("rt", "ctc", "3")
    np.testing.assert_array_equal(rec.samples["stamp_ns"].to_numpy()[::6], result.stamp_ns)
    np.testing.assert_array_equal(_wide(rec, "position_rad"), result.q)
    np.testing.assert_array_equal(_wide(rec, "velocity_rad_s"), result.qd)
    np.testing.assert_array_equal(_wide(rec, "effort_nm"), result.tau_nm)
    np.testing.assert_array_equal(_wide(rec, "commanded_effort_nm"), result.tau_cmd_nm)
    np.testing.assert_array_equal(_wide(rec, "reference_position_rad"), result.q_ref)
    np.testing.assert_array_equal(_wide(rec, "reference_velocity_rad_s"), result.qd_ref)
    np.testing.assert_array_equal(_wide(rec, "error_rad"), result.q_ref - result.q)
    assert rec.planned is not None
    np.testing.assert_allclose(rec.planned.times_s, planned.times_s, atol=1e-9)
    np.testing.assert_array_equal(rec.planned.positions, planned.positions)
    assert rec.robot_description is not None and "<robot" in rec.robot_description


def test_decimated_joint_states_pair_with_the_controller_state_at_the_same_stamp(
    tmp_path: Path,
) -> None:
    result, planned = _episode(300)
    rec = read_recording(_write(tmp_path / "dec", result, planned, joint_state_decimation=3))
    rows = np.arange(0, 300, 3)
    np.testing.assert_array_equal(rec.samples["stamp_ns"].to_numpy()[::6], result.stamp_ns[rows])
    np.testing.assert_array_equal(_wide(rec, "position_rad"), result.q[rows])
    np.testing.assert_array_equal(_wide(rec, "reference_position_rad"), result.q_ref[rows])
    assert rec.notes == ()
