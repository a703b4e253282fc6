"""fit refuses unmeasured efforts and a bag of another robot; nominal: checks the robot."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.errors import IdentificationError
from pipeline.identify.model_file import nominal_spec, spec_document
from pipeline.identify.stage import fit_command
from pipeline.pathlist import summarise_paths
from pipeline.robots.loaders import load_spec

from .conftest import fourier, record
from .test_inputs import _truth, write_humble_db3


def test_all_zero_efforts_are_refused(ideal_bags: tuple[Path, Path], tmp_path: Path) -> None:
    names, q, qd, tau = _truth(ideal_bags[0])
    path = tmp_path / "zero"
    zero = np.zeros_like(tau[:3000])
    write_humble_db3(path, names=names, q=q[:3000], qd=qd[:3000], effort=zero)
    with pytest.raises(IdentificationError, match=r"effort of shoulder_pan_joint, .* is all zero"):
        fit_command([path], out=tmp_path / "m.yaml", robot="ur5", cutoff_hz=0.0)
    assert not (tmp_path / "m.yaml").exists()


def test_one_constant_effort_is_refused_naming_the_joint(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    names, q, qd, tau = _truth(ideal_bags[0])
    tau = tau[:3000].copy()
    tau[:, names.index("wrist_2_joint")] = 1.5
    path = tmp_path / "stuck"
    write_humble_db3(path, names=names, q=q[:3000], qd=qd[:3000], effort=tau)
    with pytest.raises(
        IdentificationError, match=r"effort of wrist_2_joint is constant \(1.5 N m\)"
    ):
        fit_command([path], out=tmp_path / "m.yaml", robot="ur5", cutoff_hz=0.0)


def test_a_ur5_bag_fitted_as_ur10_is_refused(ideal_bags: tuple[Path, Path], tmp_path: Path) -> None:
    with pytest.raises(IdentificationError, match="recorded on robot 'ur5', not on --robot ur10"):
        fit_command([ideal_bags[0]], out=tmp_path / "m.yaml", robot="ur10", cutoff_hz=0.0)
    assert not (tmp_path / "m.yaml").exists()


@pytest.fixture(scope="module")
def ur5_model(ideal_bags: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("model") / "ur5.yaml"
    fit_command([ideal_bags[0]], out=path, cutoff_hz=0.0)
    return path


def test_nominal_takes_the_right_robots_model(ur5_model: Path) -> None:
    assert (
        nominal_spec(load_spec("ur5"), str(ur5_model)).joint_names == load_spec("ur5").joint_names
    )


def test_nominal_refuses_a_ur10_model_on_the_ur5(ur5_model: Path, tmp_path: Path) -> None:
    """Same joint names, other link lengths: a UR10 model (its robot section) on the UR5."""
    doc = yaml.safe_load(ur5_model.read_text())
    ur10 = spec_document(load_spec("ur10"))
    doc["robot"] = {**ur10, "name": "ur10"}
    doc["identification"]["robot"] = "ur10"
    doc["identification"]["robot_sha256"] = ""
    path = tmp_path / "ur10.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(
        IdentificationError, match=r"model of robot 'ur10', not of .* 'ur5' \(flange poses"
    ):
        nominal_spec(load_spec("ur5"), str(path), where="scenarios.s")


def test_nominal_refuses_a_model_of_another_robot_file(ur5_model: Path, tmp_path: Path) -> None:
    doc = yaml.safe_load(ur5_model.read_text())
    assert len(doc["identification"]["robot_sha256"]) == 64
    doc["identification"]["robot_sha256"] = "0" * 64  # fitted on an edited ur5.yaml
    path = tmp_path / "edited.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(IdentificationError, match="identified on robot file sha256 000000000000"):
        nominal_spec(load_spec("ur5"), str(path), where="scenarios.s")


def test_a_long_path_list_is_summarised_with_the_full_list_in_a_file() -> None:
    paths = [f"bags/b{i:04d}" for i in range(2000)]
    text = summarise_paths(paths, what="recording")
    assert text.startswith(
        "2000 recordings (bags/b0000, bags/b0001, bags/b0002, ...; all listed in "
    )
    listed = Path(text.rsplit("all listed in ", 1)[1].rstrip(")"))
    assert listed.read_text().split() == paths
    listed.unlink()
    assert summarise_paths(paths[:2]) == "bags/b0000, bags/b0001"


def test_fit_over_many_unexcited_bags_is_one_short_line(tmp_path: Path) -> None:
    bag = record(tmp_path / "two_joints", fourier(3, joints=slice(0, 2)), hold_s=0.1)
    bags = [bag]
    for k in range(7):
        (tmp_path / f"copy{k}").symlink_to(bag)
        bags.append(tmp_path / f"copy{k}")
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "identify", "fit", *map(str, bags), "--out",
         str(tmp_path / "m.yaml")],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: 8 recordings ("), proc.stderr
    assert "not excited" in lines[0] and len(lines[0]) < 600
    listed = Path(lines[0].split("all listed in ", 1)[1].split(")", 1)[0])
    assert listed.read_text().split() == list(map(str, bags))


def test_our_dh_ur5_and_the_ros_ur5_urdf_are_one_robot_the_ur10_is_not() -> None:
    from pipeline.identify.identity import kinematics_mismatch
    from pipeline.robots.packages import package_search_path

    roots = [p / "example-robot-data" for p in package_search_path()]
    root = next((r for r in roots if r.is_dir()), None)
    if root is None:
        pytest.skip("example-robot-data is not installed")
    urdf = root / "robots" / "ur_description" / "urdf"
    ur5 = load_spec("ur5")
    assert kinematics_mismatch(ur5, load_spec(str(urdf / "ur5_robot.urdf"))) is None
    assert kinematics_mismatch(ur5, load_spec(str(urdf / "ur10_robot.urdf"))) is not None
    assert kinematics_mismatch(ur5, load_spec("ur10")) is not None
