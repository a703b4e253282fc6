"""The out-of-tree example: installed with pip (--target), it runs in a campaign beside the
built-ins and a ``module:Object`` controller, on the process pool and on a local Ray instance,
and each recording names where its controller's code came from.

The shared venv is left alone: pip installs into a temporary folder that only the
subprocess's PYTHONPATH sees (``importlib.metadata`` finds the entry point on ``sys.path``).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.log.reader import read_recording

REPO = Path(__file__).parents[2]
EXAMPLE = REPO / "examples" / "armlab_example_controller"
MODULE_OBJECT = "tests.control.test_testkit:GoodPd"
OFFLINE = ("No matching distribution", "Could not find a version", "Failed to establish")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The example installed with ``pip install --no-deps --target``."""
    root = tmp_path_factory.mktemp("example")
    src = root / "src"
    shutil.copytree(EXAMPLE, src)  # the build leaves nothing in the repository
    target = root / "site"
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--quiet", "--target",
         str(target), str(src)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    if proc.returncode != 0 and any(s in proc.stderr for s in OFFLINE):
        pytest.skip(f"pip cannot fetch the example's build backend: {proc.stderr[-200:]}")
    assert proc.returncode == 0, proc.stderr
    return target


def _params(tmp_path: Path) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    for scenario in data["scenarios"].values():
        scenario.update(preroll_s=0.2, hold_s=0.2)
    data["controllers"]["example"] = {"type": "pd_gravity_accff"}
    data["controllers"]["mine"] = {"type": MODULE_OBJECT, "gains": {"omega_n_rad_s": 30.0}}
    data["campaigns"] = {
        "c": {"scenario": "paper", "controllers": ["pid", "example", "mine"], "seeds": 1}
    }
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _record(site: Path, params: Path, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(REPO)])}
    return subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(params), "--out", str(out),
         "--campaign", "c", *extra],
        capture_output=True, text=True, timeout=900, cwd=REPO, env=env,
    )  # fmt: skip


def _origins(out: Path) -> dict[str, dict[str, str]]:
    recs = {}
    for bag in sorted((out / "c").iterdir()):
        if bag.is_dir() and not bag.name.startswith("."):
            settings = read_recording(bag).settings
            assert settings is not None
            recs[settings.controller.name] = dict(settings.controller.origin)
    return recs


def _check(out: Path) -> None:
    origins = _origins(out)
    assert sorted(origins) == ["example", "mine", "pid"]
    assert origins["pid"] == {"kind": "builtin"}
    example = origins["example"]
    assert example["kind"] == "entry_point"
    assert (example["distribution"], example["version"]) == ("armlab-example-controller", "0.1.0")
    assert example["value"] == "armlab_example_controller.controller:PdGravityAccFF"
    mine = origins["mine"]
    path = REPO / "tests" / "control" / "test_testkit.py"
    assert mine["kind"] == "module" and Path(mine["path"]) == path.resolve()
    assert mine["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.slow
def test_example_and_module_object_controllers_run_in_a_pool_campaign(site, tmp_path):
    proc = _record(site, _params(tmp_path), tmp_path / "out", "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    _check(tmp_path / "out")
    # the report names each plug-in's code as its bags recorded it
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(REPO)])}
    report = subprocess.run(
        [sys.executable, "-m", "pipeline", "report", "--recordings", str(tmp_path / "out" / "c"),
         "--out", str(tmp_path / "rep")],
        capture_output=True, text=True, timeout=900, cwd=REPO, env=env,
    )  # fmt: skip
    assert report.returncode == 0, report.stderr
    text = (tmp_path / "rep" / "report.md").read_text()
    sha = hashlib.sha256((REPO / "tests" / "control" / "test_testkit.py").read_bytes()).hexdigest()
    assert "distribution armlab-example-controller 0.1.0" in text
    assert f"SHA-256 {sha[:16]}" in text and "test_testkit.py" in text


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time under pytest -n
def test_example_and_module_object_controllers_run_on_a_local_ray_instance(site, tmp_path):
    pytest.importorskip("ray")
    proc = _record(site, _params(tmp_path), tmp_path / "out", "--executor", "ray")
    assert proc.returncode == 0, proc.stderr
    _check(tmp_path / "out")


@pytest.mark.slow
def test_the_installed_example_passes_the_kit(site):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(REPO)])}
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "check-controller", "pd_gravity_accff"],
        capture_output=True, text=True, timeout=300, cwd=REPO, env=env,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
