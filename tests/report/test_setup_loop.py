"""The report's Setup names a non-ideal loop (delay, encoder) and stays silent on the ideal one."""

from __future__ import annotations

from pipeline.report.setup import _loop_lines
from pipeline.settings import LoopSettings


def test_setup_names_a_delayed_loop_and_not_the_ideal_one() -> None:
    delayed = _loop_lines(LoopSettings(delay_s=0.001, velocity="encoder"))
    assert len(delayed) == 1
    assert "delay_s = 0.001" in delayed[0] and "velocity = encoder" in delayed[0]
    assert _loop_lines(LoopSettings()) == []
    assert _loop_lines(None) == []  # a bag written before the loop settings


def test_setup_states_the_armature_and_its_source() -> None:
    from pipeline.report.setup import _armature_lines
    from pipeline.robots.loaders import load_spec
    from pipeline.stages.assemble import spec_as_dict

    robot = spec_as_dict(load_spec("ur5"))
    plant = {"nominal_armature": [0.4, 0.4, 0.2, 0.04, 0.04, 0.04]}
    (line,) = _armature_lines(robot, plant, {})
    assert "[0.4, 0.4, 0.2, 0.04, 0.04, 0.04]" in line
    assert "source: estimated per joint size" in line
    (line,) = _armature_lines(robot, plant, {"nominal": "models/ur5-s{seed}.yaml"})
    assert "source: identified (`nominal: models/ur5-s{seed}.yaml`)" in line
    assert _armature_lines(None, {}, {}) == []
