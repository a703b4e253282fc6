"""Metrics merged over time slices equal the metrics of the whole recording.

A long bag is read window by window (:func:`metric_partials` per window, then
:func:`finish_metrics`); these tests cut real recordings (written by an independent writer,
and one simulated by ``pipeline record``) into random contiguous time slices and compare
with the one-slice result, and check hand-made frames whose answer is known by
construction.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import polars as pl
import pytest
import yaml

from pipeline.analysis.episodes import episode_table, limits_table
from pipeline.analysis.metrics import (
    METRIC_COLUMNS,
    SETTLING_TOLERANCE_RAD,
    finish_metrics,
    joint_metrics,
    metric_partials,
)
from pipeline.analysis.protocol import protocol_view
from pipeline.log.reader import read_recording
from tests.analysis.bagfactory import Episode, paper_like, write_bag

REPO = Path(__file__).parents[2]
KEY = ["episode", "joint"]
# Max, min, first and last do not round: slicing must not change them by one bit. Means
# and RMS values sum in a different order over slices (non-negative terms: ~1e-15).
EXACT = ("max_abs_error", "settling_time", "overshoot", "peak_velocity", "peak_velocity_time")
SUM_REL_TOL = 1e-12

Frames = tuple[pl.DataFrame, pl.DataFrame, pl.DataFrame, pl.DataFrame | None]


# --- slicing -------------------------------------------------------------------------------


def _slices(
    samples: pl.DataFrame, states: pl.DataFrame, cuts: Sequence[float]
) -> list[tuple[pl.DataFrame, pl.DataFrame]]:
    """Both frames cut at ``cuts`` [s]: slice k holds cuts[k-1] <= time_s < cuts[k]."""
    edges = [-math.inf, *sorted(set(cuts)), math.inf]
    t = pl.col("time_s")
    return [
        (samples.filter((t >= lo) & (t < hi)), states.filter((t >= lo) & (t < hi)))
        for lo, hi in itertools.pairwise(edges)
    ]


def _sliced_metrics(frames: Frames, cuts: Sequence[float]) -> pl.DataFrame:
    samples, states, table, limits = frames
    parts = [metric_partials(s, c, table, limits) for s, c in _slices(samples, states, cuts)]
    return finish_metrics(pl.concat(parts))


def _special_cuts(frames: Frames, rng: np.random.Generator) -> list[float]:
    """Cuts that make the awkward slices: at the motion end exactly, inside the final
    window, around one controller-state sample (a single-sample slice; no /joint_states
    row when those are decimated), and two between neighbouring samples (no row at all)."""
    _, states, table, _ = frames
    row = table.row(0, named=True)
    t_cs = np.unique(states.get_column("time_s").to_numpy())
    i = int(rng.integers(1, t_cs.size - 2))
    gap = t_cs[i + 1] - t_cs[i]
    cuts = [t_cs[i], t_cs[i + 1], t_cs[i] + gap / 3, t_cs[i] + 2 * gap / 3]
    if row["motion_end_s"] is not None:
        cuts.append(row["motion_end_s"])
        cuts.append(row["end_s"] - 0.25 * (row["end_s"] - row["motion_end_s"]))
    return cuts


def _random_cuts(frames: Frames, seed: int) -> list[float]:
    """Cuts for K in 1..50 slices: the special ones first (as many as fit), then uniform
    times over the recording and a little beyond both ends."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, 51))
    special = list(rng.permutation(_special_cuts(frames, rng)))[: k - 1]
    t = frames[1].get_column("time_s").to_numpy()
    return special + list(rng.uniform(t.min() - 0.1, t.max() + 0.1, size=k - 1 - len(special)))


def _assert_same_metrics(sliced: pl.DataFrame, whole: pl.DataFrame, what: str) -> None:
    assert sliced.height == whole.height, what
    both = whole.join(sliced, on=KEY, how="left", suffix="_sliced")
    compared = 0
    for m in METRIC_COLUMNS:
        for (ep, joint), want, got in zip(
            both.select(KEY).iter_rows(),
            both.get_column(m).to_list(),
            both.get_column(f"{m}_sliced").to_list(),
            strict=True,
        ):
            where = f"{what}: {ep} {joint} {m}"
            if want is None:
                assert got is None, where
            elif m in EXACT:
                assert got == want, where
            else:
                assert got == pytest.approx(want, rel=SUM_REL_TOL, abs=0.0), where
                compared += 1
    assert compared > 0


