"""The plug-in seam: built-in, entry point, ``module:Object``; origins; one-line errors."""

from __future__ import annotations

import hashlib
import textwrap
from pathlib import Path

import pytest

from pipeline.control import (
    CONTROLLERS,
    UnknownControllerError,
    controller_entry,
    controller_origin,
    installed_controllers,
    make_controller,
)
from pipeline.control.info import declared_color, stiffness_gains
from pipeline.errors import KinematicsError, ParamsError
from pipeline.kinematics.numeric import NumericLMSolver
from pipeline.kinematics.solvers import installed_solvers, make_solver, solver_factory
from pipeline.report.colors import FIXED, PALETTE, controller_colors
from pipeline.settings import ControllerSettings

GOOD = "tests.control.test_testkit:GoodPd"


def _distribution(root: Path, name: str, entry_points: str, module: str = "") -> None:
    """A minimal installed distribution on ``root`` (what pip --target leaves)."""
    info = root / f"{name}-1.2.3.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.2.3\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points))
    if module:
        (root / f"{name}.py").write_text(textwrap.dedent(module))


@pytest.fixture
def installed(tmp_path, monkeypatch):
    """Two controller entry points (one good, one that fails to import) and an IK solver."""
    _distribution(
        tmp_path,
        "armlab_fake_plugin",
        """
        [armlab.controllers]
        fake_pd = tests.control.test_testkit:GoodPd
        fake_broken = armlab_no_such_module:Thing
        [armlab.ik_solvers]
        fake_lm = pipeline.kinematics.numeric:NumericLMSolver
        """,
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def test_a_built_in_resolves_to_its_registry_entry_with_a_builtin_origin():
    assert controller_entry("pid") is CONTROLLERS["pid"]
    assert controller_origin("ctc") == {"kind": "builtin"}


def test_an_installed_entry_point_resolves_and_names_its_distribution(installed, ur5):
    assert {"fake_pd", "fake_broken"} <= set(installed_controllers())
    ctl = make_controller("fake_pd", ur5, {"kp": 10.0})
    assert ctl.name == "good_pd" and ctl.gains_in_effect()["kp"] == [10.0] * 6
    origin = controller_origin("fake_pd")
    assert origin["kind"] == "entry_point"
    assert (origin["distribution"], origin["version"]) == ("armlab_fake_plugin", "1.2.3")
    assert origin["group"] == "armlab.controllers"


def test_a_module_object_resolves_and_names_its_file_and_sha256(ur5):
    assert make_controller(GOOD, ur5).name == "good_pd"
    origin = controller_origin(GOOD)
    path = Path(origin["path"])
    assert origin["kind"] == "module" and path.name == "test_testkit.py"
    assert origin["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()


def test_unknown_name_lists_built_in_and_installed_names_with_the_near_miss(installed, ur5):
    with pytest.raises(UnknownControllerError) as err:
        make_controller("fake_dp", ur5, source="controllers.mine")
    message = str(err.value)
    assert message.startswith("controllers.mine.type: unknown controller 'fake_dp'")
    assert "(did you mean 'fake_pd'?)" in message
    assert "valid: " + ", ".join(sorted(CONTROLLERS)) in message
    assert "installed (armlab.controllers): " in message and "fake_pd" in message
    assert "\n" not in message


@pytest.mark.parametrize(
    ("name", "words"),
    [
        ("fake_broken", "entry point armlab_no_such_module:Thing in armlab.controllers): cannot "
                        "load: ModuleNotFoundError"),
        ("armlab_no_such_module:Thing", "cannot import armlab_no_such_module: ModuleNotFoundError"),
        ("tests.control.test_testkit:Nope", "module tests.control.test_testkit has no 'Nope'"),
        ("tests.control.test_testkit:NOT_A_CONTROLLER", "is not a controller: expected a "
                                                        "ControllerEntry or a class with GAINS"),
    ],
)  # fmt: skip
def test_bad_plug_ins_get_one_line(installed, ur5, name, words):
    with pytest.raises(UnknownControllerError) as err:
        make_controller(name, ur5, source="controllers.mine")
    message = str(err.value)
    assert message.startswith("controllers.mine.type: ") and words in message
    assert "\n" not in message


def test_a_plug_in_refuses_gains_it_does_not_declare_in_one_line(ur5):
    with pytest.raises(ParamsError) as err:
        make_controller(GOOD, ur5, {"ki": 1.0}, source="controllers.mine")
    message = str(err.value)
    assert message.startswith("controllers.mine.gains.ki: unknown good_pd gain 'ki'")
    assert "valid: kp, kd" in message and "\n" not in message


def test_the_report_asks_the_entry_which_gains_are_stiffnesses(installed):
    assert stiffness_gains("pid") == ("kp",) and stiffness_gains("pd_gravity") == ("kp",)
    assert stiffness_gains("ctc") == () and stiffness_gains("ctc_pid") == ()
    assert stiffness_gains("fake_pd") == ("kp",)  # an installed entry point
    assert stiffness_gains(GOOD) is None  # a name read from a bag is never imported
    assert stiffness_gains("not_a_controller_anywhere") is None


def test_colours_come_from_the_entries_and_others_take_free_palette_colours(installed):
    assert {n: e.color for n, e in CONTROLLERS.items() if e.color is not None} == FIXED
    assert declared_color("fake_pd") == (188, 189, 34)
    assert declared_color(GOOD) is None  # module:Object from data: plain text
    colors = controller_colors(["pid", "ctc", "fake_pd", "zz_a", "zz_b"])
    assert colors["pid"] == CONTROLLERS["pid"].color and colors["fake_pd"] == (188, 189, 34)
    assert colors["zz_a"] != colors["zz_b"]
    assert {colors["zz_a"], colors["zz_b"]}.isdisjoint({*FIXED.values(), (188, 189, 34)})
    assert set(colors.values()) <= set(PALETTE)


def test_ik_solvers_resolve_the_same_way(installed, ur5):
    assert "fake_lm" in installed_solvers()
    assert solver_factory("fake_lm") is NumericLMSolver
    assert isinstance(
        make_solver("pipeline.kinematics.numeric:NumericLMSolver", ur5), NumericLMSolver
    )
    with pytest.raises(KinematicsError) as err:
        make_solver("fake_ml", ur5)
    assert "did you mean 'fake_lm'" in str(err.value) and "installed (armlab.ik_solvers)" in str(
        err.value
    )
    with pytest.raises(KinematicsError, match="is not a solver factory"):
        make_solver("tests.control.test_testkit:NOT_A_CONTROLLER", ur5)


def test_settings_without_an_origin_read_as_built_in_and_an_origin_round_trips():
    old = ControllerSettings.from_dict({"name": "pid", "type": "pid", "gains": {}})
    assert old.origin == {"kind": "builtin"}
    origin = {"kind": "module", "object": GOOD, "path": "/x.py", "sha256": "ab"}
    new = {"name": "mine", "type": GOOD, "gains": {"kp": [1.0]}, "origin": origin}
    assert ControllerSettings.from_dict(new).origin == origin
