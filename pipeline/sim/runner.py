# long: one episode's whole loop: plant, settled pre-roll, motion, settled hold, loop effects
"""One control episode: MuJoCo plant, zero-order-hold control loop, divergence detection.

The plant is the MuJoCo model built from the spec (optionally mismatched:
damping, Coulomb friction, armature, payload); the controller keeps its own
nominal model. Each control period the loop reads the plant state, adds the
(pre-drawn, seeded) sensor noise, asks the controller for a torque, clips it
to the effort limits, writes it to the motors and steps the physics
``control_period_steps`` times with that torque held.

The loop is the record stage's hot path: every array is preallocated, the
reference is sampled before the loop (in one call when the reference has
``sample_many``), noise is drawn in bulk, and saturation flags and the
result are assembled after it. Per step it costs a handful of small numpy
operations besides ``mj_step`` and the controller (see ``benches/sim_loop.py``).

A diverged episode is a result, not an exception: NaN/inf state, a MuJoCo
warning (bad qpos/qvel/qacc/ctrl, full contact or constraint buffers) or a
joint speed beyond ``divergence_speed_factor`` times its velocity limit
ends it with ``status="diverged"`` and a reason naming the time, the joint
and the cause; the rows before it are kept.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import mujoco
import numpy as np

from pipeline.constants import PLANT_FRICTION, PLANT_INTEGRATOR
from pipeline.control.controller import Controller
from pipeline.errors import SimulationError
from pipeline.model.mjcf import PlantOptions
from pipeline.model.published import SigmoidFriction
from pipeline.model.scene import Box
from pipeline.robots.spec import RobotSpec
from pipeline.settings import LoopSettings
from pipeline.sim.contact_gate import ContactGate
from pipeline.sim.loop import Actuator, Sensor, align_to_motion, check_loop
from pipeline.sim.plant import SIGMOID_FRICTION, SigmoidForce, plant_model, same_geometry
from pipeline.sim.result import F64, EpisodeResult, Reference
from pipeline.sim.settling import SETTLING, integral_state, settled

DIVERGENCE_SPEED_FACTOR = 10.0
"""A joint faster than this many times its velocity limit is out of control."""

_WARNING_NAMES = tuple(mujoco.mjtWarning(i).name for i in range(int(mujoco.mjtWarning.mjNWARNING)))
# warnings whose ``lastinfo`` is a dof (= joint) index, or an actuator (= joint) index
_PER_JOINT_WARNINGS = frozenset(
    int(w)
    for w in (
        mujoco.mjtWarning.mjWARN_BADQPOS,
        mujoco.mjtWarning.mjWARN_BADQVEL,
        mujoco.mjtWarning.mjWARN_BADQACC,
        mujoco.mjtWarning.mjWARN_BADCTRL,
    )
)

_INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")
"""MuJoCo's integrators, as MJCF names them."""

ProgressFn = Callable[[float], None]


