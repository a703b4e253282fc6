"""A Ray process dying mid-run ends `record --executor ray` in one line, with nothing left.

Ray's core worker ends its driver from C++ (QuickExit) when the raylet goes, which it does
when its dashboard agent dies: the driver cannot print anything. The command runs
supervised (pipeline/supervise.py) and the supervisor says what happened.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.supervise import drives_ray
from tests.stages.test_campaign_run import PIPELINE, REPO, _params


def test_only_ray_records_are_supervised() -> None:
    assert drives_ray(["record", "--executor", "ray", "--params", "p"])
    assert drives_ray(["record", "--campaign", "c", "--executor=ray"])
    assert not drives_ray(["record", "--executor", "local"])
    assert not drives_ray(["report", "--executor", "ray"])
    assert not drives_ray(["record", "--executor"])


def _descendants(pid: int) -> list[object]:
    psutil = pytest.importorskip("psutil")
    try:
        return list(psutil.Process(pid).children(recursive=True))
    except psutil.NoSuchProcess:
        return []


def _recorded(out: Path) -> bool:
    return any(p.is_dir() and not p.name.startswith(".") for p in out.glob("c/*"))


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time under pytest -n
def test_killing_rays_dashboard_agent_ends_the_run_in_one_line(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    psutil = pytest.importorskip("psutil")
    params = _params(tmp_path, {"scenario": "paper", "controllers": ["pid", "ctc"], "seeds": 150})
    out = tmp_path / "rec"
    proc = subprocess.Popen(
        [*PIPELINE, "record", "--params", str(params), "--out", str(out), "--campaign", "c",
         "--executor", "ray"],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip
    agent = None  # waited for while the run lives, however long Ray takes to start
    try:
        while agent is None and proc.poll() is None:
            for p in _descendants(proc.pid):
                try:
                    if any("dashboard/agent.py" in part for part in p.cmdline()):
                        agent = p
                except psutil.Error:
                    continue
            time.sleep(0.2)
        assert agent is not None, "no Ray dashboard agent appeared"
        # let the run get going: its first episode recorded (on a loaded machine Ray may take a
        # minute to start); 300 episodes cannot all finish before Ray notices the agent's death
        while proc.poll() is None and not _recorded(out):
            time.sleep(0.2)
        assert proc.poll() is None, "the run ended before the agent was killed"
        agent.kill()
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode != 0
    errors = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, stderr
    assert "the Ray run ended abruptly" in errors[0]
    assert "Traceback" not in stderr
    time.sleep(1.0)
    left = [p for p in psutil.process_iter(["cmdline"])
            if str(tmp_path) in " ".join(p.info["cmdline"] or [])]  # fmt: skip
    assert left == [], left
    assert not [p for p in out.rglob("*") if ".partial-" in p.name]


def test_after_an_abrupt_end_the_workers_half_written_bags_are_swept_once_their_writers_end(
    tmp_path: Path,
) -> None:
    from pipeline.__main__ import _sweep_partials

    writer = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1.0)"])
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "rec"
    (out / "c" / f".pid.s2.partial-{writer.pid}").mkdir(parents=True)
    (out / f".e0.partial-{dead.pid}").mkdir()
    (out / "c" / "pid.s1").mkdir()  # a finished bag stays
    try:
        _sweep_partials(["record", "--out", str(out), "--executor", "ray"])
    finally:
        writer.wait()
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*")) == ["c", "c/pid.s1"]
