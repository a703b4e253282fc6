"""An episode as run, mapped onto the recording contract (:class:`EpisodeSettings`).

What goes into a bag's ``settings`` metadata: the robot as plain data, the plant drawn
for the episode, the planner's result, the protocol's start. Nothing here reads a
clock: a recording's bytes depend on its params and seed alone.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline import __version__
from pipeline.params import Episode, RecordedScenario, ScenarioParams
from pipeline.planning import PlannedPath, TimedTrajectory
from pipeline.robots.spec import JointSpec, RobotSpec
from pipeline.settings import (
    ControllerSettings,
    EpisodeSettings,
    ExecutionSafety,
    GainDesign,
    Gains,
    LoopSettings,
    PlannerSettings,
    PlantSettings,
    ProtocolSettings,
    Uncertainty,
    per_joint,
)

if TYPE_CHECKING:
    from pipeline.model.mjcf import PlantOptions
    from pipeline.sim.result import EpisodeResult


def _inertial_dict(j: JointSpec) -> dict[str, Any]:
    if j.inertial is None:
        return {}
    t = j.inertial.inertia
    return {
        "inertial": {
            "mass": j.inertial.mass,
            "com": list(j.inertial.com),
            "inertia": [t[0][0], t[1][1], t[2][2], t[0][1], t[0][2], t[1][2]],
        }
    }


def spec_as_dict(spec: RobotSpec) -> dict[str, Any]:
    """The robot spec as plain data (radians), as recorded in every bag.

    A robot given as DH rows is recorded whole (the robot YAML, radians); any other robot
    by its source file and that file's SHA-256 (a changed file re-runs what it drives), its
    joints (limits, link inertials as modelled, armature) and where the facts its file
    lacks came from.
    """
    rows = spec.dh_rows
    if rows is None:
        return {
            "name": spec.name,
            "format": spec.format,
            "source": spec.source,
            "sha256": spec.source_sha256,
            "robot": spec.loaded_from,
            "base_link": spec.base_link,
            "joints": [
                {
                    "name": j.name,
                    "type": j.kind,
                    "link": j.link_name,
                    "limits": asdict(j.limits),
                    **_inertial_dict(j),
                    "armature": j.armature,
                }
                for j in spec.joints
            ],
            "settings_sources": dict(spec.settings_sources),
        }
    return {
        "name": spec.name,
        "convention": spec.convention,
        "angle_unit": "rad",
        "joints": [
            {
                "name": j.name,
                "dh": [dh.alpha, dh.a, dh.d, dh.theta_offset],
                "limits": asdict(j.limits),
                **(
                    {
                        "inertial": {
                            "mass": j.inertial.mass,
                            "com": list(j.inertial.com),
                            "inertia": [
                                j.inertial.inertia[0][0],
                                j.inertial.inertia[1][1],
                                j.inertial.inertia[2][2],
                                j.inertial.inertia[0][1],
                                j.inertial.inertia[0][2],
                                j.inertial.inertia[1][2],
                            ],
                        }
                    }
                    if j.inertial is not None
                    else {}
                ),
                "collision": {"radius": j.collision_radius},
                "armature": j.armature,
            }
            for j, dh in zip(spec.joints, rows, strict=True)
        ],
        **({"armature_source": spec.armature_source} if spec.armature_source else {}),
    }


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


def draw_scenario_plant(
    spec: RobotSpec, scenario: ScenarioParams, *, seed: int
) -> tuple[RobotSpec, PlantOptions, Uncertainty]:
    """The plant ``scenario`` draws for ``seed``, whatever motion is recorded on it.

    Returns:
        The plant's robot (drawn links, armature plus the scenario's extra armature), its
        MuJoCo options (damping, friction, payload) and the spread the links were drawn from.
    """
    from pipeline.model.mjcf import PlantOptions
    from pipeline.model.uncertainty import draw_plant, link_inertials, with_plant

    p = scenario.plant
    uncertainty = p.uncertainty
    drawn = draw_plant(spec, uncertainty, seed=seed)
    extra = per_joint(param_values(p.armature), spec.dof)
    plant_spec = with_plant(
        drawn, link_inertials(drawn), [a + x for a, x in zip(drawn.armature, extra, strict=True)]
    )
    damping, frictionloss = plant_friction(spec, scenario)
    plant = PlantOptions(damping=damping, frictionloss=frictionloss, payload_kg=p.payload_kg)
    return plant_spec, plant, uncertainty


def loop_settings(scenario: ScenarioParams) -> LoopSettings:
    """The scenario's loop (delay, jitter, encoder, velocity estimate) as recorded."""
    return scenario.loop


def _plant_is_exact(spec: RobotSpec, plant_spec: RobotSpec, scenario: ScenarioParams) -> bool:
    """The nominal model is the plant: nothing drawn, no friction, damping, payload, noise,
    and the loop is ideal (no delay, no quantisation, the plant's velocity)."""
    p = scenario.plant
    zero = (
        *plant_friction(plant_spec, scenario),
        (p.payload_kg,),
        (p.position_noise_std_rad, p.velocity_noise_std_rad_s),
    )
    return (
        plant_spec == spec
        and all(x == 0 for group in zero for x in group)
        and loop_settings(scenario).ideal
    )


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
    p = scenario.plant
    k0 = result.motion_start_row
    at_start = min(k0, len(result.stamp_ns) - 1)
    damping, frictionloss = plant_friction(spec, scenario)
    design, recorded_gains = GainDesign.split_from(gains)
    plant = PlantSettings(
        exact=_plant_is_exact(nominal, plant_spec, scenario),
        links=link_inertials(plant_spec),
        armature=tuple(float(a) for a in plant_spec.armature),
        nominal_armature=tuple(float(a) for a in nominal.armature),
        damping=per_joint(damping, spec.dof),
        frictionloss=per_joint(frictionloss, spec.dof),
        payload_kg=p.payload_kg,
        position_noise_std_rad=p.position_noise_std_rad,
        velocity_noise_std_rad_s=p.velocity_noise_std_rad_s,
        uncertainty=uncertainty,
        physics_dt_s=sim.physics_dt_s,
        control_period_s=sim.physics_dt_s * sim.control_period_steps,
        integrator=result.integrator,
        friction_model=result.friction_model,
    )
    # planning_time_s is wall clock: printed, never recorded (recordings are byte-reproducible)
    return EpisodeSettings(
        episode=episode.name,
        robot=spec_as_dict(spec),
        scenario=RecordedScenario.of(episode.scenario_name, scenario),
        controller=ControllerSettings(
            name=episode.controller_name,
            type=episode.controller.type,
            gains=Gains(recorded_gains),
            origin=origin,
            design=design,
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