# --- recordings ------------------------------------------------------------------------------


def _frames_of(paths: Sequence[Path]) -> Frames:
    """The frames the report stage computes metrics from (after the protocol)."""
    views = [protocol_view(read_recording(p))[0] for p in paths]
    recs = [v.recording for v in views]
    return (
        pl.concat([r.samples for r in recs]),
        pl.concat([r.controller_states for r in recs]),
        episode_table(recs, {r.episode: v for r, v in zip(recs, views, strict=True)}),
        limits_table(recs),
    )


def _cut_short(ep: Episode, end_s: float) -> Episode:
    keep = ep.stamp_ns <= round(end_s * 1e9)
    for name in ("stamp_ns", "q", "qd", "effort", "q_ref", "qd_ref"):
        setattr(ep, name, getattr(ep, name)[keep])
    return ep


def _factory_episodes() -> dict[str, Episode]:
    # Errors large enough to leave the settling band after the motion end.
    settling = paper_like("settling", "pid", duration_s=2.5, motion_end_s=1.5, period_s=1e-3,
                          error_scale=5e-2)  # fmt: skip
    decimated = paper_like("decimated", "pid", duration_s=2.0, motion_end_s=1.0,
                           period_s=1e-3, error_scale=5e-2, seed=1)  # fmt: skip
    decimated.joint_state_every = 10
    # At wrist_2's 28 N m limit part of the time: a non-trivial saturation share.
    saturating = paper_like("saturating", "ctc", duration_s=1.5, motion_end_s=1.0, seed=2)
    saturating.effort[200:500, 4] = 28.0
    unrecorded = paper_like("unrecorded", "ctc", duration_s=1.0, motion_end_s=0.6, seed=3)
    unrecorded.empty_joint_state_fields = ("velocity", "effort")
    short = _cut_short(
        paper_like("short", "pid", duration_s=3.0, motion_end_s=2.0, error_scale=5e-2), 0.8
    )
    return {e.episode: e for e in (settling, decimated, saturating, unrecorded, short)}


@pytest.fixture(scope="module")
def factory_frames(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Frames]:
    root = tmp_path_factory.mktemp("partials")
    return {name: _frames_of([write_bag(root, ep)]) for name, ep in _factory_episodes().items()}


@pytest.fixture(scope="module")
def simulated_frames(tmp_path_factory: pytest.TempPathFactory) -> Frames:
    """One PID episode of the paper's scenario through the real planner, MuJoCo and writer."""
    root = tmp_path_factory.mktemp("sim")
    params = yaml.safe_load((REPO / "params.yaml").read_text())
    params["scenarios"]["paper"]["hold_s"] = 0.5
    params["episodes"] = {"sim-pid": {"scenario": "paper", "controller": "pid", "seed": 0}}
    (root / "params.yaml").write_text(yaml.safe_dump(params))
    subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(root / "params.yaml"),
         "--out", str(root / "rec")],
        check=True, capture_output=True, timeout=300, cwd=REPO,
    )  # fmt: skip
    return _frames_of([root / "rec" / "sim-pid"])


def _whole(frames: Frames) -> pl.DataFrame:
    return joint_metrics(*frames)


def test_the_factory_recordings_exercise_every_branch(factory_frames: dict[str, Frames]) -> None:
    # Guards the comparisons below against vacuous truth: settling after violations,
    # a nonzero saturation share, metrics of nothing recorded, a motion not completed.
    m = {name: _whole(f) for name, f in factory_frames.items()}
    settle = m["settling"].get_column("settling_time").drop_nulls()
    assert (settle > 0).any() and (settle == 0).any()
    assert m["decimated"].get_column("settling_time").drop_nulls().max() > 0
    assert m["saturating"].get_column("saturation_fraction").max() > 0.1
    assert m["unrecorded"].get_column("rms_effort").null_count() == 6
    assert m["short"].get_column("final_error").null_count() == 6
    assert m["short"].get_column("max_abs_error").null_count() == 0


@pytest.mark.parametrize("name", list(_factory_episodes()))
@pytest.mark.parametrize("seed", range(6))
def test_metrics_over_random_time_slices_equal_the_whole_recording(
    factory_frames: dict[str, Frames], name: str, seed: int
) -> None:
    frames = factory_frames[name]
    cuts = _random_cuts(frames, seed)
    _assert_same_metrics(_sliced_metrics(frames, cuts), _whole(frames), f"{name}, {cuts=}")


