"""A campaign too big for the disk or a week is refused from its count, before expanding."""

from __future__ import annotations

import sys
import time
import tracemalloc
from pathlib import Path

import pytest
import yaml

from pipeline.cli import main
from pipeline.errors import ParamsError
from pipeline.params import load_params
from pipeline.stages import campaign_run

REPO = Path(__file__).parents[2]


def _params(tmp_path: Path) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["campaigns"] = {
        "huge": {
            "scenario": "paper",
            "controllers": ["pid", "ctc", "ctc_pid"],
            "seeds": 1000,
            "sweep": {"plant.payload_kg": {"uniform": [0.0, 1.0], "n": 100}},
        }
    }
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_campaign_count_multiplies_the_axes_without_drawing(tmp_path: Path) -> None:
    params = load_params(_params(tmp_path))
    assert campaign_run.campaign_count(params.campaigns["huge"]) == 300_000


def test_a_300000_episode_campaign_is_refused_quickly_and_small(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    params = load_params(_params(tmp_path))

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("expanded before the count was checked")

    monkeypatch.setattr(campaign_run, "expand", never)
    tracemalloc.start()
    started = time.monotonic()
    try:
        with pytest.raises(ParamsError, match=r"300,000 episodes would"):
            campaign_run.check_campaign_count(params, "huge", out=tmp_path / "out", jobs=1)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.monotonic() - started < 2  # expanding took 58 s and 407 MB
    assert peak < 20e6


def test_record_refuses_the_campaign_in_one_line_before_expanding(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    params = _params(tmp_path)
    monkeypatch.setattr(campaign_run, "plan_run", lambda *a, **k: pytest.fail("planned"))
    monkeypatch.chdir(tmp_path)
    argv = ["pipeline", "record", "--params", str(params), "--campaign", "huge", "--out", "o"]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "300,000 episodes" in err
    assert not (tmp_path / "o").exists()
