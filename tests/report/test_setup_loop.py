"""The report's Setup names a non-ideal loop (delay, encoder) and stays silent on the ideal one."""

from __future__ import annotations

import dataclasses
import json

from pipeline.report.setup import _loop_lines
from pipeline.settings import LoopSettings


def test_setup_names_a_delayed_loop_and_not_the_ideal_one() -> None:
    delayed = _loop_lines(LoopSettings(delay_s=0.001, velocity="encoder"))
    assert len(delayed) == 1
    assert "delay_s = 0.001" in delayed[0] and "velocity = encoder" in delayed[0]
    assert _loop_lines(LoopSettings()) == []
    assert _loop_lines(None) == []  # a bag written before the loop settings


def test_setup_states_the_armature_and_its_source() -> None:
    from pipeline.report.setup import _armature_lines, _armature_text
    from pipeline.robots.loaders import load_spec

    robot = load_spec("ur5")
    nominal = [0.4, 0.4, 0.2, 0.04, 0.04, 0.04]
    line = _armature_text(robot, nominal, None)
    assert "[0.4, 0.4, 0.2, 0.04, 0.04, 0.04]" in line
    assert "source: estimated per joint size" in line
    line = _armature_text(robot, nominal, "models/ur5-s{seed}.yaml")
    assert "source: identified (`nominal: models/ur5-s{seed}.yaml`)" in line
    assert _armature_lines(None, []) == []


def test_the_gain_design_is_recorded_typed_and_shown_in_the_setup() -> None:
    """issue 28: ``design_at`` and the inertia the gains were scaled by leave the gains and
    become ``settings.controller.design``, which the Setup prints per controller."""
    from types import SimpleNamespace

    from pipeline.control import make_controller
    from pipeline.control.controller import with_planned_path
    from pipeline.report.setup import _design_lines
    from pipeline.robots.loaders import load_spec
    from pipeline.settings import ControllerSettings, GainDesign

    spec = load_spec("ur5")
    qs = [[0.0] * 6, [0.1, -0.5, 0.8, -1.0, -0.3, 0.0]]
    gains = make_controller("pid", spec, with_planned_path({}, qs)).gains_in_effect()
    design, rest = GainDesign.split_from(gains)
    assert design is not None and design.at == "path" and len(design.inertia_kg_m2) == 6
    assert "design_at" not in rest and "kp" in rest
    recorded = ControllerSettings(name="pid", type="pid", gains=rest, design=design)
    back = ControllerSettings.from_dict(json.loads(json.dumps(dataclasses.asdict(recorded))))
    assert back.design == design
    given, _ = GainDesign.split_from({**gains, "design_at": qs[1]})
    assert given is not None and given.at == "given" and list(given.q_rad) == qs[1]
    rec = SimpleNamespace(controller="pid", settings=SimpleNamespace(controller=back))
    (blank, line) = _design_lines([rec, rec])
    assert blank == ""
    assert "`pid`'s default gains designed at **path**" in line
    assert "largest nominal inertia along the planned motion" in line
    # bags written before issue 28 have no design: nothing shown
    old = ControllerSettings.from_dict({"name": "pid", "type": "pid", "gains": {}})
    assert old.design is None
    assert (
        _design_lines([SimpleNamespace(controller="pid", settings=SimpleNamespace(controller=old))])
        == []
    )
