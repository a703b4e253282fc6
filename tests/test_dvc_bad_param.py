"""A mistyped `dvc exp run -S` value fails in check-params, before DVC removes a recording."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).parents[1]


def test_check_flag_says_params_valid_or_one_line(tmp_path: Path) -> None:
    ok = subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(REPO / "params.yaml"),
         "--check"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert ok.returncode == 0 and ok.stdout == "params valid\n", ok.stderr
    assert not (tmp_path / "recordings").exists()
    bad = tmp_path / "params.yaml"
    bad.write_text((REPO / "params.yaml").read_text().replace("hold_s: ", "hold_s: abc #", 1))
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(bad), "--check"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 1 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "hold_s" in lines[0], lines


@pytest.mark.slow
def test_a_mistyped_exp_run_value_keeps_the_committed_recording(tmp_path: Path) -> None:
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
        "PYTHONPATH": str(clone),
        "DVC_NO_ANALYTICS": "1",
    }
    dvc = str(Path(sys.executable).parent / "dvc")
    params = clone / "params.yaml"
    # a short episode: the bytes do not matter here, the recording's survival does
    params.write_text(params.read_text().replace("hold_s: ", "hold_s: 0.1 #"))
    subprocess.run(["git", "commit", "-qam", "short"], cwd=clone, check=True, env=env)
    first = subprocess.run([dvc, "repro", "record@paper-pid"], cwd=clone, env=env,
                           capture_output=True, text=True, timeout=900)  # fmt: skip
    assert first.returncode == 0, first.stdout + first.stderr
    bag = clone / "recordings" / "paper-pid"
    before = sorted(p.name for p in bag.iterdir())
    assert any(n.endswith(".mcap") for n in before)
    bad = subprocess.run(
        [dvc, "exp", "run", "-S", "scenarios.paper.hold_s=abc", "record@paper-pid"],
        cwd=clone, env=env, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert bad.returncode != 0
    assert "hold_s" in bad.stdout + bad.stderr
    assert sorted(p.name for p in bag.iterdir()) == before  # the recording is still there