def run_episode(
    spec: RobotSpec,
    *,
    reference: Reference,
    controller: Controller,
    seed: int,
    plant: PlantOptions | None = None,
    obstacles: Sequence[Box] = (),
    physics_dt_s: float = 0.001,
    control_period_steps: int = 1,
    integrator: str = PLANT_INTEGRATOR,
    hold_s: float = 1.0,
    preroll_s: float = 0.0,
    hold_max_s: float | None = None,
    settle: bool = True,
    plant_spec: RobotSpec | None = None,
    position_noise_std_rad: float = 0.0,
    velocity_noise_std_rad_s: float = 0.0,
    divergence_speed_factor: float = DIVERGENCE_SPEED_FACTOR,
    loop: LoopSettings | None = None,
    progress: ProgressFn | None = None,
    friction: SigmoidFriction | None = None,
    effort_offset_nm: Sequence[float] = (),
    effort_noise_std_nm: float = 0.0,
    contact_gate: bool = True,
) -> EpisodeResult:
    """Run ``controller`` on the MuJoCo plant along ``reference``, then hold the goal.

    Starts at rest at ``reference.sample(0)``, holds it under the same controller until
    settled, for at most ``preroll_s`` (the settled start: a ros2_control controller
    holding the start pose before a goal arrives), then runs the reference for
    ``reference.duration_s`` and holds the goal for ``hold_s`` (longer, up to
    ``hold_max_s``, until settled). Row k of the result is control instant ``k *
    physics_dt_s * control_period_steps`` from the pre-roll's start (the last row is the
    state at the end, with the torque that would be applied next); the motion starts
    at row ``motion_start_row``, time ``motion_start_s`` (the
    pre-roll rounded to whole control periods).

    Args:
        spec: robot (must have dynamics).
        reference: joint reference; ``sample_many`` is used when present.
        controller: anything satisfying ``pipeline.control.Controller``; reset first.
        seed: seed of the sensor-noise generator (``numpy.random.default_rng``).
        plant: plant mismatch (damping, friction, armature, payload); None = nominal.
        obstacles: boxes added to the MuJoCo scene.
        physics_dt_s: MuJoCo time step [s].
        control_period_steps: physics steps per control update (torque held between).
        integrator: MuJoCo's integrator ("RK4", "Euler", "implicit", "implicitfast").
        hold_s: time kept at the goal after the reference ends [s].
        preroll_s: the longest the start pose is held before the reference starts [s]:
            the pre-roll ends at the first settled window (``pipeline.sim.settling``);
            ``preroll_settled`` says whether it did before this cap.
        settle: end the pre-roll when settled; False: hold the start pose for the
            whole ``preroll_s`` (identification's excitation, whose data is not a metric).
        hold_max_s: the longest the goal is held [s]: after ``hold_s`` the hold goes on,
            a settling window at a time, until settled; None (or <= ``hold_s``): exactly
            ``hold_s``. ``hold_settled`` says whether the hold's last window is
            settled either way.
        plant_spec: the plant's robot (drawn link parameters, armature); None = ``spec``.
            The controller keeps its own nominal model either way.
        position_noise_std_rad: Gaussian noise on measured position [rad].
        velocity_noise_std_rad_s: Gaussian noise on measured velocity [rad/s].
        divergence_speed_factor: end the episode when a joint exceeds this many
            times its velocity limit.
        loop: actuation delay and jitter, encoder quantisation, encoder velocity
            (``pipeline.sim.loop``); None = the ideal loop.
        progress: called with the completed fraction in [0, 1] about every 1 %.
        friction: a sigmoid joint friction (a published plant's), applied as a generalized
            force held over each control period (``pipeline.sim.plant.SigmoidForce``).
        effort_offset_nm, effort_noise_std_nm: the torque sensor's offset per joint and
            Gaussian noise [N m] on what is recorded as effort (``tau_nm``); the noise has
            its own stream of ``seed``, so it changes no other draw.
        contact_gate: skip the plant's collision detection in control periods where no
            contact is possible (``pipeline.sim.contact_gate``: the same states, bit for
            bit); False: MuJoCo's collision detection in every step.

    Raises:
        SpecError: the robot has no dynamics.
        SimulationError: bad settings or a malformed reference or controller output.
    """
    spec.require_dynamics("simulation")
    _check_settings(
        seed=seed,
        physics_dt_s=physics_dt_s,
        control_period_steps=control_period_steps,
        integrator=integrator,
        hold_s=hold_s,
        preroll_s=preroll_s,
        hold_max_s=hold_max_s,
        position_noise_std_rad=position_noise_std_rad,
        velocity_noise_std_rad_s=velocity_noise_std_rad_s,
        divergence_speed_factor=divergence_speed_factor,
    )
    loop = loop or LoopSettings()
    check_loop(loop, physics_dt_s=physics_dt_s, velocity_noise_std_rad_s=velocity_noise_std_rad_s)
    plant = plant or PlantOptions()
    plant_spec = plant_spec or spec
    plant_spec.require_dynamics("simulation")
    if plant_spec.joint_names != spec.joint_names:
        raise SimulationError(
            f"plant_spec: joints {plant_spec.joint_names} differ from the robot's "
            f"{spec.joint_names}"
        )
    # a drawn plant is set on the robot's compiled model (pipeline.sim.plant): bit for bit
    # the model a compile of plant_spec gives, without compiling per episode
    model = plant_model(
        spec,
        plant_spec,
        timestep_s=physics_dt_s,
        plant=plant,
        obstacles=obstacles,
        integrator=integrator,
    )
    data = mujoco.MjData(model)
    dof = spec.dof
    gate = None
    if contact_gate and (plant_spec == spec or same_geometry(spec, plant_spec)):
        gate = ContactGate(
            model,
            spec,
            obstacles=tuple(obstacles),
            control_dt_s=physics_dt_s * control_period_steps,
        )

    duration_s = _reference_duration(reference)
    control_dt_s = physics_dt_s * control_period_steps
    period_ns = round(physics_dt_s * 1e9) * control_period_steps
    # rows: the pre-roll (at most cap_rows, in windows of the settling criterion), then the
    # motion and the hold (motion_rows, the last one recorded but not stepped; up to
    # max_motion_rows while the hold is not settled); n bounds them all, so the noise and
    # the jitter draws do not depend on where the hold ends. When the pre-roll ends early
    # the motion's rows are given the draws of the rows a full pre-roll would have given
    # them (align_to_motion): the motion meets the same noise however long it was held
    cap_rows = round(preroll_s / control_dt_s)
    window_rows = max(1, round(SETTLING.window_s / control_dt_s))
    motion_rows = math.ceil((duration_s + hold_s) / control_dt_s - 1e-9) + 1
    longest_hold_s = max(hold_s, hold_max_s or 0.0)
    max_motion_rows = math.ceil((duration_s + longest_hold_s) / control_dt_s - 1e-9) + 1
    n = cap_rows + max_motion_rows
    stamp_ns = np.arange(n, dtype=np.int64) * period_ns
    times_s: F64 = np.arange(n, dtype=np.float64) * control_dt_s
    motion_q, motion_qd, motion_qdd = _sample_reference(reference, times_s[:max_motion_rows], spec)
    # pre-roll: hold the start pose exactly (no velocity or acceleration feed-forward);
    # the motion's samples are put in place once the pre-roll has ended
    q_ref = np.empty((n, dof))
    q_ref[:] = motion_q[0]
    qd_ref = np.zeros((n, dof))
    qdd_ref = np.zeros((n, dof))

    rng = np.random.default_rng(seed)
    noisy = position_noise_std_rad > 0 or velocity_noise_std_rad_s > 0
    q_true = np.empty((n, dof))
    qd_true = np.empty((n, dof))
    q_meas, qd_meas, noise_q, noise_qd = q_true, qd_true, q_true, qd_true
    if noisy:
        # drawn in a fixed order (position block, then velocity block) so a seed
        # reproduces the same noise whatever the loop does
        noise_q = rng.standard_normal((n, dof)) * position_noise_std_rad
        noise_qd = rng.standard_normal((n, dof)) * velocity_noise_std_rad_s
        q_meas = np.empty((n, dof))
        qd_meas = np.empty((n, dof))
    sensor: Sensor | None = None
    actuator: Actuator | None = None
    if not loop.ideal:  # pipeline.sim.loop; the ideal loop keeps the lines above
        sensor = Sensor(
            loop,
            control_dt_s=control_dt_s,
            noise_q=noise_q if noisy else None,
            noise_qd=noise_qd if noisy else None,
        )
        actuator = Actuator(
            loop, rows=n, nstep=control_period_steps, physics_dt_s=physics_dt_s, seed=seed
        )
        q_meas, qd_meas = np.empty((n, dof)), np.empty((n, dof))
    tau_cmd = np.empty((n, dof))
    tau_app = np.empty((n, dof))

    data.qpos[:] = q_ref[0]
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    controller.reset()

    control_loop = _Loop(
        spec=spec,
        model=model,
        data=data,
        controller=controller,
        times_s=times_s,
        control_dt_s=control_dt_s,
        nstep=control_period_steps,
        speed_factor=divergence_speed_factor,
        sensor=sensor,
        actuator=actuator,
        friction=SigmoidForce(friction, data) if friction is not None else None,
        gate=gate,
    )

    def run_rows(first: int, stop: int, *, final: bool) -> tuple[int, str]:
        return control_loop.run(
            q_true, qd_true, q_meas, qd_meas, noise_q, noise_qd if noisy else None,
            q_ref, qd_ref, qdd_ref, tau_cmd, tau_app, progress or _no_progress,
            first=first, stop=stop, final=final,
        )  # fmt: skip

    with _captured_mujoco_warnings() as warning_texts:
        start_row, preroll_settled, rows, reason = _preroll(
            run_rows, controller, q_true, qd_true, q_ref, cap_rows, window_rows, check=settle
        )
        hold_settled = False
        if not reason:
            if noisy:
                align_to_motion(noise_q, start_row=start_row, cap_rows=cap_rows)
                align_to_motion(noise_qd, start_row=start_row, cap_rows=cap_rows)
            if actuator is not None:
                actuator.align_to_motion(start_row=start_row, cap_rows=cap_rows)
            end = start_row + max_motion_rows
            q_ref[start_row:end] = motion_q
            qd_ref[start_row:end] = motion_qd
            qdd_ref[start_row:end] = motion_qdd
            last, hold_settled, rows, reason = _hold(
                run_rows, controller, q_true, qd_true, q_ref,
                start_row, start_row + motion_rows - 1, end - 1, window_rows,
            )  # fmt: skip
            if not reason:
                rows, reason = run_rows(last, last + 1, final=True)
        if reason and warning_texts and "MuJoCo warning" in reason:
            reason += f': "{warning_texts[0]}"'
    motion_start_s = start_row * control_dt_s

    # A non-finite command is the controller's failure, whatever MuJoCo made of it
    # (it zeroes a NaN ctrl and warns one step later; the last row is never stepped).
    bad = ~np.isfinite(tau_cmd[:rows]).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        j = int(np.argmax(~np.isfinite(tau_cmd[k])))
        rows = k
        reason = (
            f"diverged at t={times_s[k]:.4f} s: controller '{controller.name}' returned a "
            f"non-finite torque for {spec.joint_names[j]} ({tau_cmd[k, j]})"
        )
    if progress is not None:
        progress(1.0)

    effort = spec.effort_limits
    applied = tau_cmd if actuator is None else actuator.applied(tau_cmd, rows)
    np.clip(applied[:rows], -effort, effort, out=tau_app[:rows])
    saturated = np.abs(tau_cmd[:rows]) > effort
    _torque_sensor(
        tau_app[:rows], effort_offset_nm, effort_noise_std_nm,
        seed=seed, rows=n, start_row=start_row, cap_rows=cap_rows,
    )  # fmt: skip
    warnings = {
        name: int(count)
        for name, count in zip(_WARNING_NAMES, data.warning.number, strict=True)
        if count
    }
    arrays: dict[str, Any] = {
        "stamp_ns": stamp_ns[:rows],
        "q": q_meas[:rows],
        "qd": qd_meas[:rows],
        "q_true": q_true[:rows],
        "qd_true": qd_true[:rows],
        "q_ref": q_ref[:rows],
        "qd_ref": qd_ref[:rows],
        "qdd_ref": qdd_ref[:rows],
        "tau_cmd_nm": tau_cmd[:rows],
        "tau_nm": tau_app[:rows],
        "saturated": saturated,
    }
    for a in arrays.values():
        a.flags.writeable = False  # the result is frozen; so are its arrays
    return EpisodeResult(
        joint_names=spec.joint_names,
        **arrays,
        status="diverged" if reason else "ok",
        reason=reason,
        mujoco_warnings=warnings,
        controller=controller.name,
        gains_in_effect=controller.gains_in_effect(),
        seed=int(seed),
        physics_dt_s=float(physics_dt_s),
        control_period_steps=int(control_period_steps),
        control_period_s=float(control_dt_s),
        integrator=integrator,
        friction_model=PLANT_FRICTION if friction is None else SIGMOID_FRICTION,
        motion_start_row=int(start_row),
        motion_start_s=float(motion_start_s),
        preroll_settled=bool(preroll_settled),
        hold_settled=bool(hold_settled),
        rows_planned=int(rows if not reason else start_row + motion_rows),
        loop=loop,
    )