@pytest.mark.parametrize("name", list(_factory_episodes()))
def test_metrics_over_fifty_slices_with_every_awkward_cut(
    factory_frames: dict[str, Frames], name: str
) -> None:
    frames = factory_frames[name]
    rng = np.random.default_rng(99)
    cuts = _special_cuts(frames, rng)
    t = frames[1].get_column("time_s").to_numpy()
    cuts += list(rng.uniform(t.min(), t.max(), size=49 - len(cuts)))
    slices = _slices(frames[0], frames[1], cuts)
    assert len(slices) == 50
    cs_rows = [c.height // 6 for _, c in slices]
    assert 1 in cs_rows and 0 in cs_rows  # a single-sample slice, an empty one
    if name == "decimated":
        assert any(s.height == 0 and c.height > 0 for s, c in slices)
    _assert_same_metrics(_sliced_metrics(frames, cuts), _whole(frames), name)


def test_every_sample_its_own_slice(tmp_path: Path) -> None:
    # the "decimated" recording cut to 0.6 s (600 slices; its 2 s, 2,000 slices proved the
    # same at 3x the time): still a motion, a settling after it and decimated joint states
    ep = paper_like("decimated", "pid", duration_s=0.6, motion_end_s=0.3, period_s=1e-3,
                    error_scale=5e-2, seed=1)  # fmt: skip
    ep.joint_state_every = 10
    frames = _frames_of([write_bag(tmp_path, ep)])
    assert _whole(frames).get_column("settling_time").drop_nulls().max() > 0
    t = np.unique(frames[1].get_column("time_s").to_numpy())
    assert t.size == 601 and frames[0].height < frames[1].height / 5
    _assert_same_metrics(_sliced_metrics(frames, list(t)), _whole(frames), "one per sample")


@pytest.mark.parametrize("seed", range(4))
def test_a_simulated_episode_over_random_time_slices(simulated_frames: Frames, seed: int) -> None:
    whole = _whole(simulated_frames)
    assert whole.get_column("settling_time").drop_nulls().len() > 0
    cuts = _random_cuts(simulated_frames, seed)
    _assert_same_metrics(_sliced_metrics(simulated_frames, cuts), whole, f"sim, {cuts=}")


def test_several_episodes_in_one_slice_stream(factory_frames: dict[str, Frames]) -> None:
    # Episodes interleave in the partial rows; each (episode, joint) keeps its time order.
    names = ["settling", "decimated", "short"]
    frames: Frames = (
        pl.concat([factory_frames[n][0] for n in names]),
        pl.concat([factory_frames[n][1] for n in names]),
        pl.concat([factory_frames[n][2] for n in names], how="diagonal_relaxed"),
        pl.concat([factory_frames[n][3] for n in names]),
    )
    cuts = [*_random_cuts(frames, 5), 1.0, 1.5]
    _assert_same_metrics(_sliced_metrics(frames, cuts), _whole(frames), "three episodes")


# --- hand-made frames: answers known by construction -------------------------------------------


def _frame(times: Sequence[float], columns: dict[str, Sequence[float | None]]) -> pl.DataFrame:
    """One joint ``j`` of episode ``e``: ``time_s`` and the given Float64 columns."""
    n = len(times)
    data = {"episode": ["e"] * n, "joint": ["j"] * n, "time_s": list(times), **columns}
    schema = {k: pl.String if k in KEY else pl.Float64 for k in data}
    return pl.DataFrame(data, schema=schema)


def _states(times: Sequence[float], **cols: Sequence[float | None]) -> pl.DataFrame:
    zeros = [0.0] * len(times)
    names = ("error_rad", "reference_position_rad", "feedback_position_rad")
    return _frame(times, {k: cols.get(k, zeros) for k in names})


def _samples(times: Sequence[float], **cols: Sequence[float | None]) -> pl.DataFrame:
    zeros = [0.0] * len(times)
    effort = cols.get("effort_nm", zeros)
    return _frame(
        times,
        {
            "velocity_rad_s": cols.get("velocity_rad_s", zeros),
            "effort_nm": effort,
            "commanded_effort_nm": effort,
        },
    )


def _table(motion_end_s: float | None, end_s: float, completed: bool = True) -> pl.DataFrame:
    return pl.DataFrame(
        {
            "episode": ["e"],
            "motion_end_s": [motion_end_s],
            "end_s": [end_s],
            "motion_completed": [completed],
        },
        schema_overrides={"motion_end_s": pl.Float64},
    )


def _hand(
    samples: pl.DataFrame, states: pl.DataFrame, table: pl.DataFrame, cuts: Sequence[float]
) -> dict[str, float | None]:
    """The one (episode, joint) row merged over the slices at ``cuts``, checked against the
    one-slice result."""
    frames: Frames = (samples, states, table, None)
    sliced = _sliced_metrics(frames, cuts)
    _assert_same_metrics(sliced, _whole(frames), f"{cuts=}")
    assert sliced.height == 1
    return sliced.row(0, named=True)


BAND = SETTLING_TOLERANCE_RAD
TEN = [float(i) for i in range(10)]  # samples at t = 0..9 s


def _settling(
    errors: Sequence[float], cuts: Sequence[float], motion_end_s: float | None = 2.0
) -> float | None:
    states = _states(TEN, error_rad=errors)
    return _hand(_samples(TEN), states, _table(motion_end_s, 9.0), cuts)["settling_time"]


def test_settling_violation_in_the_very_last_sample_never_settles() -> None:
    errors = [0.0] * 9 + [2 * BAND]
    for cuts in ([], [9.0], [5.0, 9.0], [2.0, 8.5]):
        assert _settling(errors, cuts) is None


def test_settling_violation_in_one_slice_settles_in_the_next() -> None:
    # Violations at t = 3 and 5 (after the motion end at 2), the last one ends slice [3, 6).
    errors = [9 * BAND, 0, 0, 2 * BAND, 0, 2 * BAND, 0, 0, 0, 0]
    assert _settling(errors, []) == 6.0 - 2.0
    assert _settling(errors, [3.0, 6.0]) == 4.0
    # Slices with no sample between the violation and the next sample: still t = 6.
    assert _settling(errors, [3.0, 5.5, 5.7, 5.9]) == 4.0
    # The last violation alone in its slice: settled in the next one.
    assert _settling(errors, [4.0, 5.0, 5.5]) == 4.0
    # Settled inside the violating slice.
    assert _settling(errors, [3.0, 8.0]) == 4.0


def test_settling_is_zero_without_violations_and_null_without_a_motion_end() -> None:
    errors = [9 * BAND, 9 * BAND] + [0.5 * BAND] * 8  # outside only before the motion end
    assert _settling(errors, [1.0, 2.0, 7.0]) == 0.0
    assert _settling([2 * BAND] * 10, [4.0], motion_end_s=None) is None


def test_settling_ignores_violations_before_the_motion_end_in_a_slice_before_it() -> None:
    errors = [0, 0, 0, 2 * BAND, 0, 0, 0, 0, 0, 0]
    # Motion end at 3.5: the violation at 3 is before it, nothing violates.
    assert _settling(errors, [3.2, 3.5], motion_end_s=3.5) == 0.0
    # Motion end at 2.5: settled at 4 = 1.5 s after it, whatever the slicing.
    for cuts in ([], [2.5], [3.0, 3.5], [3.5], [4.0]):
        assert _settling(errors, cuts, motion_end_s=2.5) == 1.5


def test_overshoot_for_negative_travel_uses_the_minimum_position() -> None:
    # Reference from 0 to -1 (unknown in the first slice), feedback dips to -1.25 in the
    # middle slice; a large positive position before the goal is not past it.
    ref = [None, None, 0.0, -0.25, -0.5, -0.75, -1.0, -1.0, -1.0, -1.0]
    fb = [0.5, 0.3, 0.0, -0.25, -0.5, -0.8, -1.25, -1.1, -1.0, -1.0]
    states = _states(TEN, reference_position_rad=ref, feedback_position_rad=fb)
    for cuts in ([], [2.0], [1.0, 6.0, 7.0], [6.5]):
        row = _hand(_samples(TEN), states, _table(6.0, 9.0), cuts)
        assert row["overshoot"] == pytest.approx(0.25, abs=1e-15)
    # Positive travel: the same positions mirrored never pass +1 -> 0 (clipped).
    mirrored = _states(
        TEN,
        reference_position_rad=[None if r is None else -r for r in ref],
        feedback_position_rad=[0.0] * 7 + [0.9, 1.0, 1.0],
    )
    assert _hand(_samples(TEN), mirrored, _table(6.0, 9.0), [3.0])["overshoot"] == 0.0


def test_peak_velocity_ties_across_slices_keep_the_first() -> None:
    v = [0.5, -2.0, 1.0, 0.0, 2.0, -2.0, 1.9, 0.0, 0.0, 0.0]
    for cuts in ([], [1.0], [2.0], [4.0], [1.5, 4.5], [3.0, 5.0]):
        row = _hand(_samples(TEN, velocity_rad_s=v), _states(TEN), _table(6.0, 9.0), cuts)
        assert (row["peak_velocity"], row["peak_velocity_time"]) == (-2.0, 1.0)
    # A larger peak in a later slice wins over an earlier slice's.
    v[7] = 2.5
    row = _hand(_samples(TEN, velocity_rad_s=v), _states(TEN), _table(6.0, 9.0), [2.0, 5.0])
    assert (row["peak_velocity"], row["peak_velocity_time"]) == (2.5, 7.0)


def test_all_null_effort_gives_null_not_zero_in_any_slicing() -> None:
    nothing: list[float | None] = [None] * 10
    samples = _samples(TEN, effort_nm=nothing, velocity_rad_s=nothing)
    for cuts in ([], [3.0], [0.5, 9.5]):
        row = _hand(samples, _states(TEN), _table(6.0, 9.0), cuts)
        for key in ("rms_effort", "saturation_fraction", "peak_velocity", "peak_velocity_time"):
            assert row[key] is None, key
    # Effort only in the second half: the RMS of what exists.
    some = _samples(TEN, effort_nm=[None] * 5 + [3.0, 4.0, 3.0, 4.0, 3.0])
    row = _hand(some, _states(TEN), _table(6.0, 9.0), [2.0, 7.0])
    assert row["rms_effort"] == pytest.approx(math.sqrt((3 * 9 + 2 * 16) / 5), rel=1e-15)


def test_final_error_and_rms_merge_counts_and_sums() -> None:
    # end 9, motion end 6: window min(0.5, 1.5) -> samples at t >= 8.5: only t = 9.
    errors = [1.0, -1.0, 2.0, -2.0, 0.0, 0.0, 0.0, 0.0, 0.5, -0.25]
    states = _states(TEN, error_rad=errors)
    row = _hand(_samples(TEN), states, _table(6.0, 9.0), [2.0, 8.7, 9.0])
    assert row["final_error"] == 0.25
    assert row["rms_error"] == pytest.approx(math.sqrt(10.3125 / 10), rel=1e-15)
    assert row["max_abs_error"] == 2.0


def test_an_incomplete_motion_gates_in_every_slicing() -> None:
    errors = [0.0] * 5 + [2 * BAND] + [0.0] * 4
    states = _states(TEN, error_rad=errors, reference_position_rad=[0.1 * t for t in TEN])
    for cuts in ([], [5.0], [1.0, 8.0]):
        row = _hand(_samples(TEN), states, _table(2.0, 9.0, completed=False), cuts)
        assert row["final_error"] is None
        assert row["settling_time"] is None
        assert row["overshoot"] is None
        assert row["max_abs_error"] == 2 * BAND
        row = _hand(_samples(TEN), states, _table(2.0, 9.0, completed=True), cuts)
        assert row["settling_time"] == 4.0
        assert row["overshoot"] == 0.0


def test_a_slice_without_controller_states_or_joint_states_for_a_joint() -> None:
    # /joint_states only in [0, 4), /controller_state only in [4, 10).
    samples = _samples(TEN[:4], velocity_rad_s=[1.0, 3.0, -3.0, 0.0], effort_nm=[2.0] * 4)
    states = _states(TEN[4:], error_rad=[3 * BAND, 0.0, 0.0, 0.0, 0.0, 0.0])
    for cuts in ([], [4.0], [2.0, 6.0]):
        row = _hand(samples, states, _table(3.0, 9.0), cuts)
        assert row["settling_time"] == 2.0
        assert (row["peak_velocity"], row["peak_velocity_time"]) == (3.0, 1.0)
        assert row["rms_effort"] == 2.0
