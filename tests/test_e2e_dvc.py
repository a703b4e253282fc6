"""The README path on a fresh clone: `dvc repro` runs record -> report, then nothing.

Clones this repository's HEAD into a temp dir and drives DVC there with the
clone's own code (PYTHONPATH) and this venv's tools (PATH).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).parents[1]


def _run(cmd: list[str], cwd: Path, env: dict[str, str]) -> str:
    result = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, f"{cmd}: {result.stdout}\n{result.stderr}"
    return result.stdout + result.stderr


@pytest.mark.slow
def test_fresh_clone_dvc_repro_runs_once_then_only_what_a_gain_change_touches(tmp_path):
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
        "PYTHONPATH": str(clone),
        "DVC_NO_ANALYTICS": "1",
    }
    dvc = [str(Path(sys.executable).parent / "dvc")]

    # the committed dvc.lock must describe the committed code and params: only the
    # outputs (not in git) are missing in a clone
    def stale_inputs(changes: list[dict[str, dict[str, object]]]) -> list[str]:
        out = []
        for change in changes:
            for path, what in change.get("changed deps", {}).items():
                # upstream outputs (recordings/, params.checked) are absent in a clone
                if not path.startswith(("recordings", "params.checked")):
                    out.append(f"{path}: {what}")
        return out

    status = json.loads(_run([*dvc, "status", "--json"], clone, env))
    stale = {stage: stale_inputs(c) for stage, c in status.items() if stale_inputs(c)}
    assert not stale, (
        f"dvc.lock is stale for {sorted(stale)}: run `make demo` (dvc repro) and commit "
        f"dvc.lock and reports/metrics.json ({stale})"
    )
    committed_lock = yaml.safe_load((clone / "dvc.lock").read_text())
    committed_metrics = (clone / "reports" / "metrics.json").read_bytes()

    episodes = yaml.safe_load((clone / "params.yaml").read_text())["episodes"]
    campaigns = yaml.safe_load((clone / "params.yaml").read_text())["campaigns"]
    assert "paper-realistic" in campaigns
    first = _run([*dvc, "repro"], clone, env)
    ran = set(re.findall(r"Running stage '([^']+)'", first))
    assert ran == {f"record@{e}" for e in episodes} | {f"campaign@{c}" for c in campaigns} | {
        "check-params",
        "report",
    }, first
    reports = clone / "reports"
    for name in ("report.md", "metrics.json", "recording.rrd"):
        assert (reports / name).is_file(), name
    metrics = json.loads((reports / "metrics.json").read_text())
    # hand-listed episodes and campaign episodes (their keys, under recordings/<campaign>/)
    assert set(episodes) <= set(metrics["episodes"])
    # committed results reproduce byte for byte from the clone (the .rrd excepted:
    # Rerun stamps chunks with time-based ids)
    assert (reports / "metrics.json").read_bytes() == committed_metrics
    lock = yaml.safe_load((clone / "dvc.lock").read_text())
    for stage in ("record@paper-pid", "record@paper-ctc", "campaign@paper-realistic"):
        assert lock["stages"][stage]["outs"] == committed_lock["stages"][stage]["outs"], stage

    second = _run([*dvc, "repro"], clone, env)
    assert "Running stage" not in second, second

    params = clone / "params.yaml"
    text = params.read_text()
    assert "gains: {kp: 1600.0, kd: 80.0}" in text
    params.write_text(text.replace("gains: {kp: 1600.0, kd: 80.0}", "gains: {kp: 900.0, kd: 60.0}"))
    status = _run([*dvc, "status", "--json"], clone, env)
    changed = set(json.loads(status))
    # the hand-listed CTC episode and the campaign that runs CTC; not paper-pid (the params
    # check runs on every change, and its unchanged output re-runs nothing)
    assert changed == {"check-params", "record@paper-ctc", "campaign@paper-realistic"}, status
    third = _run([*dvc, "repro"], clone, env)
    assert set(re.findall(r"Running stage '([^']+)'", third)) == {
        "check-params", "record@paper-ctc", "campaign@paper-realistic", "report",
    }  # fmt: skip
    # a campaign's own change re-runs that campaign alone
    text = params.read_text()
    assert "    seeds: 10\n" in text
    params.write_text(text.replace("    seeds: 10\n", "    seeds: 11\n", 1))
    status = _run([*dvc, "status", "--json"], clone, env)
    assert set(json.loads(status)) == {"check-params", "campaign@paper-realistic"}, status
