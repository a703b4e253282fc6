"""The controllers' declared facts (pipeline.control.info) are what the laws do."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from pipeline.control import controller_names, default_gains, make_controller, pd_gravity
from pipeline.control.controller import NominalPDController
from pipeline.control.info import builtin_info, controller_info, info_of
from pipeline.control.registry import controller_entry_of_class
from pipeline.model.uncertainty import draw_plant
from pipeline.settings import Uncertainty


def test_every_builtin_has_a_record_and_a_distinct_colour() -> None:
    info = builtin_info()
    assert sorted(info) == sorted(controller_names())
    colours = [i.color for i in info.values()]
    assert None not in colours and len(set(colours)) == len(colours)


def test_holds_gravity_is_what_the_class_declares_and_a_law_that_does_not_says_why() -> None:
    from pipeline.control.registry import CONTROLLERS

    for name, info in builtin_info().items():
        declared = str(getattr(CONTROLLERS[name].factory, "KIT_STEADY_OFFSET", ""))
        assert info.steady_offset == declared, name
        assert info.holds_gravity is (declared == ""), name


@pytest.mark.parametrize("name", controller_names())
def test_uses_nominal_model_is_whether_the_torque_depends_on_the_model(ur5, name) -> None:
    """Same gains, nominal models 30 % apart: a model-based law commands another torque,
    a model-free one the same."""
    other = draw_plant(ur5, Uncertainty(mass_rel=0.3, com_m=0.02, inertia_rel=0.3), seed=1)
    gains = default_gains(ur5, name)
    rng = np.random.default_rng(0)
    q, qd, q_ref, qd_ref, qdd_ref = (rng.uniform(-0.5, 0.5, ur5.dof) for _ in range(5))
    taus = [
        make_controller(name, spec, gains).compute(q, qd, q_ref, qd_ref, qdd_ref, 1e-3).copy()
        for spec in (ur5, other)
    ]
    differs = not np.allclose(taus[0], taus[1], rtol=1e-9, atol=1e-9)
    assert differs == controller_info(name).uses_nominal_model, (name, taus)


def test_a_name_that_is_no_controller_has_no_record() -> None:
    assert controller_info("not_a_controller_anywhere") is None
    assert controller_info("this:s") is None  # never imported


def test_reading_the_records_imports_no_controller_nor_physics_library() -> None:
    code = (
        "import sys; from pipeline.control.info import builtin_info, controller_info; "
        "builtin_info(); controller_info('pid'); controller_info('nope'); "
        "bad = [m for m in ('pinocchio', 'mujoco', 'pipeline.control.registry') "
        "if m in sys.modules]; assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


class _Law(NominalPDController):
    """A law as a plug-in writes it."""

    NAME = "law"
    DEFAULT_GAINS = staticmethod(pd_gravity.default_gains)
    COLOR = (1, 2, 3)
    KIT_STEADY_OFFSET = "no gravity term"


class _BadColour(_Law):
    COLOR = (300, 0, 0)


def test_a_plugin_class_is_read_as_the_registry_reads_it() -> None:
    info = info_of("law", _Law)
    assert info is not None and info.color == (1, 2, 3) and not info.holds_gravity
    assert info.uses_nominal_model and info.summary == "A law as a plug-in writes it."
    assert info == info_of("law", controller_entry_of_class(_Law))
    # what the registry refuses has no record (no colour, no stiffness gains)
    assert info_of("bad", _BadColour) is None
    assert info_of("bad", object()) is None


def test_every_controller_class_in_the_package_is_one_builtin_line() -> None:
    """A law added as a file in pipeline/control/ and not listed in BUILTIN fails here."""
    import importlib
    import pkgutil

    import pipeline.control
    from pipeline.control.registry import BUILTIN, CONTROLLERS

    found = set()
    for mod in pkgutil.iter_modules(pipeline.control.__path__):
        module = importlib.import_module(f"pipeline.control.{mod.name}")
        for attr, obj in vars(module).items():
            if (
                isinstance(obj, type)
                and obj.__module__ == module.__name__
                and isinstance(getattr(obj, "NAME", None), str)
                and hasattr(obj, "GAINS")
            ):
                found.add(f"{module.__name__}:{attr}")
    assert sorted(found) == sorted(BUILTIN)
    assert len(CONTROLLERS) == len(BUILTIN)


def test_a_builtin_line_that_names_no_controller_class_fails_naming_it() -> None:
    from pipeline.control.registry import _builtin

    assert _builtin("pipeline.control.pid:PidController")[0] == "pid"
    with pytest.raises(TypeError, match=r"'pipeline\.control\.pid:Nope' is no controller class"):
        _builtin("pipeline.control.pid:Nope")
