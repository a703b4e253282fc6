"""Friction feed-forward (``friction_ff: true``): the nominal model's Coulomb + viscous
friction of the reference velocity, smooth through zero, on ctc, ctc_pid and pid_ff."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.control import make_controller
from pipeline.control.controller import friction_feedforward
from pipeline.errors import ParamsError
from pipeline.experiment.assemble import draw_scenario_plant, scenario_spec
from pipeline.identify.model_file import (
    FORMAT,
    nominal_path,
    spec_document,
    with_nominal_friction,
)
from pipeline.params import load_params
from pipeline.robots.loaders import load_spec

REPO = Path(__file__).parents[2]
FC = [3.0, 3.0, 2.0, 0.8, 0.8, 0.8]  # params.yaml's paper-realistic plant
FV = [1.0, 1.0, 0.8, 0.3, 0.3, 0.3]


def _gains(on: bool) -> dict[str, object]:
    return {"friction_ff": on, "friction_coulomb_nm": FC, "friction_viscous_nm_s_rad": FV}


def test_the_torque_is_smooth_through_zero_and_off_unless_asked() -> None:
    spec = load_spec("ur5")
    c = make_controller("ctc", spec, _gains(True))
    gains = {k: np.asarray(v) if isinstance(v, list) else v for k, v in c.gains_in_effect().items()}
    assert np.array_equal(friction_feedforward(gains, np.zeros(6)), np.zeros(6))
    fast = friction_feedforward(gains, np.full(6, 1.0))
    assert fast is not None
    np.testing.assert_allclose(fast, np.array(FC) + np.array(FV), rtol=1e-9)
    tiny = friction_feedforward(gains, np.full(6, 1e-4))  # 1 % of the smoothing scale
    assert tiny is not None and np.all(np.abs(tiny) < 0.011 * np.array(FC) + 1e-3)
    assert friction_feedforward({**gains, "friction_ff": False}, np.ones(6)) is None
    # off by default: the law is unchanged
    off = make_controller("ctc", spec).gains_in_effect()
    assert not any(k.startswith("friction") for k in off), off  # recorded only when on
    on = make_controller("ctc_pid", spec, _gains(True)).gains_in_effect()
    assert on["friction_ff"] is True and on["friction_coulomb_nm"] == FC


def test_a_model_law_without_the_option_refuses_it() -> None:
    with pytest.raises(ParamsError, match="friction_ff"):
        make_controller("pid", load_spec("ur5"), {"friction_ff": True})


def test_a_nominal_model_file_fills_in_the_friction_and_explicit_values_win(
    tmp_path: Path,
) -> None:
    path = tmp_path / "ur5-s3.yaml"
    doc = {
        "format": FORMAT,
        "robot": spec_document(load_spec("ur5")),
        "friction": {
            "coulomb_nm": [2.9] * 6,
            "viscous_nm_s_rad": [0.9] * 6,
            "offset_nm": [0.1] * 6,
        },
    }
    path.write_text(yaml.safe_dump(doc))
    model = nominal_path(str(tmp_path / "ur5-s{seed}.yaml"), seed=3)
    assert model == str(path)
    filled = with_nominal_friction({"friction_ff": True}, model)
    assert filled["friction_coulomb_nm"] == [2.9] * 6
    assert filled["friction_viscous_nm_s_rad"] == [0.9] * 6
    given = with_nominal_friction({"friction_ff": True, "friction_coulomb_nm": 1.0}, model)
    assert given["friction_coulomb_nm"] == 1.0
    assert with_nominal_friction({"kp": 1.0}, model) == {"kp": 1.0}
    assert with_nominal_friction({"friction_ff": True}, None) == {"friction_ff": True}


@pytest.mark.parametrize("seed", [0, 1])
def test_friction_feedforward_reduces_ctc_tracking_error_on_the_realistic_plant(
    seed: int,
) -> None:
    """The paper's motion on a drawn realistic plant (sticking friction, drawn links,
    noise): CTC plus the plant's Coulomb and viscous friction as feed-forward has a
    smaller max error on every joint than CTC alone."""
    from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
    from pipeline.sim.runner import run_episode

    scenario = load_params(REPO / "params.yaml").scenarios["paper-realistic"]
    spec = scenario_spec(scenario)
    plant_spec, plant, _ = draw_scenario_plant(spec, scenario, seed=seed)
    reference = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=3.0)
    max_error = {}
    for on in (False, True):
        result = run_episode(
            spec, reference=reference, controller=make_controller("ctc", spec, _gains(on)),
            seed=seed, plant=plant, plant_spec=plant_spec, hold_s=1.0, preroll_s=1.0,
            position_noise_std_rad=scenario.plant.position_noise_std_rad,
            velocity_noise_std_rad_s=scenario.plant.velocity_noise_std_rad_s,
        )  # fmt: skip
        assert result.status == "ok"
        max_error[on] = np.abs(result.q_ref - result.q_true).max(axis=0)
    assert np.all(max_error[True] < max_error[False]), max_error
