"""The PID's closed-loop modes on the UR5 with and without a pure actuation delay.

Linearizes the sampled loop (MuJoCo's one-step transition at a held pose, with gravity
compensated by the integrator, and the PID's discrete law as ``pipeline.control.pid``
computes it) and prints each mode's equivalent continuous frequency, damping ratio and
the joint it lives on, for delays of 0, 1 and 2 control periods. The nominal plant (the
realistic plant's Coulomb friction has no linearization). Used by docs/control.md,
"The study".

    python studies/pid_modes.py [--pose start|goal] [--period-steps N]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import mujoco
import numpy as np

from pipeline.control import default_gains
from pipeline.model.mjcf import build_mujoco_model
from pipeline.robots import RobotSpec, load_spec
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD
from pipeline.trajectory import F64


def closed_loop(spec: RobotSpec, q0: Sequence[float], *, delay: int, dt_s: float) -> F64:
    """The closed-loop transition matrix and the index ranges of q and qd in its state."""
    # MuJoCo's finite-difference transition supports the Euler integrators only: the
    # linearization is of the semi-implicit Euler step at the control period
    model = build_mujoco_model(spec, timestep_s=dt_s, integrator="Euler")
    data = mujoco.MjData(model)
    n = spec.dof
    data.qpos[:] = q0
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    data.ctrl[:] = data.qfrc_bias  # held: the integrator carries gravity
    a = np.zeros((2 * n, 2 * n))
    b = np.zeros((2 * n, n))
    mujoco.mjd_transitionFD(model, data, 1e-7, True, a, b, None, None)
    g = default_gains(spec, "pid", omega_n_rad_s=40.0, zeta=1.0)
    kp, kd, ki = (np.diag(np.asarray(g[k], dtype=float)) for k in ("kp", "kd", "ki"))
    # state [dq, dv, s (integral before this step), w_1..w_d (commands in flight)]
    # I_k = s_k - ki dt dq_k;  u_k = -kp dq_k - kd dv_k + I_k;  s_{k+1} = I_k
    size = 3 * n + delay * n
    m = np.zeros((size, size))
    u_row = np.hstack([-kp - ki * dt_s, -kd, np.eye(n), np.zeros((n, delay * n))])
    applied = u_row if delay == 0 else np.eye(size)[3 * n + (delay - 1) * n : 3 * n + delay * n]
    m[: 2 * n, : 2 * n] = a
    m[: 2 * n] += b @ applied
    m[2 * n : 3 * n] = np.hstack(
        [-ki * dt_s, np.zeros((n, n)), np.eye(n), np.zeros((n, delay * n))]
    )
    for i in range(delay):  # w_1 <- u_k, w_{i+1} <- w_i
        rows = slice(3 * n + i * n, 3 * n + (i + 1) * n)
        m[rows] = u_row if i == 0 else np.eye(size)[3 * n + (i - 1) * n : 3 * n + i * n]
    return m


def modes(
    spec: RobotSpec, q0: Sequence[float], *, delay: int, dt_s: float
) -> list[tuple[str, float, float, float]]:
    """(joints, |s| [rad/s], damping ratio, |lambda|) per mode with arm motion in it,
    fastest first; ``joints`` names the joints that carry >= 30 % of the mode's
    mass-weighted amplitude ``sqrt(m_jj) |dq_j|`` (the largest first)."""
    import pinocchio as pin

    from pipeline.robots.urdf import build_pinocchio_model

    n = spec.dof
    pmodel = build_pinocchio_model(spec)
    mass = pin.crba(pmodel, pmodel.createData(), np.asarray(q0, dtype=float))
    weight = np.sqrt(np.diag(mass))
    vals, vecs = np.linalg.eig(closed_loop(spec, q0, delay=delay, dt_s=dt_s))
    out = []
    for lam, vec in zip(vals, vecs.T, strict=True):
        if lam.imag < -1e-12:
            continue  # one of each conjugate pair
        shape = weight * (np.abs(vec[:n]) + np.abs(vec[n : 2 * n]) * dt_s)
        if shape.sum() < 1e-6 * np.abs(vec).sum():
            continue  # a delay-line or integrator state alone
        order = np.argsort(-shape)
        names = [
            spec.joint_names[i].replace("_joint", "")
            for i in order
            if shape[i] >= 0.3 * shape[order[0]]
        ]
        s = np.log(lam.astype(complex)) / dt_s
        zeta = -s.real / abs(s) if abs(s) > 0 else 1.0
        out.append(("+".join(names), float(abs(s)), float(zeta), float(abs(lam))))
    return sorted(out, key=lambda r: -r[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pose", choices=("start", "goal"), default="start")
    parser.add_argument("--dt", type=float, default=0.001)
    args = parser.parse_args()
    spec = load_spec("ur5")
    q0 = PAPER_START_RAD if args.pose == "start" else PAPER_GOAL_RAD
    for delay in (0, 1, 2):
        print(f"delay {delay} period(s) of {args.dt * 1e3:g} ms, pose {args.pose}")
        for joint, w, zeta, mag in modes(spec, q0, delay=delay, dt_s=args.dt):
            print(f"  {joint:34s} |s| {w:8.1f} rad/s  zeta {zeta:6.3f}  |lambda| {mag:.4f}")
    radius = [
        float(np.abs(np.linalg.eigvals(closed_loop(spec, q0, delay=d, dt_s=args.dt))).max())
        for d in range(7)
    ]
    print("spectral radius for a delay of 0..6 periods:", ", ".join(f"{r:.4f}" for r in radius))


if __name__ == "__main__":
    main()