def _torque_sensor(
    tau: F64,
    offset_nm: Sequence[float],
    noise_std_nm: float,
    *,
    seed: int,
    rows: int,
    start_row: int,
    cap_rows: int,
) -> None:
    """Add the torque sensor's offset and noise to ``tau`` in place (what is recorded as
    effort). The noise is drawn for all ``rows`` the episode may have, in one block of its
    own stream, and aligned to the motion's start (:func:`align_to_motion`), so where the
    pre-roll or the episode ends does not change the motion's noise."""
    if len(offset_nm):
        tau += np.asarray(offset_nm, dtype=np.float64)
    if noise_std_nm > 0:
        from pipeline.model.uncertainty import EFFORT_NOISE_STREAM

        rng = np.random.default_rng([int(seed), EFFORT_NOISE_STREAM])
        noise = rng.standard_normal((rows, tau.shape[1]))
        align_to_motion(noise, start_row=start_row, cap_rows=cap_rows)
        tau += noise[: tau.shape[0]] * noise_std_nm


def _no_progress(fraction: float) -> None:
    """Default progress callback: nothing to draw."""


RunRows = Callable[..., tuple[int, str]]


def _preroll(
    run_rows: RunRows,
    controller: Controller,
    q_true: F64,
    qd_true: F64,
    q_ref: F64,
    cap_rows: int,
    window_rows: int,
    *,
    check: bool = True,
) -> tuple[int, bool, int, str]:
    """Hold the start pose in windows until one is settled (``pipeline.sim.settling``)
    or ``cap_rows`` have passed (``check`` False: all of them, in one run; the flag then
    says whether the last window is settled, its integral not judged).

    Returns:
        (the motion's first row, settled before the cap, rows recorded, divergence
        reason or ""). With no pre-roll (``cap_rows`` 0) the start counts as settled:
        the episode starts at rest at the start pose.
    """
    if not check and cap_rows:
        rows, reason = run_rows(0, cap_rows, final=False)
        if reason:
            return 0, False, rows, reason
        last = slice(max(0, cap_rows - window_rows), cap_rows)
        return cap_rows, settled(q_ref[last] - q_true[last], qd_true[last]), cap_rows, ""
    row = 0
    while row < cap_rows:
        stop = min(row + window_rows, cap_rows)
        before = integral_state(controller)
        rows, reason = run_rows(row, stop, final=False)
        if reason:
            return row, False, rows, reason
        if stop - row == window_rows and settled(
            q_ref[row:stop] - q_true[row:stop],
            qd_true[row:stop],
            integral_before=before,
            integral_after=integral_state(controller),
        ):
            return stop, True, stop, ""
        row = stop
    return cap_rows, cap_rows == 0, cap_rows, ""


