"""An episode as run, mapped onto the recording contract (:class:`EpisodeSettings`).

What goes into a bag's ``settings`` metadata: the robot as plain data, the plant drawn
for the episode, the planner's result, the protocol's start. Nothing here reads a
clock: a recording's bytes depend on its params and seed alone.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline import __version__
from pipeline.contract import given_fields
from pipeline.params import Episode, RecordedScenario, ScenarioParams, SimParams, nominal_path
from pipeline.planning import PlannedPath, TimedTrajectory
from pipeline.robots.spec import RobotSpec
from pipeline.settings import (
    ControllerSettings,
    EpisodeSettings,
    ExecutionSafety,
    GainDesign,
    Gains,
    LoopSettings,
    NominalModelSettings,
    PlannerSettings,
    PlantSettings,
    ProtocolSettings,
    SigmoidFrictionSettings,
    Uncertainty,
    per_joint,
)

if TYPE_CHECKING:
    from pipeline.model.mjcf import PlantOptions
    from pipeline.model.uncertainty import DrawnFriction
    from pipeline.sim.result import EpisodeResult


def scenario_spec(scenario: ScenarioParams) -> RobotSpec:
    """The scenario's robot: its description, armature x ``armature_scale`` (the arm's own,
    so the plant and the CAD nominal model both get it).

    Raises:
        SpecError: an unknown robot or a bad robot file.
    """
    from dataclasses import replace

    from pipeline.robots.loaders import load_spec

    spec = load_spec(scenario.robot)
    stated = dict(spec.settings_sources)
    given = [k for k in FRICTION_KEYS if k in stated and k in scenario.plant.model_fields_set]
    if given:  # the recording names where the plant's friction came from
        stated.update({k: f"scenario plant.{k} (the robot's: {stated[k]})" for k in given})
        spec = replace(spec, settings_sources=tuple(stated.items()))
    scale = scenario.armature_scale
    if scale == 1.0:
        return spec
    joints = tuple(replace(j, armature=j.armature * scale) for j in spec.joints)
    source = f"{spec.armature_source or 'the robot file'}; x {scale:g} (scenario armature_scale)"
    return replace(spec, joints=joints, armature_source=source)


def param_values(value: float | list[float]) -> tuple[float, ...]:
    """A params entry given as one number or one per joint, as a tuple (not yet per joint)."""
    return tuple(value) if isinstance(value, list) else (float(value),)


FRICTION_KEYS = ("damping", "frictionloss")


def plant_friction(
    spec: RobotSpec, scenario: ScenarioParams
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The plant's joint friction, ``(damping [N m s/rad], frictionloss [N m])``, each one
    value or one per joint: the scenario's ``plant`` where it gives the key, else the
    robot's own (:attr:`RobotSpec.damping`: its sidecar's, else its URDF's ``<dynamics>``)
    where the robot states any, else the scenario's default 0."""
    p = scenario.plant

    def pick(key: str, robot: tuple[float, ...]) -> tuple[float, ...]:
        given = key in p.model_fields_set or not any(robot)
        return param_values(getattr(p, key)) if given else robot

    return pick("damping", spec.damping), pick("frictionloss", spec.frictionloss)


def _per_joint(values: tuple[float, ...], dof: int, what: str) -> tuple[float, ...]:
    from pipeline.errors import ModelError

    if len(values) not in (1, dof):
        raise ModelError(f"plant.{what}: expected 1 or {dof} values, got {len(values)}")
    return values * dof if len(values) == 1 else values


def scenario_friction(spec: RobotSpec, scenario: ScenarioParams, *, seed: int) -> DrawnFriction:
    """The plant's joint friction, payload and torque-sensor offset ``scenario`` draws for
    ``seed`` (:func:`pipeline.model.uncertainty.draw_friction`). A published profile's
    friction is the plant's whole friction: the robot's own damping and frictionloss do
    not apply (the scenario's ``plant.damping``, ``plant.frictionloss`` still add theirs).

    Raises:
        ModelError: a per-joint list of the wrong length, a transition spread without a
            sigmoid.
    """
    from pipeline.model.published import PROFILES
    from pipeline.model.uncertainty import draw_friction

    p = scenario.plant
    profile = PROFILES[p.profile] if p.profile else None
    if profile is None:
        damping, frictionloss = plant_friction(spec, scenario)
    else:
        damping, frictionloss = param_values(p.damping), param_values(p.frictionloss)
    return draw_friction(
        p.uncertainty,
        damping=_per_joint(damping, spec.dof, "damping"),
        frictionloss=_per_joint(frictionloss, spec.dof, "frictionloss"),
        sigmoid=profile.friction if profile else None,
        payload_kg=p.payload_kg,
        effort_offset_nm=p.effort_offset_nm,
        seed=seed,
    )


