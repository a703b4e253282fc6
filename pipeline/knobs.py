"""The settings concepts ``params.yaml`` and a recording share, each declared once.

A scenario's ``loop:`` and ``plant.uncertainty:`` are these dataclasses: params validate
them at the edge (with the ranges each field's :func:`~pipeline.contract.knob` declares,
``pipeline.params.AsParams``), the episode records them as they are, and the report's
setup lines list the fields their metadata shows. Adding a field here is the whole change.

The plant as recorded (:class:`PlantSettings`) is mostly drawn and expanded per joint
from params; its fields declared ``knob(..., given=True)`` are the ones params take as
they are: ``pipeline.params.PlantParams`` gets each (type, default, range) from here,
the recording copies it, the exact-plant check wants its default, and the plant line
shows it. Adding such a field here is the whole change too (the simulation that uses it
aside). A campaign's :class:`CampaignInfo` is what params expand and the recording keeps.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Literal

from pipeline.contract import (
    Contract,
    Count,
    Finite,
    Flag,
    NonNegative,
    NonNegatives,
    Numbers,
    Positive,
    Scalar,
    Text,
    at_defaults,
    guard,
    is_mapping,
    knob,
    listed,
    rule,
)

MAX_LOOP_DELAY_S = 0.1  # a 100 ms actuation delay is a broken loop, not a setting

VelocitySource = Literal["plant", "encoder"]
VELOCITY_SOURCES: tuple[VelocitySource, ...] = ("plant", "encoder")


@dataclass(frozen=True)
class Uncertainty(Contract):
    """How far the plant may differ from the nominal model (uniform draws per episode seed).

    Attributes:
        mass_rel: link mass factor in ``[1 - r, 1 + r]``.
        com_m: centre-of-mass offset per axis in ``[-r, r]`` [m].
        inertia_rel: per-axis scale of the link's second moments in ``[1 - r, 1 + r]``
            (keeps the tensor physical: positive definite, triangle inequality).
        armature_rel: rotor armature factor in ``[1 - r, 1 + r]``.
        coulomb_rel, viscous_rel, transition_rel: per-joint factors in ``[1 - r, 1 + r]``
            on the Coulomb friction (``frictionloss`` or a sigmoid's ``phi1``), the viscous
            damping and a sigmoid's steepness ``phi2`` (``pipeline.model.uncertainty``).
        payload_kg: extra payload in ``[0, r]`` [kg].
    """

    _where = "plant.uncertainty"

    mass_rel: NonNegative = knob(0.0, ge=0, lt=1, description="link mass x U[1 - r, 1 + r]")
    com_m: NonNegative = knob(0.0, ge=0, le=0.5, unit="m", description="per axis U[-r, r]")
    inertia_rel: NonNegative = knob(
        0.0, ge=0, lt=1, description="second moments scaled per axis by U[1 - r, 1 + r]"
    )
    armature_rel: NonNegative = knob(
        0.0, ge=0, lt=1, description="rotor armature x U[1 - r, 1 + r]"
    )
    # issue 28's draws (added: bags written before it drew none)
    coulomb_rel: NonNegative = knob(
        0.0,
        ge=0,
        lt=1,
        added=True,
        description="Coulomb friction (or a sigmoid's phi1) x U[1 - r, 1 + r]",
    )
    viscous_rel: NonNegative = knob(
        0.0, ge=0, lt=1, added=True, description="viscous damping x U[1 - r, 1 + r]"
    )
    transition_rel: NonNegative = knob(
        0.0, ge=0, lt=1, added=True, description="a sigmoid's steepness phi2 x U[1 - r, 1 + r]"
    )
    payload_kg: NonNegative = knob(
        0.0, ge=0, le=1000, unit="kg", added=True, description="extra payload U[0, r]"
    )

    @property
    def any(self) -> bool:
        return any(v > 0 for v in (self.mass_rel, self.com_m, self.inertia_rel, self.armature_rel))


@dataclass(frozen=True)
class LoopSettings(Contract):
    """The loop between the plant and the controller, the same for every law (the
    defaults: an ideal loop: no delay, exact position, the plant's velocity).

    Attributes:
        delay_s: pure actuation delay: a command reaches the motors this long after
            the instant it was computed for [s] (a whole number of physics steps).
        encoder_counts_per_rev: encoder resolution; the measured position is rounded
            to the nearest count (0: not quantised).
        jitter_s: most extra delay per control period, drawn uniformly in whole
            physics steps ``{0, .., jitter_s / physics_dt_s}`` from the episode seed [s].
        velocity: ``plant``: the plant's velocity plus the independent velocity noise;
            ``encoder``: the measured position differenced over the control period, then
            low-passed (first order, ``velocity_cutoff_hz``).
        velocity_cutoff_hz: the low-pass cutoff for ``encoder`` velocity (0: unfiltered).

    The report's loop line lists the fields in this order.
    """

    _where = "loop"

    delay_s: NonNegative = knob(
        0.0,
        ge=0,
        le=MAX_LOOP_DELAY_S,
        unit="s",
        description="actuation delay (whole physics steps)",
    )
    encoder_counts_per_rev: Count = knob(
        0, ge=0, le=2**40, description="encoder resolution (0: not quantised)"
    )
    jitter_s: NonNegative = knob(
        0.0, ge=0, le=MAX_LOOP_DELAY_S, unit="s", description="most extra delay per control period"
    )
    velocity: Annotated[
        VelocitySource,
        rule(f"one of {', '.join(VELOCITY_SOURCES)}", lambda v: v in VELOCITY_SOURCES),
    ] = knob("plant", description="plant, or encoder: differenced, low-passed")
    velocity_cutoff_hz: NonNegative = knob(
        0.0,
        ge=0,
        le=1e6,
        unit="Hz",
        refines="velocity",
        description="encoder velocity low-pass cutoff (0: unfiltered)",
    )

    @property
    def ideal(self) -> bool:
        """Every field at its default: no delay, no jitter, no quantisation, the plant's
        velocity (the loop before issue 18; ``velocity_cutoff_hz`` refines ``velocity``
        and then plays no part). A new field's default is its ideal value."""
        return at_defaults(self)


LEGACY_FRICTION = "frictionloss at MuJoCo's default softness (creeps under the breakaway torque)"
"""The friction law of bags that do not name theirs (recorded before it stuck)."""


@dataclass(frozen=True)
class LinkInertial(Contract):
    """One link's rigid-body inertia as the plant has it (DH frame of its joint).

    Attributes:
        mass: [kg]. com: centre of mass [m].
        inertia: [ixx, iyy, izz, ixy, ixz, iyz] about the centre of mass [kg m^2].
    """

    _where = "plant.links[0]"

    mass: Positive
    com: Annotated[
        tuple[Finite, Finite, Finite], listed("a list of numbers", length=3, sized="3 numbers")
    ]
    inertia: Annotated[
        tuple[Finite, Finite, Finite, Finite, Finite, Finite],
        listed("a list of numbers", length=6, sized="6 numbers (ixx iyy izz ixy ixz iyz)"),
    ]


@dataclass(frozen=True)
class SigmoidFrictionSettings(Contract):
    """A plant's sigmoid joint friction per joint, as drawn (``pipeline.model.published``):
    ``tau_f = phi1 / (1 + exp(-phi2 (qd + phi3))) - phi1 / (1 + exp(-phi2 phi3))``."""

    _where = "plant.sigmoid_friction"

    phi1_nm: NonNegatives
    phi2_s_rad: NonNegatives
    phi3_rad_s: Numbers


@dataclass(frozen=True, kw_only=True)
class PlantSettings(Contract):
    """The simulated plant, exactly enough to rebuild it (with the robot's geometry).

    Attributes:
        exact: the nominal model is the plant (no mismatch of any kind, no noise): the
            controllers' model-based terms are exact by construction.
        links: the plant's link inertials (drawn from ``uncertainty`` or the nominal ones).
        armature: the plant's rotor armature per joint [kg m^2] (nominal + mismatch).
        nominal_armature: the nominal model's armature per joint [kg m^2].
        damping, frictionloss: per joint [N m s/rad], [N m] (the nominal model has none).
        payload_kg: point mass at the flange the nominal model does not know [kg].
        position_noise_std_rad, velocity_noise_std_rad_s: sensor noise (std).
        uncertainty: the spread the links and armature were drawn from.
        physics_dt_s, control_period_s: MuJoCo step and control period [s].
        integrator, engine: MuJoCo's integrator, "mujoco".
        friction_model: the joint friction law the plant ran (``frictionloss`` and ``damping``).
        profile: the published plant's source (``plant.profile``), "" for the robot's own.
        sigmoid_friction: the sigmoid friction the plant ran, None if none.
        effort_offset_nm, effort_noise_std_nm: the torque sensor's offset per joint and
            noise std on what is recorded as effort [N m] (empty, 0: exact).

    The ``given`` fields are params' ``plant.<field>`` as given (their default: the exact
    plant); ``added`` ones are left out of the settings while at their default (bags
    written before issue 28 have none). The report's plant line lists the shown fields
    in this order.
    """

    _where = "plant"
    # bags written before the plant recorded its friction law ran MuJoCo's soft default
    _may_be_absent = frozenset({"friction_model"})

    exact: Flag
    damping: NonNegatives
    frictionloss: NonNegatives
    armature: NonNegatives
    nominal_armature: NonNegatives
    payload_kg: NonNegative
    position_noise_std_rad: NonNegative = knob(
        0.0, ge=0, le=1.0, unit="rad", given=True, description="position sensor noise std"
    )
    velocity_noise_std_rad_s: NonNegative = knob(
        0.0, ge=0, le=100.0, unit="rad/s", given=True, description="velocity sensor noise std"
    )
    uncertainty: Uncertainty
    physics_dt_s: Positive
    integrator: Text = "Euler"
    control_period_s: Positive
    engine: Text = "mujoco"
    friction_model: Text = LEGACY_FRICTION
    links: Annotated[tuple[LinkInertial, ...], listed("a list of link inertials", tuples=False)] = (
        knob(shown=False, description="the plant's link inertials")
    )
    profile: Text = knob("", shown=False, added=True, description="the published plant's source")
    sigmoid_friction: SigmoidFrictionSettings | None = knob(
        None, shown=False, added=True, description="the sigmoid friction the plant ran"
    )
    effort_offset_nm: Numbers = knob(
        (), shown=False, added=True, description="torque-sensor offset"
    )
    effort_noise_std_nm: NonNegative = knob(
        0.0,
        ge=0,
        le=1000,
        unit="N m",
        shown=False,
        given=True,
        added=True,
        description="torque-sensor noise std",
    )


@dataclass(frozen=True)
class CampaignInfo(Contract):
    """Where an episode sits in a campaign (a sweep), for the report's summaries.

    Attributes:
        name: the campaign's name in params.
        condition: stable key of the swept values other than the controller and the
            seed (e.g. ``"payload_kg=0.5,frictionloss=1"``; ``""`` when only those vary):
            episodes of one condition differ only by controller and seed.
        swept: every swept axis and this episode's value (controller and seed included),
            JSON scalars, keyed by the params path (``plant.payload_kg``).
    """

    _where = "campaign"

    name: Text
    condition: Text
    swept: Annotated[Mapping[str, Scalar], guard("a mapping", is_mapping)]
