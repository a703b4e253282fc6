"""The record console and the report print the same error at the target, digit for digit."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).parents[2]
PIPELINE = [sys.executable, "-m", "pipeline"]
SCI = re.compile(r"-?\d\.\d{3}e[-+]\d\d")


def _run(*args: str) -> str:
    proc = subprocess.run([*PIPELINE, *args], capture_output=True, text=True, timeout=600, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _numbers(stdout: str, episode: str) -> list[str]:
    (line,) = [ln for ln in stdout.splitlines() if re.search(rf"\b{episode}\b", ln)]
    return SCI.findall(line)


@pytest.mark.slow
@pytest.mark.parametrize("hold_s", [0.3, 1.0])  # a window off and on the sample grid
def test_record_console_and_report_agree_on_max_and_final_error(
    tmp_path: Path, hold_s: float
) -> None:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = hold_s
    data["episodes"] = {k: v for k, v in data["episodes"].items() if v["scenario"] == "paper"}
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    recorded = _run("record", "--params", str(params), "--out", str(tmp_path / "rec"))
    reported = _run("report", "--recordings", str(tmp_path / "rec"), "-o", str(tmp_path / "rep"))
    report_md = (tmp_path / "rep" / "report.md").read_text(encoding="utf-8")
    assert data["episodes"]
    for episode in data["episodes"]:
        max_rec, final_rec = _numbers(recorded, episode)  # max |e|, final |e|
        max_rep, _rms, final_rep = _numbers(reported, episode)
        assert (max_rec, final_rec) == (max_rep, final_rep), episode
        assert final_rec in report_md  # report.md's joint table, same formatter
