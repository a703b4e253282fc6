from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.errors import SpecError
from pipeline.robots import builtin_robot_names, load_spec


def _ur5_data() -> dict:
    text = (Path(__file__).parents[2] / "pipeline/robots/ur5.yaml").read_text()
    return yaml.safe_load(text)


def _write(tmp_path: Path, data: object) -> Path:
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_builtin_robots_are_listed_and_load():
    names = builtin_robot_names()
    assert {"ur5", "ur10", "mdh_example", "panda_dh", "arm3_example"} <= set(names)
    dofs = {name: load_spec(name).dof for name in names}
    assert dofs["ur5"] == dofs["mdh_example"] == 6
    assert dofs["panda_dh"] == 7 and dofs["arm3_example"] == 3
    assert dofs["panda"] == 7  # the URDF Panda, gripper locked


def test_ur5_uses_manufacturer_values_not_the_papers_rounding(ur5):
    assert ur5.convention == "standard"
    assert ur5.joints[1].dh.a == -0.425
    assert ur5.joints[2].dh.a == -0.39225
    assert ur5.joints[0].dh.d == 0.089159
    assert ur5.joints[4].dh.alpha == pytest.approx(-math.pi / 2)
    assert ur5.joint_names[0] == "shoulder_pan_joint"
    assert list(ur5.effort_limits) == [150, 150, 150, 28, 28, 28]
    assert ur5.has_dynamics


def test_degrees_in_file_become_radians():
    spec = load_spec("mdh_example")
    assert spec.convention == "modified"
    assert spec.joints[1].dh.theta_offset == pytest.approx(math.radians(-172.22))
    assert spec.joints[1].dh.alpha == pytest.approx(-math.pi / 2)
    assert spec.joints[0].limits.upper == pytest.approx(math.radians(170))
    assert not spec.has_dynamics


def test_kinematics_only_robot_refuses_dynamics_clearly():
    with pytest.raises(SpecError, match=r"kinematics-only.*simulation needs link dynamics"):
        load_spec("mdh_example").require_dynamics("simulation")


def test_load_by_path(tmp_path):
    spec = load_spec(_write(tmp_path, _ur5_data()))
    assert spec.name == "ur5"
    assert spec.source.endswith("robot.yaml")


def test_unknown_name_lists_available_and_closest():
    with pytest.raises(SpecError) as err:
        load_spec("ur6")
    msg = str(err.value)
    assert "ur10" in msg and "mdh_example" in msg and "did you mean 'ur5'" in msg


@pytest.mark.parametrize(
    ("mutate", "expected"),
    [
        (
            lambda d: d["joints"][3]["limits"].update(lower=7.0),
            r"joints\[3\]\.limits: .*lower \(7.0\) must be < upper",
        ),
        (
            lambda d: d["joints"][2]["inertial"].update(mass=-1.0),
            r"joints\[2\]\.inertial\.mass: .*greater than or equal to 0.000001",
        ),
        (
            lambda d: d["joints"][0].update(dh=[0.0, float("nan"), 0.0, 0.0]),
            r"joints\[0\]\.dh\[1\]: .*finite",
        ),
        (
            lambda d: d["joints"][1]["inertial"].update(inertia=[1, 1, -1, 0, 0, 0]),
            r"joints\[1\]\.inertial\.inertia: .*positive definite",
        ),
        (
            lambda d: d["joints"][1]["inertial"].update(inertia=[1, 1, 5, 0, 0, 0]),
            r"joints\[1\]\.inertial\.inertia: .*triangle inequality",
        ),
        (lambda d: d["joints"][0].pop("limits"), r"joints\[0\]\.limits: Field required"),
        (lambda d: d["joints"][0].update(dh="zero"), r"joints\[0\]\.dh: "),
        (
            lambda d: d.update(convention="craig"),
            r"convention: Input should be 'standard' or 'modified'",
        ),
        (
            lambda d: d["joints"][4].update(colour="red"),
            r"joints\[4\]\.colour: Extra inputs are not permitted",
        ),
        (
            lambda d: d["joints"][5].update(name="elbow_joint"),
            r"duplicate joint name 'elbow_joint'",
        ),
    ],
)
def test_bad_yaml_names_file_and_field(tmp_path, mutate, expected):
    data = _ur5_data()
    mutate(data)
    path = _write(tmp_path, data)
    with pytest.raises(SpecError, match=expected) as err:
        load_spec(path)
    message = str(err.value)
    assert message.startswith(str(path) + ": ")
    assert "\n" not in message


def test_not_yaml_and_not_a_mapping(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(SpecError, match=r"bad.yaml: not valid YAML at line"):
        load_spec(bad)
    bad.write_text("- just\n- a list\n")
    with pytest.raises(SpecError, match=r"bad.yaml: expected a mapping"):
        load_spec(bad)
    with pytest.raises(SpecError, match="no such robot file"):
        load_spec(tmp_path / "missing.yaml")


def test_a_folder_named_like_a_robot_does_not_hide_the_builtin(tmp_path, monkeypatch):
    (tmp_path / "ur5").mkdir()
    monkeypatch.chdir(tmp_path)
    assert load_spec("ur5").name == "ur5"
    with pytest.raises(SpecError, match=r"is a directory, expected a robot YAML or URDF file"):
        load_spec("./ur5")


@pytest.mark.parametrize("name", builtin_robot_names())
def test_no_configuration_takes_the_flange_beyond_the_reach(name):
    from pipeline.model.dh import forward_kinematics

    spec = load_spec(name)
    rng = np.random.default_rng(0)
    for q in rng.uniform(spec.lower, spec.upper, size=(200, spec.dof)):
        assert np.linalg.norm(forward_kinematics(spec, q)[:3, 3]) <= spec.reach_m() + 1e-12
    assert spec.reach_m(spec.dof) == 0.0  # nothing beyond the last joint
