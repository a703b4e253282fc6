"""A recorded ``planner.trajectory_duration_s`` that the data contradict (1e9 s, 0 s): noted,
and the metrics that depend on the motion end (final error, overshoot, settling time) come
from the data (the planned trajectory topic, else the reference's stamps) or are n/a."""

from __future__ import annotations

from pathlib import Path

import polars as pl
import pytest

from pipeline.analysis.episodes import episode_table, limits_table
from pipeline.analysis.metrics import joint_metrics
from pipeline.log.reader import Recording, read_recording
from tests.analysis.bagfactory import default_settings, paper_like, write_bag

DEPENDENT = ("final_error", "overshoot", "settling_time")
NO_PLAN = ("/joint_states", "/controller_state", "/tf")
WITH_PLAN = (*NO_PLAN, "/planned_trajectory")


def recorded(
    tmp_path: Path, name: str, duration_s: float | None, topics: tuple[str, ...]
) -> Recording:
    """paper_like's episode (motion 2 s, hold 1 s), its settings' trajectory duration set
    to ``duration_s`` (None: the true 2 s)."""
    ep = paper_like(name, "pid")
    settings = default_settings(ep)
    if duration_s is not None:
        settings["planner"]["trajectory_duration_s"] = duration_s
    ep.settings = settings
    return read_recording(write_bag(tmp_path, ep, topics=topics))


def metrics(rec: Recording) -> dict[str, list[float | None]]:
    m = joint_metrics(rec.samples, rec.controller_states, episode_table([rec]), limits_table([rec]))
    return {k: m.sort("joint").get_column(k).to_list() for k in DEPENDENT}


@pytest.mark.parametrize("duration_s", [1e9, 0.0])
def test_a_duration_the_planned_trajectory_contradicts_is_taken_from_it(
    tmp_path: Path, duration_s: float
) -> None:
    honest = recorded(tmp_path / "a", "honest", None, WITH_PLAN)
    assert not any("contradicted" in n for n in honest.notes)
    rec = recorded(tmp_path / "b", "lying", duration_s, WITH_PLAN)
    [note] = [n for n in rec.notes if "contradicted" in n]
    assert f"trajectory_duration_s = {duration_s:g} s" in note and "/planned_trajectory" in note
    assert rec.trajectory_duration_s == pytest.approx(2.0)
    assert metrics(rec) == metrics(honest)


@pytest.mark.parametrize("duration_s", [1.996, 1.75])
def test_a_duration_between_the_plans_last_two_samples_is_not_contradicted(
    tmp_path: Path, duration_s: float
) -> None:
    """The recorder samples the plan on a grid up to the first instant >= its end (0.886 s
    -> a last point at 0.890 s on a 10 ms grid): that is no contradiction, and the motion
    end stays the settings' (the factory's plan has a 0.5 s step ending at 2 s)."""
    rec = recorded(tmp_path, "gridded", duration_s, WITH_PLAN)
    assert not any("contradicted" in n for n in rec.notes)
    assert rec.trajectory_duration_s == pytest.approx(duration_s)


def test_a_plan_that_ends_before_the_duration_contradicts_it(tmp_path: Path) -> None:
    rec = recorded(tmp_path, "short", 2.1, WITH_PLAN)
    [note] = [n for n in rec.notes if "contradicted" in n]
    assert "trajectory_duration_s = 2.1 s" in note
    assert rec.trajectory_duration_s == pytest.approx(2.0)


def test_a_duration_the_reference_contradicts_is_taken_from_its_stamps(tmp_path: Path) -> None:
    honest = recorded(tmp_path / "a", "honest", None, NO_PLAN)
    rec = recorded(tmp_path / "b", "zero", 0.0, NO_PLAN)
    [note] = [n for n in rec.notes if "contradicted" in n]
    assert "reference" in note
    assert rec.trajectory_duration_s == pytest.approx(2.0, abs=0.01)
    for key, values in metrics(rec).items():
        assert values == pytest.approx(metrics(honest)[key], abs=0.01, nan_ok=True), key


def test_a_duration_past_the_recordings_end_makes_the_motion_end_unknown(tmp_path: Path) -> None:
    rec = recorded(tmp_path, "long", 1e9, NO_PLAN)
    [note] = [n for n in rec.notes if "contradicted" in n]
    assert "ends at 3.000 s" in note and "n/a" in note
    assert rec.trajectory_duration_s is None
    table = episode_table([rec])
    assert table.get_column("motion_end_s").to_list() == [None]
    m = joint_metrics(rec.samples, rec.controller_states, table, limits_table([rec]))
    assert m.get_column("settling_time").null_count() == m.height
    assert isinstance(m, pl.DataFrame)
