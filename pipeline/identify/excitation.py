"""Excitation design and recording: a Fourier series that makes the base regressor well
conditioned, run on the plant a scenario draws for a seed.

Design (Swevers et al. 1997; Gaz et al. 2019): the free Fourier coefficients of every
joint (:mod:`.fourier`) minimise ``log cond(Y_b)`` of the base regressor with unit-norm
columns, sampled over one period, plus a penalty for leaving :data:`LIMIT_SHARE` of the
velocity and acceleration limits or ``span_rad`` around the mid posture. L-BFGS-B from
random coefficients (``numpy.random.default_rng(variant)``), restarted until a budget of
objective evaluations is spent (:data:`DEFAULT_EVALUATIONS`; a count, not a time, so the
design is the same on any machine and under any load; a wall-clock cap only fails); the
best design is then scaled down onto the limits if it still leaves them, and
checked: within the position, velocity and acceleration limits and collision-free
(robot, floor, the scenario's obstacles) at every sample, or an error.

Recording: the reference runs under one of the params' controllers on the plant the
scenario draws for the seed (the record stage's draw: link parameters and armature from
``plant.uncertainty``, friction, damping, payload, sensor noise, a published profile's
sigmoid friction, the torque sensor's offset and noise), with the scenario's pre-roll and
hold, and is written as a rosbag2 recording like ``pipeline record``'s, its settings'
``plant`` describing that plant as an episode's does (:func:`scenario_plant`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from pipeline.errors import IdentificationError, ParamsError
from pipeline.identify.blas import one_thread
from pipeline.identify.defaults import DEFAULT_BUDGET_S, DEFAULT_EVALUATIONS
from pipeline.identify.fourier import FourierReference
from pipeline.identify.regressor import Regressor, base_parameters
from pipeline.robots.spec import RobotSpec

F64 = NDArray[np.float64]

LIMIT_SHARE = 0.9
"""Share of the velocity and acceleration limits the design may use."""
DESIGN_SAMPLES_PER_PERIOD = 60
CHECK_SAMPLES_PER_PERIOD = 1000
PENALTY = 1e3
EXPORT_RATE_HZ = 1000.0
CLEARANCE_M = 0.05
"""The design keeps this far from collisions (robot, floor, pedestal, obstacles) [m]."""


@dataclass(frozen=True)
class Design:
    """An excitation design.

    Attributes:
        reference: the Fourier series.
        condition_number_scaled: ``cond`` of the base regressor (unit-norm columns) over
            one period of the design samples.
        condition_number: the same, columns unscaled.
        evaluations: objective evaluations spent (the budget: the same on any machine).
        wall_s: design time [s] (machine-dependent: never recorded in a bag).
    """

    reference: FourierReference
    condition_number_scaled: float
    condition_number: float
    evaluations: int
    wall_s: float


class _Spent(Exception):
    """The evaluation budget is spent."""


class _OutOfTime(Exception):
    """The wall-clock safety cap has passed."""


def _conditions(y: F64) -> tuple[float, float]:
    sv = np.linalg.svd(y, compute_uv=False)
    norms = np.linalg.norm(y, axis=0)
    sv_scaled = np.linalg.svd(y / np.where(norms > 0, norms, 1.0), compute_uv=False)
    raw = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    scaled = float(sv_scaled[0] / sv_scaled[-1]) if sv_scaled[-1] > 0 else math.inf
    return scaled, raw


def limit_ratios(
    spec: RobotSpec, reference: FourierReference, *, span_rad: float, samples: int
) -> tuple[F64, F64, F64, F64]:
    """Per joint: |q - q0| / span, then position, velocity and acceleration use of limits.

    The position ratio is the larger excursion towards a limit over the room to it.
    """
    t = np.linspace(0.0, 1.0 / reference.base_frequency_hz, samples, endpoint=False)
    q, qd, qdd = reference.sample_many(t)
    q0 = np.asarray(reference.q0)
    dev = np.abs(q - q0).max(axis=0) / span_rad
    up = (q.max(axis=0) - q0) / np.maximum(spec.upper - q0, 1e-9)
    down = (q0 - q.min(axis=0)) / np.maximum(q0 - spec.lower, 1e-9)
    pos = np.maximum(up, down)
    vel = np.abs(qd).max(axis=0) / (LIMIT_SHARE * spec.velocity_limits)
    acc = np.abs(qdd).max(axis=0) / (LIMIT_SHARE * spec.acceleration_limits)
    return dev, pos, vel, acc


def design_excitation(
    spec: RobotSpec,
    *,
    q0: F64,
    variant: int,
    harmonics: int = 5,
    base_frequency_hz: float = 0.1,
    periods: int = 2,
    span_rad: float = 1.0,
    evaluations: int = DEFAULT_EVALUATIONS,
    budget_s: float = DEFAULT_BUDGET_S,
    obstacles: tuple[Any, ...] = (),
) -> Design:
    """Design excitation ``variant`` around ``q0`` (see the module docstring).

    Collisions enter the objective as a penalty on clearances below
    :data:`CLEARANCE_M` at the design samples. ``evaluations`` objective evaluations are
    spent (restarts of L-BFGS-B until then; the last one cut where the count runs out): the
    same inputs give the same design, bit for bit, whatever the machine's load.
    ``budget_s`` is only a safety cap on the wall-clock time.

    Raises:
        IdentificationError: bad settings, ``q0`` outside the limits, the design running
            past ``budget_s`` (one line: raise the cap or lower ``evaluations``).
    """
    dof = spec.dof
    q0 = np.asarray(q0, dtype=float)
    if q0.shape != (dof,) or not np.isfinite(q0).all():
        raise IdentificationError(f"mid posture: expected {dof} finite angles, got {q0.tolist()}")
    if np.any(q0 <= spec.lower) or np.any(q0 >= spec.upper):
        raise IdentificationError(f"mid posture {q0.tolist()} is not inside the joint limits")
    for name, value, low in (
        ("harmonics", harmonics, 2),
        ("periods", periods, 1),
        ("evaluations", evaluations, 1),
    ):
        if not (isinstance(value, int) and value >= low):
            raise IdentificationError(f"{name}: expected an integer >= {low}, got {value!r}")
    if not (0 < base_frequency_hz <= 10 and 0 < span_rad <= math.pi and budget_s > 0):
        raise IdentificationError(
            f"base frequency {base_frequency_hz} Hz, span {span_rad} rad, budget {budget_s} s: "
            "expected 0 < f <= 10, 0 < span <= pi, budget > 0"
        )
    with one_thread():
        return _design(
            spec, q0=q0, variant=variant, harmonics=harmonics,
            base_frequency_hz=base_frequency_hz, periods=periods, span_rad=span_rad,
            evaluations=evaluations, budget_s=budget_s, obstacles=obstacles,
        )  # fmt: skip


def _design(
    spec: RobotSpec,
    *,
    q0: F64,
    variant: int,
    harmonics: int,
    base_frequency_hz: float,
    periods: int,
    span_rad: float,
    evaluations: int,
    budget_s: float,
    obstacles: tuple[Any, ...],
) -> Design:
    from pipeline.planning.collision import CollisionChecker

    dof = spec.dof
    wall0 = time.perf_counter()
    base = base_parameters(spec)
    reg = Regressor(spec)
    checker = CollisionChecker(spec, obstacles=obstacles, padding_m=CLEARANCE_M)
    t = np.linspace(0.0, 1.0 / base_frequency_hz, DESIGN_SAMPLES_PER_PERIOD, endpoint=False)
    n_free = 2 * dof * (harmonics - 1)

    def reference_of(x: F64) -> FourierReference:
        return FourierReference.from_free(
            q0, x, harmonics=harmonics, base_frequency_hz=base_frequency_hz, periods=periods
        )

    best: dict[str, Any] = {"f": math.inf, "x": None}
    spent = 0

    def objective(x: F64) -> float:
        nonlocal spent
        if spent >= evaluations:
            raise _Spent
        if time.perf_counter() - wall0 > budget_s:
            raise _OutOfTime
        spent += 1
        ref = reference_of(x)
        q, qd, qdd = ref.sample_many(t)
        y = reg.stacked(q, qd, qdd)[:, base.columns]
        scaled, _ = _conditions(y)
        ratios = np.concatenate(limit_ratios(spec, ref, span_rad=span_rad, samples=t.size))
        excess = np.maximum(ratios - 1.0, 0.0)
        near = np.array([checker.clearance_m(qk)[0] for qk in q])
        close = np.maximum(CLEARANCE_M - near, 0.0) / CLEARANCE_M
        f = math.log(min(scaled, 1e12)) + PENALTY * float(excess @ excess + close @ close)
        if f < best["f"]:  # scaled onto the limits at the end if it still leaves them
            best["f"], best["x"] = f, x.copy()
        return f

    rng = np.random.default_rng(variant)
    # coefficient scale: each harmonic's velocity amplitude a share of the velocity limit
    scale = 0.05 * np.tile(np.repeat(spec.velocity_limits, harmonics - 1), 2)
    while spent < evaluations:  # restarts until the count is spent, never the clock
        x0 = rng.normal(size=n_free) * scale / np.sqrt(harmonics)
        try:
            optimize.minimize(objective, x0, method="L-BFGS-B", options={"maxiter": 200})
        except _Spent:
            break
        except _OutOfTime:
            raise IdentificationError(
                f"the excitation design ran past --budget-s {budget_s:g} s after {spent} of "
                f"{evaluations} evaluations: raise --budget-s or lower --evaluations"
            ) from None
    x = best["x"]
    if x is None:  # only a non-finite objective leaves no best
        raise IdentificationError(
            f"no excitation found in {evaluations} evaluations: raise --evaluations"
        )
    ref = _onto_limits(spec, reference_of(x), span_rad=span_rad)
    q, qd, qdd = ref.sample_many(t)
    scaled, raw = _conditions(reg.stacked(q, qd, qdd)[:, base.columns])
    return Design(ref, scaled, raw, spent, time.perf_counter() - wall0)


def _onto_limits(spec: RobotSpec, ref: FourierReference, *, span_rad: float) -> FourierReference:
    """Scale the series about ``q0`` so that a fine sampling stays within the limits."""
    worst = max(
        float(r.max())
        for r in limit_ratios(spec, ref, span_rad=span_rad, samples=CHECK_SAMPLES_PER_PERIOD)
    )
    if worst <= 1.0:
        return ref
    k = 1.0 / (worst * (1 + 1e-3))  # a margin for the peaks between samples
    return FourierReference(
        q0=ref.q0,
        a=tuple(tuple(v * k for v in row) for row in ref.a),
        b=tuple(tuple(v * k for v in row) for row in ref.b),
        base_frequency_hz=ref.base_frequency_hz,
        periods=ref.periods,
    )


def check_excitation(
    spec: RobotSpec, ref: FourierReference, *, obstacles: tuple[Any, ...] = ()
) -> None:
    """Refuse an excitation that leaves the limits or collides (one line).

    Raises:
        IdentificationError: naming the joint and limit, or the time and the contact.
    """
    from pipeline.planning.collision import CollisionChecker

    n = CHECK_SAMPLES_PER_PERIOD * ref.periods
    t = np.linspace(0.0, ref.duration_s, n + 1)
    q, qd, qdd = ref.sample_many(t)
    checks = (
        ("position", q < spec.lower, q > spec.upper),
        ("velocity", np.abs(qd) > spec.velocity_limits, np.zeros_like(q, dtype=bool)),
        ("acceleration", np.abs(qdd) > spec.acceleration_limits, np.zeros_like(q, dtype=bool)),
    )
    for what, low, high in checks:
        bad = low | high
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise IdentificationError(
                f"excitation leaves the {what} limit of {spec.joint_names[j]} at t={t[k]:.3f} s"
            )
    checker = CollisionChecker(spec, obstacles=obstacles)
    step = max(1, n // 400)
    for k in range(0, n + 1, step):
        contacts = checker.contacts(q[k])
        if contacts:
            a, b = contacts[0]
            raise IdentificationError(
                f"excitation collides at t={t[k]:.3f} s ({a} touches {b}): try another "
                "--variant or a smaller --span-rad"
            )


def record_excitation(
    params_path: Path,
    *,
    scenario_name: str,
    seed: int,
    variant: int,
    out: Path,
    controller_name: str | None = None,
    harmonics: int = 5,
    base_frequency_hz: float = 0.1,
    periods: int = 2,
    span_rad: float = 1.0,
    evaluations: int = DEFAULT_EVALUATIONS,
    budget_s: float = DEFAULT_BUDGET_S,
    force: bool = False,
    export: Path | None = None,
    mid_posture: Sequence[float] | None = None,
) -> dict[str, Any]:
    """Design excitation ``variant`` for scenario ``scenario_name`` and record it on the
    plant that scenario draws for ``seed``; the JSON summary.

    ``mid_posture``: the series' offset [rad] (default: the scenario's start pose).
    ``export``: also write the trajectory as CSV at 1 kHz (:func:`.fourier.write_csv`),
    for a real robot. ``evaluations``, ``budget_s``: see :func:`design_excitation`; the
    recording holds the evaluation count (``settings.excitation.evaluations``), never the
    design's wall time (same inputs, same bytes).

    Raises:
        PipelineError: unknown scenario or controller, an excitation that leaves the limits
            or collides, a diverged episode, an existing ``out`` without ``force``.
    """
    from pipeline.control import make_controller
    from pipeline.experiment.assemble import scenario_spec
    from pipeline.experiment.goals import resolve_start
    from pipeline.log.bag import write_episode_bag
    from pipeline.model.scene import Box
    from pipeline.params import load_params
    from pipeline.sim.runner import run_episode
    from pipeline.trajectory import TrajectorySamples

    wall0 = time.perf_counter()
    if export is not None:
        from pipeline.fsutil import check_output_file

        check_output_file(Path(export))  # refused before the design and the run
    params = load_params(params_path)
    if scenario_name not in params.scenarios:
        raise ParamsError(
            f"{params.source}: unknown scenario '{scenario_name}' (scenarios: "
            f"{', '.join(params.scenarios)})"
        )
    scenario = params.scenarios[scenario_name]
    if controller_name is None:
        controller_name = "ctc" if "ctc" in params.controllers else next(iter(params.controllers))
    if controller_name not in params.controllers:
        raise ParamsError(
            f"{params.source}: unknown controller '{controller_name}' (controllers: "
            f"{', '.join(params.controllers)})"
        )
    if out.exists() and not force:
        raise IdentificationError(f"{out}: recording already exists; use --force to overwrite it")
    spec = scenario_spec(scenario)
    # everything the recording needs, checked before the design's work: the robot's
    # dynamics (any description format), the mid posture, the nominal model, the controller
    from pipeline.identify.model_file import nominal_path, nominal_spec
    from pipeline.identify.stage import require_identifiable

    require_identifiable(spec, what="an excitation")
    if mid_posture is not None and len(mid_posture) != spec.dof:
        raise IdentificationError(
            f"--mid: expected {spec.dof} angles (robot '{spec.name}': "
            f"{', '.join(spec.joint_names)}), got {len(mid_posture)}"
        )
    cparams = params.controllers[controller_name]
    nominal = nominal_spec(
        spec,
        nominal_path(scenario.nominal, seed=seed),
        where=f"scenarios.{scenario_name}",
    )
    controller = make_controller(
        cparams.type, nominal, cparams.gains, source=f"controllers.{controller_name}"
    )
    obstacles = tuple(Box(b.name, b.center, b.half_size) for b in scenario.obstacles)
    design = design_excitation(
        spec,
        q0=(
            resolve_start(spec, scenario, name=scenario_name, source=params.source)
            if mid_posture is None
            else np.asarray(mid_posture, dtype=float)
        ),
        variant=variant,
        harmonics=harmonics,
        base_frequency_hz=base_frequency_hz,
        periods=periods,
        span_rad=span_rad,
        evaluations=evaluations,
        budget_s=budget_s,
        obstacles=obstacles,
    )
    ref = design.reference
    check_excitation(spec, ref, obstacles=obstacles)
    from pipeline.control.controller import with_planned_path

    # built again with its default gains designed along the excitation (the one built above
    # checked the controller before the design's work)
    controller = make_controller(
        cparams.type,
        nominal,
        with_planned_path(
            cparams.gains,
            ref.sample_many(np.linspace(0.0, 1.0 / ref.base_frequency_hz, 200, endpoint=False))[0],
        ),
        source=f"controllers.{controller_name}",
    )
    from pipeline.experiment.assemble import plant_run_options, plant_run_settings

    plant_spec, plant, plant_settings = scenario_plant(spec, scenario, seed=seed)
    sim = params.sim
    result = run_episode(
        spec,
        reference=ref,
        controller=controller,
        plant=plant,
        plant_spec=plant_spec,
        obstacles=obstacles,
        physics_dt_s=sim.physics_dt_s,
        integrator=sim.integrator,
        control_period_steps=sim.control_period_steps,
        hold_s=scenario.hold_s,
        preroll_s=scenario.preroll_s,
        settle=False,  # identification data, not a metric: the whole pre-roll, as before
        position_noise_std_rad=scenario.plant.position_noise_std_rad,
        velocity_noise_std_rad_s=scenario.plant.velocity_noise_std_rad_s,
        seed=seed,
        **plant_run_options(spec, scenario, seed=seed),
    )
    if result.status != "ok":
        raise IdentificationError(f"excitation episode {result.status}: {result.reason}")
    from pipeline.identify.model_file import spec_document
    from pipeline.robots.recorded import robot_to_dict

    excitation = {
        "variant": variant,
        "harmonics": harmonics,
        "base_frequency_hz": base_frequency_hz,
        "periods": periods,
        "span_rad": span_rad,
        "evaluations": design.evaluations,
        "q0": list(ref.q0),
        "a": [list(r) for r in ref.a],
        "b": [list(r) for r in ref.b],
        "condition_number_scaled": design.condition_number_scaled,
        "condition_number": design.condition_number,
    }
    motion_start_s = result.motion_start_s
    name = out.name
    settings = {
        "episode": name,
        # a DH robot whole, any other by value (as episodes: pipeline.robots.recorded)
        "robot": spec_document(spec) if spec.dh_rows is not None else robot_to_dict(spec),
        "scenario": {"name": scenario_name, **scenario.model_dump()},
        "controller": {
            "name": controller_name,
            "type": cparams.type,
            "gains": controller.gains_in_effect(),
        },
        "plant": {**plant_settings, **plant_run_settings(sim, result)},
        "excitation": excitation,
        "planner": {"trajectory_duration_s": ref.duration_s},
        "protocol": {"motion_start_s": motion_start_s, "hold_s": scenario.hold_s},
        "seed": seed,
        "status": result.status,
        "reason": result.reason,
    }
    times = np.arange(0.0, ref.duration_s + 1e-9, 0.01)
    planned = TrajectorySamples(times, *ref.sample_many(times))
    summary = write_episode_bag(
        out,
        spec=spec,
        result=result,
        planned=planned,
        motion_start_ns=round(motion_start_s * 1e9),
        metadata={
            "episode": name,
            "scenario": scenario_name,
            "controller": controller_name,
            "robot": spec.name,
            "seed": str(seed),
            "status": result.status,
            "settings": json.dumps(settings, sort_keys=True, separators=(",", ":")),
        },
        joint_state_decimation=1,  # identification needs every control step
        ros_distro=sim.ros_distro,
        force=force,
    )
    if export is not None:
        from pipeline.identify.fourier import write_csv

        try:
            write_csv(export, ref, spec.joint_names, rate_hz=EXPORT_RATE_HZ)
        except OSError as err:
            raise IdentificationError(f"{export}: cannot write ({err.strerror or err})") from err
    return {
        "recording": str(out),
        "export": str(export) if export is not None else None,
        "scenario": scenario_name,
        "seed": seed,
        "variant": variant,
        "controller": controller_name,
        "duration_s": ref.duration_s,
        "condition_number_scaled": design.condition_number_scaled,
        "condition_number": design.condition_number,
        "design_evaluations": design.evaluations,
        "design_wall_s": design.wall_s,
        "size_bytes": summary.size_bytes,
        "wall_s": time.perf_counter() - wall0,
    }


def scenario_plant(
    spec: RobotSpec, scenario: Any, *, seed: int
) -> tuple[RobotSpec, Any, dict[str, Any]]:
    """The plant ``scenario`` draws for ``seed``: the record stage's draw, whatever the motion.

    Returns:
        The plant's robot (drawn links, armature), its MuJoCo options, and plain settings:
        the drawn links, armature, friction and payload, the fields params give as they
        are (the sensors' noise, ...: ``given_plant``) and what a published profile or a
        torque sensor adds (its source, the drawn sigmoid friction, the drawn effort
        offset), as an episode's plant records them; the fields declared ``added`` left
        out while at their default (a plant without them records what it did before).
    """
    from pipeline.contract import omit_added, plain
    from pipeline.experiment.assemble import (
        draw_scenario_plant,
        given_plant,
        published_plant,
        scenario_friction,
    )
    from pipeline.model.uncertainty import link_inertials
    from pipeline.settings import PlantSettings, SigmoidFrictionSettings, per_joint

    plant_spec, plant, uncertainty = draw_scenario_plant(spec, scenario, seed=seed)
    drawn = scenario_friction(spec, scenario, seed=seed)  # what the run's options use
    settings = {
        "links": [asdict(x) for x in link_inertials(plant_spec)],
        "armature": [float(a) for a in plant_spec.armature],
        "damping": list(per_joint(plant.damping, spec.dof)),
        "frictionloss": list(per_joint(plant.frictionloss, spec.dof)),
        "payload_kg": plant.payload_kg,
        **given_plant(scenario),
        **{
            k: plain(asdict(v) if isinstance(v, SigmoidFrictionSettings) else v)
            for k, v in published_plant(scenario, drawn).items()
        },
        "uncertainty": asdict(uncertainty),
    }
    return plant_spec, plant, omit_added(PlantSettings, settings)
