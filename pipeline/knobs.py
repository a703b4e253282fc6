"""The settings concepts ``params.yaml`` and a recording share, each declared once.

A scenario's ``loop:`` and ``plant.uncertainty:`` are these dataclasses: params validate
them at the edge (with the ranges each field's :func:`~pipeline.contract.knob` declares,
``pipeline.params.AsParams``), the episode records them as they are, and the report's
setup lines list the fields their metadata shows. Adding a field here is the whole change.
A campaign's :class:`CampaignInfo` is what params expand and the recording keeps.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Literal

from pipeline.contract import (
    Contract,
    Count,
    NonNegative,
    Scalar,
    Text,
    guard,
    is_mapping,
    knob,
    rule,
)

MAX_LOOP_DELAY_S = 0.1  # a 100 ms actuation delay is a broken loop, not a setting

# issue 28's draws at their unused values: left out of params dumps and settings then
UNUSED_DRAWS: dict[str, float] = {
    "coulomb_rel": 0.0,
    "viscous_rel": 0.0,
    "transition_rel": 0.0,
    "payload_kg": 0.0,
}

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
    _may_be_absent = frozenset(UNUSED_DRAWS)  # bags written before issue 28: none drawn

    mass_rel: NonNegative = knob(0.0, ge=0, lt=1, description="link mass x U[1 - r, 1 + r]")
    com_m: NonNegative = knob(0.0, ge=0, le=0.5, unit="m", description="per axis U[-r, r]")
    inertia_rel: NonNegative = knob(
        0.0, ge=0, lt=1, description="second moments scaled per axis by U[1 - r, 1 + r]"
    )
    armature_rel: NonNegative = knob(
        0.0, ge=0, lt=1, description="rotor armature x U[1 - r, 1 + r]"
    )
    coulomb_rel: NonNegative = knob(
        0.0, ge=0, lt=1, description="Coulomb friction (or a sigmoid's phi1) x U[1 - r, 1 + r]"
    )
    viscous_rel: NonNegative = knob(
        0.0, ge=0, lt=1, description="viscous damping x U[1 - r, 1 + r]"
    )
    transition_rel: NonNegative = knob(
        0.0, ge=0, lt=1, description="a sigmoid's steepness phi2 x U[1 - r, 1 + r]"
    )
    payload_kg: NonNegative = knob(
        0.0, ge=0, le=1000, unit="kg", description="extra payload U[0, r]"
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
        0.0, ge=0, le=1e6, unit="Hz", description="encoder velocity low-pass cutoff (0: unfiltered)"
    )

    @property
    def ideal(self) -> bool:
        """No delay, no jitter, no quantisation, the plant's velocity (the loop before
        issue 18; ``velocity_cutoff_hz`` then plays no part)."""
        return (
            self.delay_s == 0
            and self.jitter_s == 0
            and self.encoder_counts_per_rev == 0
            and self.velocity == "plant"
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
