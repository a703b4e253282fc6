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