def plant_run_options(spec: RobotSpec, scenario: ScenarioParams, *, seed: int) -> dict[str, Any]:
    """``run_episode``'s keyword arguments for what the plant adds beyond MuJoCo's model:
    the sigmoid friction and the torque sensor's offset and noise."""
    drawn = scenario_friction(spec, scenario, seed=seed)
    return {
        "friction": drawn.sigmoid,
        "effort_offset_nm": drawn.effort_offset_nm,
        "effort_noise_std_nm": scenario.plant.effort_noise_std_nm,
    }


def plant_run_settings(sim: SimParams, result: EpisodeResult) -> dict[str, Any]:
    """What a plant's settings record of how it was stepped (episode and excitation bags
    alike): the physics step and control period [s], the integrator and the friction law
    the run reports."""
    return {
        "physics_dt_s": sim.physics_dt_s,
        "control_period_s": sim.physics_dt_s * sim.control_period_steps,
        "integrator": result.integrator,
        "friction_model": result.friction_model,
    }


def draw_scenario_plant(
    spec: RobotSpec, scenario: ScenarioParams, *, seed: int, where: str = "plant.profile"
) -> tuple[RobotSpec, PlantOptions, Uncertainty]:
    """The plant ``scenario`` draws for ``seed``, whatever motion is recorded on it.

    Returns:
        The plant's robot (the robot's or a published profile's links, drawn; armature
        plus the scenario's extra armature), its MuJoCo options (damping, friction,
        payload, drawn) and the spread the links were drawn from.

    Raises:
        ModelError: a profile that does not describe the robot (``where`` names the field).
    """
    from pipeline.model.mjcf import PlantOptions
    from pipeline.model.published import profile_plant
    from pipeline.model.uncertainty import draw_plant, link_inertials, with_plant

    p = scenario.plant
    uncertainty = p.uncertainty
    base = profile_plant(spec, p.profile, where=where) if p.profile else spec
    drawn = draw_plant(base, uncertainty, seed=seed)
    extra = per_joint(param_values(p.armature), spec.dof)
    plant_spec = with_plant(
        drawn, link_inertials(drawn), [a + x for a, x in zip(drawn.armature, extra, strict=True)]
    )
    friction = scenario_friction(spec, scenario, seed=seed)
    plant = PlantOptions(
        damping=friction.damping,
        frictionloss=friction.frictionloss,
        payload_kg=friction.payload_kg,
    )
    return plant_spec, plant, uncertainty


def loop_settings(scenario: ScenarioParams) -> LoopSettings:
    """The scenario's loop (delay, jitter, encoder, velocity estimate) as recorded."""
    return scenario.loop


def given_plant(scenario: ScenarioParams) -> dict[str, Any]:
    """The plant fields params pass through to the recording as given (each field of
    :class:`PlantSettings` declared ``knob(..., given=True)``)."""
    return {f.name: getattr(scenario.plant, f.name) for f in given_fields(PlantSettings)}


def _plant_is_exact(spec: RobotSpec, plant_spec: RobotSpec, scenario: ScenarioParams) -> bool:
    """The nominal model is the plant: nothing drawn, no friction, damping, payload,
    torque-sensor offset, every given field (the sensors' noise, ...) at its default,
    and the loop is ideal (no delay, no quantisation, the plant's velocity)."""
    p = scenario.plant
    zero = (*plant_friction(plant_spec, scenario), (p.payload_kg, p.uncertainty.payload_kg))
    given = given_plant(scenario)
    return (
        plant_spec == spec
        and p.profile is None
        and p.effort_offset_nm == 0
        and all(x == 0 for group in zero for x in group)
        and all(given[f.name] == f.default for f in given_fields(PlantSettings))
        and loop_settings(scenario).ideal
    )


def published_plant(scenario: ScenarioParams, drawn: DrawnFriction) -> dict[str, Any]:
    """The plant settings a published profile or a torque sensor adds (none: nothing, so
    the settings of plants without them read as before): an episode's and an
    excitation's (:func:`pipeline.identify.excitation.scenario_plant`)."""
    from pipeline.model.published import PROFILES

    p = scenario.plant
    out: dict[str, Any] = {}
    if p.profile:
        out["profile"] = f"{p.profile}: {PROFILES[p.profile].source}"
    if drawn.sigmoid is not None:
        out["sigmoid_friction"] = SigmoidFrictionSettings(
            phi1_nm=drawn.sigmoid.phi1_nm,
            phi2_s_rad=drawn.sigmoid.phi2_s_rad,
            phi3_rad_s=drawn.sigmoid.phi3_rad_s,
        )
    if drawn.effort_offset_nm:
        out["effort_offset_nm"] = drawn.effort_offset_nm
    return out


def _own_nominal(episode: Episode) -> NominalModelSettings | None:
    """The controller's own nominal model file as run (None: its scenario's)."""
    import hashlib

    path = nominal_path(episode.controller.nominal, seed=episode.seed)
    if path is None:
        return None
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return NominalModelSettings(file=path, sha256=digest)


