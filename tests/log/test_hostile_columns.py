"""Torques that are not real numbers, and non-finite gains, never reach a bag: the writer
refuses them in one line (complex torques used to lose their imaginary part, booleans to
be recorded as 0/1, NaN gains to be written into the episode's settings)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from pipeline.errors import RecordingError
from pipeline.log import bag
from tests.log.test_writer import analytic_episode, episode_metadata


@pytest.mark.parametrize(
    ("field", "dtype"), [("tau_cmd_nm", np.complex128), ("tau_nm", np.bool_), ("q", object)]
)
def test_torques_that_are_not_real_numbers_are_refused(ur5, tmp_path, field, dtype):
    result, planned = analytic_episode(ur5)
    values = getattr(result, field).astype(dtype)
    if dtype is np.complex128:
        values = values + 1j
    if dtype is object:
        values[0, 0] = "12"
    result = dataclasses.replace(result, **{field: values})
    with pytest.raises(RecordingError, match=rf"result.{field}: dtype .*, expected real numbers"):
        bag.write_episode_bag(
            tmp_path / "ep", spec=ur5, result=result, planned=planned, metadata=episode_metadata()
        )
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_gains_never_reach_the_bags_metadata(ur5, tmp_path, bad):
    result, planned = analytic_episode(ur5)
    settings = {"controller": {"name": "x", "type": "pid", "gains": {"kp": [1.0, bad]}}}
    metadata = {**episode_metadata(), "settings": json.dumps(settings)}
    with pytest.raises(RecordingError, match=r"controller.gains.kp\[1\] = (nan|inf): expected"):
        bag.write_episode_bag(
            tmp_path / "ep", spec=ur5, result=result, planned=planned, metadata=metadata
        )
    assert list(tmp_path.iterdir()) == []
