"""dvc.yaml's deps must cover every pipeline module a stage's command really loads.

Otherwise DVC would skip a stage whose code changed. `make sync` writes the deps from the
commands' import closure, found by scanning the source (pipeline/devtools/deps.py); here
each stage runs for real in a fresh interpreter that prints the pipeline modules it
imported: a cross-check of the scan.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.stages.provenance import RECORD_CODE

REPO = Path(__file__).parents[1]
_PROBE = """
import atexit, json, sys
OUT = sys.argv[1]
def dump():
    import pipeline
    root = pipeline.__path__[0]
    files = sorted({m.__file__[len(root) + 1:] for name, m in list(sys.modules.items())
                    if name.startswith("pipeline") and getattr(m, "__file__", None)})
    with open(OUT, "w") as f:
        json.dump(files, f)
atexit.register(dump)
sys.argv = ["pipeline", *sys.argv[2:]]
from pipeline.cli import main
main()
"""


def _loaded(tmp_path: Path, name: str, *args: str) -> list[str]:
    out = tmp_path / f"{name}.json"
    subprocess.run(
        [sys.executable, "-c", _PROBE, str(out), *args], cwd=REPO, check=True, capture_output=True
    )
    return [f"pipeline/{f}" for f in json.loads(out.read_text())]


def _deps(stage: dict) -> list[str]:
    return [d for d in stage["deps"] if d.startswith("pipeline")]


def _covered(path: str, deps: list[str]) -> bool:
    return any(path == d or path.startswith(d.rstrip("/") + "/") for d in deps)


@pytest.mark.slow
def test_stage_deps_cover_every_module_the_stage_loads(tmp_path):
    stages = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"]
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = 0.1
    data["scenarios"]["paper"]["goal"] = {
        "pose": {"position": [0.5, 0.1, 0.3], "rpy": [3.14159, 0.0, 0.0]}
    }
    for scenario in data["scenarios"].values():
        scenario.update(preroll_s=0.1, hold_s=0.1)
    data["campaigns"] = {"c": {"scenario": "paper-realistic", "controllers": ["pid"],
                               "goals": {"random": 1, "radius_rad": 0.2}}}  # fmt: skip
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    rec, rep = tmp_path / "rec", tmp_path / "rep"
    record = _loaded(tmp_path, "record", "record", "--params", str(params), "--out", str(rec))
    campaign = _loaded(
        tmp_path, "campaign", "record", "--params", str(params), "--out", str(rec), "-j", "2",
        "--campaign", "c",
    )  # fmt: skip
    report = _loaded(tmp_path, "report", "report", "--recordings", str(rec), "--out", str(rep))
    assert (rep / "metrics.json").is_file()

    record_deps = _deps(stages["record"]["do"])
    missing = [f for f in record if not _covered(f, record_deps)]
    assert not missing, f"dvc.yaml record deps miss {missing}"
    campaign_deps = _deps(stages["campaign"]["do"])
    missing = [f for f in campaign if not _covered(f, campaign_deps)]
    assert not missing, f"dvc.yaml campaign deps miss {missing}"
    report_deps = _deps(stages["report"])
    missing = [f for f in report if not _covered(f, report_deps)]
    assert not missing, f"dvc.yaml report deps miss {missing}"


def test_recordings_carry_the_commit_of_exactly_the_record_stage_code():
    stages = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"]
    assert sorted(f"pipeline/{p}" for p in RECORD_CODE) == sorted(_deps(stages["record"]["do"]))
    assert _deps(stages["campaign"]["do"]) == _deps(stages["record"]["do"])