def _hold(
    run_rows: RunRows,
    controller: Controller,
    q_true: F64,
    qd_true: F64,
    q_ref: F64,
    start: int,
    last: int,
    cap: int,
    window_rows: int,
) -> tuple[int, bool, int, str]:
    """Run the motion and the hold from row ``start`` up to (not including) row ``last``,
    then, while the last window (``window_rows``, or what the episode has) is not settled,
    one more window at a time up to row ``cap``.

    Returns:
        (the episode's final row, the hold's last window settled, rows recorded,
        divergence reason or "").
    """
    row = max(start, last - window_rows)
    rows, reason = run_rows(start, row, final=False) if row > start else (row, "")
    if reason:
        return rows, False, rows, reason
    while True:
        before = integral_state(controller)
        rows, reason = run_rows(row, last, final=False)
        if reason:
            return rows, False, rows, reason
        if settled(
            q_ref[row:last] - q_true[row:last],
            qd_true[row:last],
            integral_before=before,
            integral_after=integral_state(controller),
        ):
            return last, True, last, ""
        if last + window_rows > cap:
            return last, False, last, ""
        row, last = last, last + window_rows


class _Loop:
    """The control loop and its divergence diagnosis (state kept off the hot path)."""

    def __init__(
        self,
        *,
        spec: RobotSpec,
        model: Any,
        data: Any,
        controller: Controller,
        times_s: F64,
        control_dt_s: float,
        nstep: int,
        speed_factor: float,
        sensor: Sensor | None = None,
        actuator: Actuator | None = None,
        friction: SigmoidForce | None = None,
        gate: ContactGate | None = None,
    ) -> None:
        self.spec = spec
        self.model = model
        self.data = data
        self.controller = controller
        self.times_s = times_s
        self.control_dt_s = control_dt_s
        self.nstep = nstep
        self.speed_factor = speed_factor
        self.speed_limits = spec.velocity_limits
        self.sensor = sensor
        self.actuator = actuator
        self.friction = friction
        self.gate = gate

    def run(
        self,
        q_true: F64,
        qd_true: F64,
        q_meas: F64,
        qd_meas: F64,
        noise_q: F64,
        noise_qd: F64 | None,
        q_ref: F64,
        qd_ref: F64,
        qdd_ref: F64,
        tau_cmd: F64,
        tau_app: F64,
        progress: ProgressFn,
        *,
        first: int = 0,
        stop: int | None = None,
        final: bool = True,
    ) -> tuple[int, str]:
        """Fill rows ``first`` to ``stop`` (default: all) row by row; return (rows recorded,
        divergence reason or ""). The physics steps after every row but a ``final`` run's
        last one (the episode's end: its torque is recorded, never applied).

        ``q_meas`` and ``qd_meas`` may be ``q_true`` and ``qd_true`` themselves (no noise,
        ideal loop): the controller then reads the plant's state rows.
        """
        model, data, nstep, dt = self.model, self.data, self.nstep, self.control_dt_s
        compute = self.controller.compute
        step = mujoco.mj_step
        add = np.add
        qpos, qvel, ctrl = data.qpos, data.qvel, data.ctrl
        warn = data.warning.number  # a live view of MuJoCo's warning counters
        clean = np.zeros_like(warn).tobytes()
        # divergence: a MuJoCo warning, or the weighted |qd|^2 beyond speed_factor^2 (NaN
        # and inf fail it too) sends a row to the per-joint diagnosis. Before the weighted
        # test, |qd| (math.hypot, cheaper) against the slowest joint's limit with a 1 %
        # margin: a row within it has no joint near its limit, so the diagnosis would find
        # nothing there; the same rows end the episode as with the weighted test alone.
        weights = 1.0 / self.speed_limits**2
        limit_sq = self.speed_factor**2
        slowest = float(np.min(self.speed_limits, initial=np.inf))
        bound = 0.99 * self.speed_factor * slowest if math.isfinite(slowest) else 0.0
        hypot = math.hypot
        total = q_true.shape[0]
        n = total if stop is None else stop
        last = n - 1 if final else -1
        span = max(1, total - 1)
        tick = max(1, total // 100)
        next_tick = (first // tick + 1) * tick
        noisy = noise_qd is not None
        shape = (self.spec.dof,)
        sensor, actuator, friction = self.sensor, self.actuator, self.friction
        gate = self.gate

        def physics(steps: int) -> None:
            step(model, data, steps)

        # one row view of every array per step from one zip (cheaper than indexing each);
        # the arrays a loop does not use are a repeated None
        unused = itertools.repeat(None)
        measured = (q_meas, qd_meas) if sensor is not None or noisy else (unused, unused)
        noises = (noise_q, noise_qd) if noisy and sensor is None else (unused, unused)
        arrays = (q_true, qd_true, *measured, *noises, q_ref, qd_ref, qdd_ref, tau_cmd)
        rows = zip(
            range(first, n),
            *(a if a is unused else a[first:n] for a in arrays),
            strict=False,  # (the repeated None is endless)
        )
        for k, qt, vt, qm, vm, nq, nv, qr, vr, ar, tc_row in rows:
            qt[:] = qpos
            vt[:] = qvel
            speed = hypot(*vt.tolist())
            if warn.tobytes() != clean or (
                not speed <= bound and not (vt * weights).dot(vt) <= limit_sq
            ):
                reason = self._diagnose(k, qt, vt)
                if reason:
                    return k, reason
            if sensor is not None:
                sensor.measure(k, qt, vt, qm, vm)
            elif noisy:
                add(qt, nq, qm)
                add(vt, nv, vm)
            else:
                qm, vm = qt, vt
            try:
                tc = compute(qm, vm, qr, vr, ar, dt)
                if tc.shape != shape:  # a (1,) or scalar torque would broadcast silently
                    raise ValueError(f"got shape {tc.shape}")
                tc_row[:] = tc
            except (ValueError, AttributeError) as err:
                raise SimulationError(
                    f"controller '{self.controller.name}' failed at t={self.times_s[k]:.4f} s "
                    f"(expected an array of {self.spec.dof} torques): {err}"
                ) from err
            # the motors' ctrlrange (= +-effort) clamps inside MuJoCo; tau_app gets the
            # same clip for all rows at once after the loop (saves ~1 us per step)
            ctrl[:] = tc
            if k == last:
                break
            if friction is not None:  # held over the control period, as the torque
                friction.apply(vt)
            if gate is not None:  # contacts on or off for this period
                gate.before_period(qt, vt, speed)
            if actuator is None:
                step(model, data, nstep)
            else:
                actuator.advance(k, tau_cmd, ctrl, physics)
            if k == next_tick:
                progress(k / span)
                next_tick += tick
        return n, ""

    def _diagnose(self, k: int, q: F64, qd: F64) -> str:
        """Why row k is not a controlled state ("" if it is, after all)."""
        t = f"t={self.times_s[k]:.4f} s"
        names = self.spec.joint_names
        numbers = self.data.warning.number
        if numbers.any():
            i = int(np.argmax(numbers != 0))
            info = int(self.data.warning.lastinfo[i])
            where = (
                f"joint {names[info]}"
                if i in _PER_JOINT_WARNINGS and 0 <= info < len(names)
                else f"info {info}"
            )
            return f"diverged by {t}: MuJoCo warning {_WARNING_NAMES[i]} at {where}"
        finite = np.isfinite(q) & np.isfinite(qd)
        if not finite.all():
            j = int(np.argmax(~finite))
            return f"diverged at {t}: {names[j]} state is not finite (q={q[j]}, qd={qd[j]})"
        ratio = np.abs(qd) / self.speed_limits
        j = int(np.argmax(ratio))
        if ratio[j] > self.speed_factor:
            return (
                f"diverged at {t}: {names[j]} speed {abs(qd[j]):.4g} rad/s exceeds "
                f"{self.speed_factor:g} x its velocity limit ({self.speed_limits[j]:.4g} rad/s)"
            )
        return ""


@contextmanager
def _captured_mujoco_warnings() -> Iterator[list[str]]:
    """Collect MuJoCo's warning texts instead of letting it print them.

    The warning goes into the episode's ``reason``; printing it would break the
    CLI's progress bar. MuJoCo's handler is process-global, so restore it after.
    """
    texts: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(texts.append)
    try:
        yield texts
    finally:
        mujoco.set_mju_user_warning(previous)


def _check_settings(
    *,
    seed: int,
    physics_dt_s: float,
    control_period_steps: int,
    integrator: str,
    hold_s: float,
    preroll_s: float,
    hold_max_s: float | None,
    position_noise_std_rad: float,
    velocity_noise_std_rad_s: float,
    divergence_speed_factor: float,
) -> None:
    def number(x: object) -> bool:
        return isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool)

    if not (isinstance(seed, int | np.integer) and not isinstance(seed, bool) and seed >= 0):
        raise SimulationError(f"seed: expected a non-negative integer, got {seed!r}")
    if not (number(physics_dt_s) and math.isfinite(physics_dt_s) and physics_dt_s > 0):
        raise SimulationError(
            f"physics_dt_s: expected a positive time step [s], got {physics_dt_s!r}"
        )
    if not (
        isinstance(control_period_steps, int | np.integer)
        and not isinstance(control_period_steps, bool)
        and control_period_steps >= 1
    ):
        raise SimulationError(
            f"control_period_steps: expected an integer >= 1 (physics steps per control "
            f"update), got {control_period_steps!r}"
        )
    if integrator not in _INTEGRATORS:
        raise SimulationError(
            f"integrator: expected one of {', '.join(_INTEGRATORS)}, got {integrator!r}"
        )
    for name, value in (
        ("hold_s", hold_s),
        ("preroll_s", preroll_s),
        ("position_noise_std_rad", position_noise_std_rad),
        ("velocity_noise_std_rad_s", velocity_noise_std_rad_s),
    ):
        if not (number(value) and math.isfinite(value) and value >= 0):
            raise SimulationError(f"{name}: expected a finite number >= 0, got {value!r}")
    if hold_max_s is not None and not (number(hold_max_s) and math.isfinite(hold_max_s)):
        raise SimulationError(f"hold_max_s: expected a finite time [s] or None, got {hold_max_s!r}")
    if not (
        number(divergence_speed_factor)
        and math.isfinite(divergence_speed_factor)
        and divergence_speed_factor > 0
    ):
        raise SimulationError(
            f"divergence_speed_factor: expected a positive number, got {divergence_speed_factor!r}"
        )


def _reference_duration(reference: Reference) -> float:
    duration = reference.duration_s
    if not (isinstance(duration, int | float) and math.isfinite(duration) and duration >= 0):
        raise SimulationError(
            f"reference.duration_s: expected a finite time >= 0 [s], got {duration!r}"
        )
    return float(duration)


def _sample_reference(reference: Reference, times_s: F64, spec: RobotSpec) -> tuple[F64, F64, F64]:
    """Reference position, velocity, acceleration at every control instant, (N, n) each."""
    sample_many = getattr(reference, "sample_many", None)
    if callable(sample_many):
        arrays = tuple(sample_many(times_s))
    else:
        samples = [reference.sample(float(t)) for t in times_s]
        arrays = tuple(np.array([s[i] for s in samples]) for i in range(3))
    if len(arrays) != 3:
        raise SimulationError(
            f"reference: expected (position, velocity, acceleration), got {len(arrays)} arrays"
        )
    out = []
    expected = (len(times_s), spec.dof)
    for what, arr in zip(("position", "velocity", "acceleration"), arrays, strict=True):
        a = np.ascontiguousarray(arr, dtype=float)
        if a.shape != expected:
            raise SimulationError(
                f"reference: {what} samples have shape {a.shape}, expected {expected} "
                f"({spec.dof} joints of {spec.name})"
            )
        bad = ~np.isfinite(a)
        if bad.any():
            k, j = (int(x) for x in np.argwhere(bad)[0])
            raise SimulationError(
                f"reference: {what} of {spec.joint_names[j]} is {a[k, j]} at t={times_s[k]:.4f} s"
            )
        out.append(a)
    return out[0], out[1], out[2]
