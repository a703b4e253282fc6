"""Running campaigns: same bytes on every executor, resume after a kill, failures isolated."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import yaml

from pipeline.params import load_params
from pipeline.stages.campaign_run import DONE_DIR, bag_is_whole, completion_marker, plan_run
from pipeline.stages.executors.ray import start_ray
from pipeline.stages.record import record

REPO = Path(__file__).parents[2]
PIPELINE = [sys.executable, "-m", "pipeline"]


def _params(tmp_path: Path, campaign: dict[str, Any] | None = None) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    for s in data["scenarios"].values():
        s.update(preroll_s=0.2, hold_s=0.2)  # short episodes: the bytes matter, not the length
    data["campaigns"] = {
        "c": campaign
        or {
            "scenario": "paper-realistic",  # seeded plant draws and sensor noise
            "controllers": ["pid", "ctc"],
            "seeds": 2,
            "sweep": {"plant.payload_kg": [0.0, 0.5]},
        }
    }
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _run(params: Path, out: Path, **kwargs: Any) -> list[Any]:
    loaded = load_params(params)
    run = plan_run(loaded, "c", out=out)
    return record(
        loaded, run.pending, out_dir=run.out_dir, force=True, commit=run.commit,
        on_event=completion_marker(run, lambda *a: None), **kwargs,
    )  # fmt: skip


def _files(out: Path) -> dict[str, bytes]:
    """Every file of every published bag (.mcap and metadata.yaml), by relative path."""
    return {
        str(p.relative_to(out)): p.read_bytes()
        for p in sorted(out.glob("c/*/*"))
        if not p.parent.name.startswith(".")
    }


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time under pytest -n
def test_same_campaign_same_bytes_with_one_two_jobs_and_ray(tmp_path):
    ray = pytest.importorskip("ray")
    params = _params(tmp_path)
    one = _run(params, tmp_path / "j1", jobs=1)
    two = _run(params, tmp_path / "j2", jobs=2)
    start_ray(address=None, num_cpus=2)  # waits for readiness (retries a start-up timeout)
    try:
        on_ray = _run(params, tmp_path / "ray", executor="ray")
    finally:
        ray.shutdown()
    for outcomes in (one, two, on_ray):
        assert [o.status for o in outcomes] == ["ok"] * 8, [o.reason for o in outcomes]
    a, b, c = _files(tmp_path / "j1"), _files(tmp_path / "j2"), _files(tmp_path / "ray")
    assert len(a) == 16 and {Path(k).suffix for k in a} == {".mcap", ".yaml"}
    assert a == b
    assert a == c
    # the campaign's own values are in every recording's settings
    meta = yaml.safe_load((tmp_path / "j1" / "c" / "payload_kg-0.5.ctc.s1" / "metadata.yaml")
                          .read_text())  # fmt: skip
    text = str(meta)
    assert "payload_kg=0.5" in text and "plant.payload_kg" in text


@pytest.mark.slow
def test_a_killed_campaign_resumes_without_redoing_or_trusting_partial_work(tmp_path):
    params = _params(tmp_path, {"scenario": "paper", "controllers": ["pid", "ctc"], "seeds": 6})
    out = tmp_path / "rec"
    cmd = [*PIPELINE, "record", "--params", str(params), "--out", str(out), "--campaign", "c"]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)  # fmt: skip
    done = out / "c" / DONE_DIR
    while len(list(done.glob("*"))) < 3:  # no wall-clock deadline: the run ends or marks
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    marked = {p.name for p in done.iterdir() if not p.name.startswith(".")}
    assert 3 <= len(marked) < 12
    # a marked bag damaged since is not trusted (nor is one the kill left without its mark)
    victim = sorted(marked)[0]
    mcap = next((out / "c" / victim).glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[:-100])
    assert not bag_is_whole(out / "c" / victim)
    loaded = load_params(params)
    run = plan_run(loaded, "c", out=out)
    assert set(run.skipped) == marked - {victim}
    resumed = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(marked) - 1} of 12 episode(s) already recorded" in resumed.stderr.replace(
        "\n", " "
    )
    # the result is what one uninterrupted run gives, byte for byte
    _run(params, tmp_path / "clean")
    assert _files(out) == _files(tmp_path / "clean")
    again = plan_run(loaded, "c", out=out)
    assert again.pending == () and len(again.skipped) == 12


@pytest.mark.slow
def test_a_changed_value_reruns_only_its_episodes(tmp_path):
    params = _params(tmp_path)
    _run(params, tmp_path / "rec")
    data = yaml.safe_load(params.read_text())
    data["campaigns"]["c"]["sweep"]["plant.payload_kg"] = [0.0, 0.25]
    params.write_text(yaml.safe_dump(data))
    run = plan_run(load_params(params), "c", out=tmp_path / "rec")
    assert sorted(e.name for e in run.pending) == sorted(
        f"payload_kg-0.25.{c}.s{s}" for c in ("pid", "ctc") for s in (0, 1)
    )
    assert sorted(run.stray) == sorted(
        f"payload_kg-0.5.{c}.s{s}" for c in ("pid", "ctc") for s in (0, 1)
    )


@pytest.mark.slow
def test_a_failed_episode_never_stops_the_others_and_is_listed(tmp_path):
    # goal "bad" puts the arm into the ground: its plan fails, the other goal's episodes run
    params = _params(
        tmp_path,
        {"scenario": "paper", "controllers": ["pid", "ctc"],
         "goals": {"ok": [-0.15, -0.5, 0.785, -1.15, -0.3925, 0.0],
                   "bad": [0.0, 1.2, 1.5, 0.0, 0.0, 0.0]}},
    )  # fmt: skip
    result = subprocess.run(
        [*PIPELINE, "record", "--params", str(params), "--out", str(tmp_path / "rec"),
         "--campaign", "c", "-j", "2"],
        cwd=REPO, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert result.returncode == 1
    assert "2 failed, 2 ok" in result.stdout
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert [e.split(":")[1].strip() for e in errors] == ["c/goal-bad.pid.s0", "c/goal-bad.ctc.s0"]
    assert "Traceback" not in result.stderr
    assert sorted(p.name for p in (tmp_path / "rec" / "c" / DONE_DIR).iterdir()) == [
        "goal-ok.ctc.s0", "goal-ok.pid.s0",
    ]  # fmt: skip


def test_unknown_executor_and_stray_address_fail_in_one_line(tmp_path):
    params = _params(tmp_path)
    for extra, expected in (
        (["--executor", "dask"], "error: --executor: expected local or ray, got 'dask'"),
        (["--address", "auto"], "error: --address: only with --executor ray"),
        (["--campaign", "nope"], "unknown campaign 'nope'; valid: c"),
    ):
        result = subprocess.run(
            [*PIPELINE, "record", "--params", str(params), "--out", str(tmp_path / "o"), *extra],
            cwd=REPO, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert result.returncode == 1
        assert expected in result.stderr and len(result.stderr.strip().splitlines()) == 1
