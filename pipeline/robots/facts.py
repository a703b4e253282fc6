"""Facts a robot description may lack, what stands in for each, and the warning that says so.

A URDF carries no rotor armature and no acceleration limits; an MJCF no velocity limits. A
run on such a robot works, but what stood in for the missing value shapes its numbers, so
``pipeline record`` names each one (:func:`missing_facts`) before any work.

Acceleration limits are not a made-up constant: where the robot's files state none, each
joint gets :func:`derived_acceleration_limits`,

    a_max_j = min(ACCELERATION_EFFORT_FRACTION x effort_limit_j / max_q M_jj(q),
                  velocity_limit_j / VELOCITY_RISE_S)

with ``M`` the nominal joint-space inertia (link inertials + armature) and the maximum
over the zero pose (clipped into the limits), the middle of the joint limits and every
named state: half the joint's torque accelerates the joint's own worst-case inertia,
the other half is left to gravity, coupling and feedback. The second term bounds a wrist
whose inertia without armature is tiny (example-robot-data's xArm7: 7e4 rad/s^2 from the
first term alone): no joint reaches its velocity limit in less than 0.1 s, four time
constants of the controllers' default 40 rad/s loop, so the reference stays trackable.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.robots.sidecar import DEFAULT_ACCELERATION, NOT_STATED
from pipeline.robots.spec import RobotSpec

ACCELERATION_EFFORT_FRACTION = 0.5
"""Share of a joint's effort limit the derived acceleration limit spends on its inertia."""
VELOCITY_RISE_S = 0.1
"""The shortest time a derived acceleration limit takes a joint to its velocity limit [s]."""
ACCELERATION_RULE = (
    f"derived: min({ACCELERATION_EFFORT_FRACTION:g} x effort limit / max M_jj, velocity "
    f"limit / {VELOCITY_RISE_S:g} s), M_jj the nominal inertia at zero, mid-range and named poses"
)
"""The ``settings_sources`` entry of acceleration limits derived by the rule."""
UNSTATED = frozenset({"", "defaults", NOT_STATED})
"""Sources that mean the robot's files did not state the value."""


@dataclass(frozen=True)
class MissingFact:
    """One value a robot's files do not state, and what the pipeline uses instead.

    Attributes:
        robot: the robot's name.
        joint: the joint's name.
        field: ``armature``, ``acceleration`` or ``velocity``.
        used: the value used instead, with its unit and where it comes from.
        effect: what the substitute means for the results, in a few words.
    """

    robot: str
    joint: str
    field: str
    used: str
    effect: str

    def message(self) -> str:
        """One line: ``robot 'r', joint 'j': no armature stated; using ... (effect)``."""
        return (
            f"robot '{self.robot}', joint '{self.joint}': no {self.field} stated; using "
            f"{self.used} ({self.effect})"
        )


def _poses(spec: RobotSpec) -> list[NDArray[np.float64]]:
    lower, upper = spec.lower, spec.upper
    mid = np.where(np.isfinite(lower) & np.isfinite(upper), 0.5 * (lower + upper), 0.0)
    poses = [np.clip(np.zeros(spec.dof), lower, upper), mid]
    poses += [np.asarray(q, dtype=float) for _, q in spec.named_states]
    return poses


def derived_acceleration_limits(spec: RobotSpec) -> NDArray[np.float64]:
    """``min(0.5 x effort_j / max_q M_jj(q), velocity_j / 0.1 s)`` per joint [rad/s^2] (see
    the module docstring).

    A robot without link inertias keeps :data:`DEFAULT_ACCELERATION` per joint.
    """
    if not spec.has_dynamics:
        return np.full(spec.dof, DEFAULT_ACCELERATION)
    import pinocchio as pin

    from pipeline.robots.urdf import build_pinocchio_model

    model = build_pinocchio_model(spec)
    data = model.createData()
    m_max = np.max([np.diag(pin.crba(model, data, q)) for q in _poses(spec)], axis=0)
    by_effort = ACCELERATION_EFFORT_FRACTION * spec.effort_limits / m_max
    out: NDArray[np.float64] = np.minimum(by_effort, spec.velocity_limits / VELOCITY_RISE_S)
    return out


def with_derived_accelerations(spec: RobotSpec) -> RobotSpec:
    """``spec`` with derived acceleration limits where its files state none (source
    :data:`NOT_STATED`); else ``spec`` itself."""
    sources = dict(spec.settings_sources)
    if sources.get("acceleration") != NOT_STATED:
        return spec
    a_max = derived_acceleration_limits(spec)
    joints = tuple(
        dataclasses.replace(j, limits=dataclasses.replace(j.limits, acceleration=float(a)))
        for j, a in zip(spec.joints, a_max, strict=True)
    )
    rule = ACCELERATION_RULE if spec.has_dynamics else f"default {DEFAULT_ACCELERATION:g}"
    sources["acceleration"] = rule
    return dataclasses.replace(spec, joints=joints, settings_sources=tuple(sources.items()))


def missing_facts(spec: RobotSpec) -> tuple[MissingFact, ...]:
    """Every armature, acceleration and velocity limit ``spec``'s files do not state.

    Effort limits are not listed: every loader refuses a joint without one.
    """
    sources = dict(spec.settings_sources)
    out: list[MissingFact] = []
    armature_unstated = sources.get("armature", spec.armature_source) in UNSTATED
    accel = sources.get("acceleration", "")
    velocity = sources.get("velocity", "")
    planner = "the planner's time-parameterization uses it"
    for j in spec.joints:

        def add(field: str, used: str, effect: str, joint: str = j.name) -> None:
            out.append(MissingFact(robot=spec.name, joint=joint, field=field, used=used,
                                   effect=effect))  # fmt: skip

        if armature_unstated and j.armature == 0.0:
            add("armature", "0 kg m^2", "no rotor inertia in the plant or the nominal model: "
                "inertia-scaled gains rest on the link inertia alone")  # fmt: skip
        if accel == NOT_STATED or accel.startswith(("derived", "default")):
            add("acceleration limit", f"{j.limits.acceleration:.3g} rad/s^2 ({accel})", planner)
        if velocity.startswith("default"):
            add("velocity limit", f"{j.limits.velocity:.3g} rad/s ({velocity})", planner)
    return tuple(out)


def fact_warnings(facts: tuple[MissingFact, ...]) -> list[str]:
    """One line per robot and field: each joint lacking it and the value used instead."""
    groups: dict[tuple[str, str], list[MissingFact]] = {}
    for f in facts:
        groups.setdefault((f.robot, f.field), []).append(f)
    return [
        f"robot '{robot}' states no {field}: using "
        + ", ".join(f"{f.joint} {f.used.split(' (')[0]}" for f in group)
        + (f" ({group[0].used.split(' (', 1)[1]}" if " (" in group[0].used else "")
        + f"; {group[0].effect}"
        for (robot, field), group in groups.items()
    ]
