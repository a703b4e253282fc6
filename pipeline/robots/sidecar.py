"""The settings sidecar ``<stem>.armlab.yaml``: the facts a robot file (URDF, MJCF) lacks or
that its user states over it (tip, locked joints, armature, friction, acceleration limits).

One schema for every loader that reads a description format. A value the sidecar gives
wins over the file's own; :func:`joint_default` applies that precedence and names the
source, which the recording keeps (:attr:`pipeline.robots.spec.RobotSpec.settings_sources`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

from pydantic import Field, ValidationError

from pipeline.errors import SpecError
from pipeline.robots.dh_yaml import StrictModel, format_validation_error
from pipeline.yamlio import parse_yaml

__all__ = [
    "NOT_STATED",
    "SIDECAR_SUFFIX",
    "Sidecar",
    "joint_default",
    "per_joint",
    "read_sidecar",
    "validate_sidecar",
]

SIDECAR_SUFFIX = ".armlab.yaml"
DEFAULT_ACCELERATION = 5.0  # [rad/s^2]: a planning default, as the DH robots' files state
DEFAULT_RADIUS_M = 0.04
NOT_STATED = "not stated (0)"


Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class Sidecar(StrictModel):
    """A sidecar's content (every key optional)."""

    urdf: str | None = None
    srdf: str | None = None
    tip: str | None = None
    flange: str | None = None
    locked: dict[str, float] = Field(default_factory=dict)
    acceleration: Positive | list[Positive] = Field(default=DEFAULT_ACCELERATION)
    velocity: Positive | list[Positive] | None = None  # over the file's (MJCF states none)
    armature: NonNegative | list[NonNegative] = 0.0
    armature_source: str | None = None
    damping: NonNegative | list[NonNegative] = 0.0
    frictionloss: NonNegative | list[NonNegative] = 0.0
    collision_radius: float = Field(default=DEFAULT_RADIUS_M, gt=0, le=1.0)

    def source_of(self, key: str, sidecar: str) -> str:
        """``sidecar`` (its name) when it gives ``key``, else :data:`NOT_STATED` (a robot fact
        the files do not state: :mod:`pipeline.robots.facts` supplies and reports it)."""
        return sidecar if key in self.model_fields_set else NOT_STATED


def read_sidecar(path: Path) -> dict[str, Any]:
    """A sidecar file's YAML mapping (validate it with :func:`validate_sidecar`).

    Raises:
        SpecError: unreadable, bad YAML or not a mapping (names the file).
    """
    try:
        data = parse_yaml(path.read_text(encoding="utf-8"), source=str(path), error=SpecError)
    except (OSError, UnicodeDecodeError) as err:
        raise SpecError(f"{path}: cannot read ({err})") from err
    if not isinstance(data, dict):
        raise SpecError(f"{path}: expected a mapping (urdf, tip, locked, armature, ...)")
    return data


def validate_sidecar(data: dict[str, Any], source: str) -> Sidecar:
    """``data`` as a :class:`Sidecar`.

    Raises:
        SpecError: one line naming ``source`` and the field path.
    """
    try:
        return Sidecar.model_validate(data)
    except ValidationError as err:
        raise SpecError(format_validation_error(source, err)) from err


def per_joint(value: float | list[float], names: list[str], what: str, source: str) -> list[float]:
    """A sidecar value given once or per joint, one per joint of ``names``.

    Raises:
        SpecError: a list of another length (names ``source`` and ``what``).
    """
    if isinstance(value, list):
        if len(value) != len(names):
            raise SpecError(
                f"{source}: {what}: expected 1 or {len(names)} values, got {len(value)}"
            )
        return [float(v) for v in value]
    return [float(value)] * len(names)


def joint_default(
    opts: Sidecar, key: str, in_file: list[float | None], *, sidecar: str, stated: str
) -> tuple[list[float], str]:
    """A per-joint fact (``damping``, ``frictionloss``, ``armature``) and where it came from.

    The sidecar wins where it gives ``key``; else each joint's value in the robot file
    (``in_file``, None where a joint states none: 0); else 0 (:data:`NOT_STATED`).

    Args:
        in_file: the robot file's value per chain joint, None where it states none.
        sidecar: the sidecar's name (its source when it gives ``key``).
        stated: the source named when the file states the value (``URDF <dynamics>``).

    Raises:
        SpecError: a sidecar list of the wrong length or a negative value.
    """
    if key in opts.model_fields_set:
        names = [str(i) for i in range(len(in_file))]
        values = per_joint(getattr(opts, key), names, key, sidecar)
        if any(v < 0 for v in values):
            raise SpecError(f"{sidecar}: {key}: values must be >= 0, got {values}")
        return values, sidecar
    if all(v is None for v in in_file):
        return [0.0] * len(in_file), NOT_STATED
    return [v or 0.0 for v in in_file], stated
