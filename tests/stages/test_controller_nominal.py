"""A controller's own ``nominal:``: the same law on the CAD model and on another model file
in one scenario, recorded side by side, compared by seed in one report, each bag naming
the nominal it ran on; a missing file or another robot's model refused in one line."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import pytest
import yaml

from pipeline.identify.model_file import FORMAT, model_robot_document, write_model
from pipeline.robots.loaders import load_spec
from tests.stages.controller_study import cli, settings_of
from tests.stages.controller_study import params_file as study_params

SEEDS = (0, 1)


def model_file(path: Path, robot: str, *, mass_scale: float) -> Path:
    """A model file of ``robot`` (as ``pipeline identify fit`` writes one) whose link
    masses are the CAD ones x ``mass_scale``: a nominal model that is not the CAD one."""
    spec = load_spec(robot)
    doc: dict[str, Any] = {"format": FORMAT, **model_robot_document(spec)}
    for joint in doc["robot"]["joints"]:
        joint["inertial"]["mass"] *= mass_scale
    n = spec.dof
    doc["friction"] = {"coulomb_nm": [0.0] * n, "viscous_nm_s_rad": [0.0] * n,
                       "offset_nm": [0.0] * n}  # fmt: skip
    doc["identification"] = {"robot": spec.name}
    write_model(path, doc)
    return path


def params_file(folder: Path, nominal: str) -> Path:
    """UR5, short episodes: ctc on the CAD model and ctc on ``nominal``, seeds 0 and 1."""
    controllers = {"ctc": {"type": "ctc"}, "ctc_id": {"type": "ctc", "nominal": nominal}}
    return study_params(
        folder,
        controllers=controllers,
        seeds={c: SEEDS for c in controllers},
        scenario_extra={
            "timing": {"velocity_scaling": 1.0, "acceleration_scaling": 1.0},
            "plant": {"payload_kg": 1.0},
        },
    )


@pytest.mark.slow
def test_cad_and_identified_nominal_compared_by_seed_in_one_report(tmp_path: Path) -> None:
    folder = tmp_path / "study"
    (folder / "models").mkdir(parents=True)
    model = model_file(folder / "models" / "ur5.yaml", "ur5", mass_scale=1.3)
    # relative to the params file's folder, run from elsewhere
    params = params_file(folder, "models/ur5.yaml")
    rec = cli("record", "--params", str(params), "--out", str(tmp_path / "rec"), cwd=tmp_path)
    assert rec.returncode == 0, rec.stderr
    digest = hashlib.sha256(model.read_bytes()).hexdigest()
    for seed in SEEDS:
        cad = settings_of(tmp_path / "rec" / f"ctc-{seed}")["controller"]
        own = settings_of(tmp_path / "rec" / f"ctc_id-{seed}")["controller"]
        assert "nominal" not in cad  # the scenario's (CAD): recorded as before
        assert own["nominal"] == {"file": "study/models/ur5.yaml", "sha256": digest}
    out = tmp_path / "report"
    rep = cli("report", "--recordings", str(tmp_path / "rec"), "--out", str(out),
              "--baseline", "ctc", cwd=tmp_path)  # fmt: skip
    assert rep.returncode == 0, rep.stderr
    text = (out / "report.md").read_text()
    assert "**ctc_id vs ctc** in `s` (2 seed pairs" in text
    assert f"- ctc_id: `study/models/ur5.yaml` (SHA-256 {digest[:16]}…)." in text
    assert "- ctc: the robot description's (CAD) values." in text


def test_a_missing_controller_nominal_is_refused_in_one_line(tmp_path: Path) -> None:
    params = params_file(tmp_path, "models/none.yaml")
    proc = cli("record", "--params", str(params), "--out", str(tmp_path / "rec"), cwd=tmp_path)
    assert proc.returncode != 0
    assert proc.stderr.strip().count("\n") == 0, proc.stderr
    assert "controllers.ctc_id.nominal:" in proc.stderr
    assert "models/none.yaml: no such model file" in proc.stderr
    assert not (tmp_path / "rec").exists() or not any((tmp_path / "rec").iterdir())


def test_another_robots_model_as_controller_nominal_is_refused(tmp_path: Path) -> None:
    """A UR10 model (same joint names, other link lengths) as the UR5 controller's."""
    (tmp_path / "models").mkdir()
    model_file(tmp_path / "models" / "ur10.yaml", "ur10", mass_scale=1.0)
    params = params_file(tmp_path, "models/ur10.yaml")
    proc = cli("record", "--params", str(params), "--out", str(tmp_path / "rec"), cwd=tmp_path)
    assert proc.returncode != 0
    assert proc.stderr.strip().count("\n") == 0, proc.stderr
    assert "controllers.ctc_id.nominal: models/ur10.yaml is a model of robot 'ur10'" in (
        proc.stderr
    )


def test_a_controller_nominal_is_read_from_the_params_folder_and_kept_by_a_campaign(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from pipeline.params import load_params
    from pipeline.stages.campaign_expand import expand

    folder = tmp_path / "study"
    folder.mkdir()
    data = yaml.safe_load(params_file(folder, "models/ur5-s{seed}.yaml").read_text())
    data["campaigns"] = {"c": {"scenario": "s", "controllers": ["ctc", "ctc_id"], "seeds": 2}}
    (folder / "params.yaml").write_text(yaml.safe_dump(data))
    monkeypatch.chdir(tmp_path)
    params = load_params(folder / "params.yaml")
    assert params.controllers["ctc_id"].nominal == "study/models/ur5-s{seed}.yaml"
    episodes = {e.controller_name: e for e in expand(params, "c")}
    assert episodes["ctc_id"].controller.nominal == "study/models/ur5-s{seed}.yaml"
    # a controller without one dumps (and fingerprints) as before the field existed
    assert "nominal" not in episodes["ctc"].controller.model_dump()