def episode_settings(
    episode: Episode,
    *,
    spec: RobotSpec,
    nominal: RobotSpec,
    plant_spec: RobotSpec,
    uncertainty: Uncertainty,
    gains: Mapping[str, Any],
    origin: Mapping[str, Any],
    path: PlannedPath,
    trajectory: TimedTrajectory,
    result: EpisodeResult,
    safety: ExecutionSafety,
    commit: str,
) -> EpisodeSettings:
    """What the episode's bag records about how it was run.

    Args:
        spec: the robot as described (its YAML: what the bag records as ``robot``).
        nominal: the controllers' model: ``spec``, or the identified robot of a scenario's
            ``nominal:`` model file.
        plant_spec: the robot as simulated (drawn inertials, armature).
        gains: the controller's gains in effect (``Controller.gains_in_effect()``).
        origin: where the controller's code came from
            (:func:`pipeline.control.registry.controller_origin`).
        commit: the recording code's version (:func:`pipeline.stages.provenance.git_commit`).
    """
    from pipeline.model.uncertainty import link_inertials

    scenario = episode.scenario
    sim = episode.sim
    k0 = result.motion_start_row
    at_start = min(k0, len(result.stamp_ns) - 1)
    drawn = scenario_friction(spec, scenario, seed=episode.seed)
    design, recorded_gains = GainDesign.split_from(gains)
    plant = PlantSettings(
        exact=_plant_is_exact(nominal, plant_spec, scenario),
        links=link_inertials(plant_spec),
        armature=tuple(float(a) for a in plant_spec.armature),
        nominal_armature=tuple(float(a) for a in nominal.armature),
        damping=drawn.damping,
        frictionloss=drawn.frictionloss,
        payload_kg=drawn.payload_kg,
        uncertainty=uncertainty,
        **plant_run_settings(sim, result),
        **given_plant(scenario),
        **published_plant(scenario, drawn),
    )
    # planning_time_s is wall clock: printed, never recorded (recordings are byte-reproducible)
    return EpisodeSettings(
        episode=episode.name,
        robot=spec,
        scenario=RecordedScenario.of(episode.scenario_name, scenario),
        controller=ControllerSettings(
            name=episode.controller_name,
            type=episode.controller.type,
            gains=Gains(recorded_gains),
            origin=origin,
            design=design,
            nominal=_own_nominal(episode),
            plant=(
                None
                if episode.controller.plant is None
                else episode.controller.plant.model_dump(mode="json")
            ),
        ),
        plant=plant,
        planner=PlannerSettings(
            planner=path.planner,
            seed=path.seed,
            time_limit_s=path.time_limit_s,
            simplify=path.simplified,
            direct=path.direct,
            n_waypoints=len(path.waypoints),
            n_states_before_simplify=path.n_states_before_simplify,
            path_length_rad=path.path_length_rad,
            padding_m=path.padding_m,
            check_step_rad=path.check_step_rad,
            interpolation=trajectory.interpolation,
            trajectory_duration_s=float(trajectory.duration_s),
            velocity_scaling=scenario.timing.velocity_scaling,
            acceleration_scaling=scenario.timing.acceleration_scaling,
            start=tuple(float(x) for x in path.start),
            goal=tuple(float(x) for x in path.goal),
        ),
        protocol=ProtocolSettings(
            motion_start_s=result.motion_start_s,
            hold_s=scenario.hold_s,
            start_abs_error_rad=tuple(
                float(x) for x in np.abs(result.q_ref[at_start] - result.q_true[at_start])
            )
            if result.stamp_ns.size
            else (),
            start_effort_nm=tuple(float(x) for x in result.tau_nm[at_start])
            if result.stamp_ns.size
            else (),
            reproduces_paper=scenario.reproduces_paper,
            preroll_settled=result.preroll_settled,
            hold_settled=result.hold_settled if result.ok else None,
        ),
        safety=safety,
        seed=episode.seed,
        status=result.status,
        reason=result.reason,
        mujoco_warnings=result.mujoco_warnings,
        package_version=__version__,
        git_commit=commit,
        campaign=episode.campaign,
        loop=loop_settings(scenario),
    )


def bag_metadata(episode: Episode, settings: EpisodeSettings, *, robot: str) -> dict[str, str]:
    """The bag's metadata: the episode's names, for tools that do not parse the settings,
    and the settings as compact, key-sorted JSON."""
    return {
        "episode": episode.name,
        "scenario": episode.scenario_name,
        "controller": episode.controller_name,
        "robot": robot,
        "seed": str(episode.seed),
        **({"campaign": episode.campaign.name} if episode.campaign else {}),
        "status": settings.status,
        "settings": json.dumps(settings.to_dict(), sort_keys=True, separators=(",", ":")),
    }
