"""The record stage estimates an episode's memory and time before running it.

The estimate must refuse what cannot fit (one line: the estimate and the field to
change) and be honest: an upper bound of what a real run's memory grows by, and not
wildly above it.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.errors import ParamsError
from pipeline.params import parse_params
from pipeline.stages.budget import (
    BYTES_PER_JOINT_STEP,
    MAX_EPISODE_WALL_S,
    check_budget,
    estimate_episode,
)

REPO = Path(__file__).parents[2]


def _data(**sim: float) -> dict:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["sim"].update(sim)
    return data


def test_estimate_counts_control_steps_and_physics_steps():
    data = _data(physics_dt_s=0.0005, control_period_steps=4)
    data["scenarios"]["paper"].update(hold_s=3.0, preroll_s=1.0)
    episode = parse_params(data, source="p.yaml").episodes[0]
    est = estimate_episode(episode, dof=6, motion_s=1.0)
    assert est.duration_s == 5.0  # pre-roll + motion + hold
    assert est.control_steps == 2501  # 5 s at 2 ms, both ends
    assert est.physics_steps == 10004
    assert est.memory_bytes == 2501 * 6 * BYTES_PER_JOINT_STEP


def test_an_hour_at_100_khz_is_refused_up_front_in_one_line(tmp_path):
    data = _data(physics_dt_s=1e-5, control_period_steps=1)
    data["scenarios"]["paper"]["hold_s"] = 3600.0
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    result = subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(params), "--out",
         str(tmp_path / "rec")],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 1 and len(lines) == 1, result.stderr
    assert re.search(r"episode 'paper-\w+' is 36\d\d s at 36\d,\d{3},\d{3} control steps x 6 "
                     r"joints: ", lines[0])  # fmt: skip
    assert re.search(r"would hold about [\d.]+ TB in memory, more than the ", lines[0])
    assert "lower scenarios.paper.hold_s or sim.control_period_steps" in lines[0]
    assert not (tmp_path / "rec").exists()


def test_memory_is_shared_between_parallel_episodes():
    data = _data()
    data["scenarios"]["paper"]["hold_s"] = 100.0
    params = parse_params(data, source="p.yaml")
    need = estimate_episode(params.episodes[0], dof=6, motion_s=0.0).memory_bytes
    memory = int(need / 0.8 * 1.5)  # fits one at a time, not two
    check_budget(params, params.episodes, motion_s={}, jobs=1, memory_bytes=memory)
    with pytest.raises(ParamsError, match=r"each of 2 parallel episodes.*or --jobs"):
        check_budget(params, params.episodes, motion_s={}, jobs=2, memory_bytes=memory)


def test_an_episode_over_the_time_limit_is_refused_with_its_estimate():
    data = _data(physics_dt_s=1e-5, control_period_steps=100)
    data["scenarios"]["paper"]["hold_s"] = 3600.0
    params = parse_params(data, source="p.yaml")
    est = estimate_episode(params.episodes[0], dof=6, motion_s=0.0)
    assert est.wall_s > MAX_EPISODE_WALL_S
    with pytest.raises(ParamsError, match=r"run for about \d.* h, more than 2 h; lower "):
        check_budget(params, params.episodes, motion_s={}, jobs=1, memory_bytes=10**15)


_WRAPPER = (
    "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, "
    "stdout=subprocess.DEVNULL); print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
)


@pytest.mark.slow
def test_the_memory_estimate_bounds_what_a_longer_episode_really_adds(tmp_path):
    """Peak RSS of two real runs, 1 s and 41 s of hold: the growth per control step is
    at most the estimate's and at least half of it."""
    rss = {}
    for hold in (1.0, 41.0):
        data = _data()
        data["scenarios"]["paper"]["hold_s"] = hold
        params = tmp_path / f"p{hold}.yaml"
        params.write_text(yaml.safe_dump(data))
        result = subprocess.run(
            [sys.executable, "-c", _WRAPPER, sys.executable, "-m", "pipeline", "record",
             "--params", str(params), "--out", str(tmp_path / f"rec{hold}"),
             "--only", "paper-ctc"],
            cwd=REPO, capture_output=True, text=True, timeout=300, check=True,
        )  # fmt: skip
        rss[hold] = int(result.stdout.split()[-1]) * 1024
    episode = parse_params(_data(), source="p.yaml").episodes[1]
    per_step_estimate = estimate_episode(episode, dof=6, motion_s=0.0).memory_bytes / (
        estimate_episode(episode, dof=6, motion_s=0.0).control_steps
    )
    measured = (rss[41.0] - rss[1.0]) / 40_000  # 40 s more at 1 kHz
    assert 0.5 * per_step_estimate <= measured <= per_step_estimate, (measured, per_step_estimate)
