"""Default gains are designed where the arm moves (issue 28): the closed-loop bandwidth
PID achieves along the planned motion, sqrt(kp_j / M_jj(q)) with MuJoCo's inertia (not
Pinocchio's, which designed the gains), stays within 25 % of the target on every moving
joint."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from pipeline.control import make_controller
from pipeline.control.controller import with_planned_path
from pipeline.errors import ParamsError
from pipeline.model.mjcf import build_mujoco_model
from pipeline.params import load_params
from pipeline.planning import plan_path, time_parameterize
from pipeline.robots import load_spec
from pipeline.stages.plans import plan_scenario

ROOT = Path(__file__).resolve().parents[2]
ROBOTS = Path(mujoco.__file__).parents[1] / "cmeel.prefix/share/example-robot-data/robots"
XARM7 = ROBOTS / "xarm_description/urdf/xarm7.urdf"
# a reach-and-turn from a working pose (elbow bent), as a pick-and-place would move
XARM_START = [0.0, 0.3, 0.0, 0.8, 0.0, 0.5, 0.0]
XARM_GOAL = [1.2, 0.5, -0.4, 1.1, 0.4, 0.6, 0.5]
W = 40.0  # the target natural frequency [rad/s] (params.yaml's)


def _motion(case: str):
    """(spec, planned positions (K, n)) of the case's planned motion, sampled every 10 ms."""
    if case == "xarm7":
        spec = load_spec(XARM7)
        path = plan_path(
            spec,
            start=np.array(XARM_START),
            goal=np.array(XARM_GOAL),
            obstacles=[],
            time_limit_s=2.0,
            simplify=True,
            seed=0,
        )
        trajectory = time_parameterize(spec, path, velocity_scaling=1.0, acceleration_scaling=1.0)
    else:
        params = load_params(ROOT / "params.yaml")
        plan = plan_scenario(case, params.scenarios[case], "params.yaml")
        assert plan.trajectory is not None, plan.error
        spec = load_spec(params.scenarios[case].robot)
        trajectory = plan.trajectory
    return spec, trajectory.samples(0.01).positions


def _mujoco_mass_diagonal(spec, qs):
    model = build_mujoco_model(spec)
    data = mujoco.MjData(model)
    full = np.zeros((model.nv, model.nv))
    out = []
    for q in qs:
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, full)
        out.append(np.diag(full).copy())
    return np.array(out)


CASES = ["paper", "panda-box", "xarm7"]


@pytest.mark.parametrize("case", CASES)
def test_pid_bandwidth_along_the_planned_motion_is_within_25_percent_of_the_target(case):
    spec, qs = _motion(case)
    moving = np.ptp(qs, axis=0) > 1e-3
    ctl = make_controller("pid", spec, with_planned_path({"omega_n_rad_s": W}, qs))
    gains = ctl.gains_in_effect()
    assert gains["design_at"] == "path"
    kp = np.array(gains["kp"])
    # local linearisation along the whole motion, MuJoCo's inertia
    ratio = np.sqrt(kp / _mujoco_mass_diagonal(spec, qs)) / W
    assert ratio[:, moving].min() >= 0.75, ratio.min(axis=0)
    assert ratio[:, moving].max() <= 1.25, ratio.max(axis=0)
    # the design statistic: per joint the largest inertia, so never below the target
    assert ratio[:, moving].min() >= 1.0 - 1e-9
    # with every joint free (the others' loops do not hold them), the inertia a joint's
    # loop meets at once is 1 / (M^-1)_jj < M_jj: faster, never slower (docs/control.md)


def test_the_old_rule_at_q_zero_misses_the_target_on_the_panda():
    """What the test above guards against: designed at q = 0 (upright, outside joint 4's
    limits), PID's shoulder joints 1 and 3 get 0.4-0.6 of the target along the motion."""
    spec, qs = _motion("panda-box")
    old = make_controller("pid", spec, {"omega_n_rad_s": W, "design_at": "path"})
    assert old.gains_in_effect()["design_at"] == "zero"  # no planned motion given
    from pipeline.control.registry import default_gains

    kp = np.array(default_gains(spec, "pid", omega_n_rad_s=W, q_config=np.zeros(7))["kp"])
    ratio = np.sqrt(kp / _mujoco_mass_diagonal(spec, qs)) / W
    assert ratio[:, [0, 2]].max() < 0.75


def test_design_at_start_and_a_given_configuration_use_that_inertia():
    spec = load_spec("ur5")
    qs = np.array([[0.0, -0.5, 0.8, 0.0, 0.0, 0.0], [0.5, -1.2, 1.5, 0.3, 0.2, 0.1]])
    m = _mujoco_mass_diagonal(spec, qs)
    for at, expect in (("path", m.max(axis=0)), ("start", m[0]), (qs[1].tolist(), m[1])):
        g = make_controller("pid", spec, with_planned_path({"design_at": at}, qs)).gains_in_effect()
        np.testing.assert_allclose(np.array(g["kp"]) / expect, W**2, rtol=1e-9)
        np.testing.assert_allclose(g["design_inertia_kg_m2"], expect, rtol=1e-9)
    # CTC's gains do not depend on it: nothing recorded
    ctc = make_controller("ctc", spec, with_planned_path({"omega_n_rad_s": W}, qs))
    assert set(ctc.gains_in_effect()) == {"kp", "kd", "omega_n_rad_s", "zeta"}


@pytest.mark.parametrize(
    ("design_at", "match"),
    [
        ([0.0] * 5, r"^controllers\.pid\.gains\.design_at: expected 6 finite joint angles"),
        (
            [0.0, 0.0, 9.0, 0.0, 0.0, 0.0],
            r"^controllers\.pid\.gains\.design_at: joint \w+ = 9 rad is outside",
        ),
        ("goal", r"^controllers\.pid\.gains\.design_at: expected 'path', 'start' or a list of 6"),
        (["a"] * 6, r"^controllers\.pid\.gains\.design_at: expected 'path', 'start'"),
    ],
)
def test_a_bad_design_at_is_one_line_naming_the_field(design_at, match):
    with pytest.raises(ParamsError, match=match):
        make_controller("pid", load_spec("ur5"), {"design_at": design_at}, source="controllers.pid")


def test_params_refuse_the_planned_path_which_the_pipeline_sets():
    from pipeline.params import ControllerParams

    with pytest.raises(ValueError, match=r"gains\.planned_path_rad: set from the planned motion"):
        ControllerParams(type="pid", gains={"planned_path_rad": [[0.0] * 6]})
