"""Extra campaigns: params.yaml's ``extra_campaigns`` run on demand, outside the DVC stages
(and `make demo`), and record outside the report's ``recordings/`` by default."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

from pipeline.errors import ParamsError
from pipeline.params import EXTRA_RECORDINGS_DIR, load_params, parse_params
from pipeline.stages.campaign_expand import expand
from tests.test_bad_input import run_cli

REPO = Path(__file__).parents[2]


def _data() -> dict[str, Any]:
    return copy.deepcopy(yaml.safe_load((REPO / "params.yaml").read_text()))


def test_the_panda_experiment_is_in_params_yaml_but_no_dvc_stage() -> None:
    params = load_params(REPO / "params.yaml")
    assert params.extra_campaigns == {"panda-box"}
    episodes = expand(params, "panda-box")
    assert {e.scenario.robot for e in episodes} == {"panda"}
    assert {e.controller_name for e in episodes} == {"pid", "ctc", "ctc_pid"}
    assert len(episodes) == 9
    # dvc.yaml's campaign stages iterate `campaigns` only: `make demo` stays the UR5's
    stages = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"]
    assert stages["campaign"]["foreach"] == "${campaigns}"
    assert "panda-box" not in _data()["campaigns"]
    assert not (REPO / "params-panda.yaml").exists()


def test_an_extra_campaign_error_names_its_own_section() -> None:
    data = _data()
    data["extra_campaigns"]["panda-box"]["controllers"] = ["pid", "nope"]
    with pytest.raises(ParamsError, match=r"extra_campaigns\.panda-box\.controllers\[1\]"):
        parse_params(data, source="p.yaml")
    data = _data()
    data["extra_campaigns"]["paper-realistic"] = data["campaigns"]["paper-realistic"]
    with pytest.raises(ParamsError, match=r"extra_campaigns\.paper-realistic: also in campaigns"):
        parse_params(data, source="p.yaml")


def test_params_with_only_extra_campaigns_are_valid() -> None:
    data = _data()
    data["episodes"], data["campaigns"] = {}, {}
    params = parse_params(data, source="p.yaml")
    assert list(params.campaigns) == ["panda-box"] and params.where("panda-box") == (
        "extra_campaigns.panda-box"
    )


def test_an_extra_campaign_records_outside_recordings_by_default(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    data = _data()
    data["scenarios"]["paper"].update(preroll_s=0.05, hold_s=0.05)
    data["extra_campaigns"] = {"quick": {"scenario": "paper", "controllers": ["ctc"]}}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(data))
    monkeypatch.chdir(tmp_path)
    code, err = run_cli(["record", "--campaign", "quick"], capsys)
    assert code == 0, err
    assert (tmp_path / EXTRA_RECORDINGS_DIR / "quick" / "ctc.s0" / "metadata.yaml").is_file()
    assert not (tmp_path / "recordings").exists()  # the DVC report's folder stays the UR5's
