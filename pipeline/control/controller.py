"""The controller interface, gain validation and the nominal-model helpers they share.

A controller maps the measured state and the reference at one control instant
to a commanded joint torque (before saturation). Gains come from
``params.yaml`` as scalars (all joints) or per-joint lists; they are checked
once, here, and every controller reports all of them through ``gains_in_effect()``
so a recording holds exactly what ran.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Protocol

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from pipeline.errors import ParamsError, unknown_name_message
from pipeline.robots.spec import RobotSpec
from pipeline.robots.urdf import build_pinocchio_model

F64 = NDArray[np.float64]

DEFAULT_OMEGA_N_RAD_S = 40.0
"""Closed-loop natural frequency of the default gains [rad/s] (see docs/control.md)."""
DEFAULT_ZETA = 1.0
"""Closed-loop damping ratio of the default gains (critically damped)."""


# What a controller class declares for the rest of the pipeline, read from the class by
# pipeline.control.info (the report reads a generated table of the built-ins' facts and
# never imports a controller). NAME, GAINS and DEFAULT_GAINS are required; the others
# are optional, with these defaults:
#   COLOR = None               its plot colour, (R, G, B) bytes; None: the next free one.
#   USES_NOMINAL_MODEL = False compute() evaluates the nominal rigid-body model.
#   KIT_STEADY_OFFSET = ""     why, at its default gains, it does not hold the arm still
#                              against gravity (a steady offset g / kp); "": it does.
#   REPORTS = ()               keys of gains_in_effect() that are not gains.
#   DESCRIPTION = ""           one line; "": the first line of the class docstring.


class Controller(Protocol):
    """A joint-space torque controller.

    ``compute`` is called once per control period with the measured state and
    the reference at the same instant; it returns the commanded torque [N m]
    before saturation (the runner clips it to the effort limits). The
    returned array belongs to the caller only until the next ``compute``.
    """

    @property
    def name(self) -> str:
        """Registry name, e.g. ``"pid"``."""
        ...

    def gains_in_effect(self) -> dict[str, Any]:
        """Every gain, JSON-serializable, per joint (lists) or flags."""
        ...

    def reset(self) -> None:
        """Forget internal state (integrators) before a new episode."""
        ...

    def compute(self, q: F64, qd: F64, q_ref: F64, qd_ref: F64, qdd_ref: F64, dt_s: float) -> F64:
        """Commanded torque [N m] for measured q [rad], qd [rad/s], reference q_ref [rad],
        qd_ref [rad/s], qdd_ref [rad/s^2]; ``dt_s`` is the control period [s]."""
        ...


@dataclass(frozen=True)
class GainSpec:
    """One accepted gain key.

    Attributes:
        key: name in ``params.yaml`` and in ``gains_in_effect()``.
        flag: a boolean switch instead of a per-joint number.
        nonnegative: refuse values < 0 (stiffness, damping, integral gains).
        unit: its unit, e.g. ``N m/rad`` (empty for flags and dimensionless gains).
        stiffness: a joint position stiffness [N m/rad] (the report's friction
            dead-band check reads it as is; other ``kp`` are scaled by the inertia).
        default: how the default is chosen, in one short formula (docs, the kit).
    """

    key: str
    flag: bool = False
    nonnegative: bool = True
    unit: str = ""
    stiffness: bool = False
    default: str = ""


def _is_number(x: object) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool)


def resolve_gains(
    controller: str,
    spec: RobotSpec,
    schema: Sequence[GainSpec],
    defaults: Mapping[str, Any],
    gains: Mapping[str, Any] | None,
    *,
    where: str = "gains",
) -> dict[str, Any]:
    """Merge user gains over the defaults and validate every key and value.

    ``where`` prefixes error messages (e.g. ``controllers.pid_slow.gains``).

    Returns:
        key -> per-joint ``(dof,)`` float array, or ``bool`` for flags.

    Raises:
        ParamsError: unknown key (lists the valid ones), a non-number, a list
            of the wrong length, a non-finite or a negative value.
    """
    if gains is not None and not isinstance(gains, Mapping):
        raise ParamsError(f"{where}: expected a mapping of gain names to values, got {gains!r}")
    by_key = {g.key: g for g in schema}
    merged = dict(defaults)
    for key, value in (gains or {}).items():
        if key not in by_key:
            raise ParamsError(
                unknown_name_message(f"{controller} gain", key, by_key, where=f"{where}.{key}")
            )
        merged[key] = value
    out: dict[str, Any] = {}
    for g in schema:
        if g.key not in merged:
            raise ParamsError(f"{where}.{g.key}: missing for controller '{controller}'")
        value = merged[g.key]
        if g.flag:
            if not isinstance(value, bool | np.bool_):
                raise ParamsError(f"{where}.{g.key}: expected true or false, got {value!r}")
            out[g.key] = bool(value)
            continue
        out[g.key] = _validated_gain_array(controller, spec, g, value, where)
    return out


def _validated_gain_array(
    controller: str, spec: RobotSpec, g: GainSpec, value: Any, where: str
) -> F64:
    expected = f"a number or a list of {spec.dof} numbers (one per joint of {spec.name})"
    if _is_number(value):
        arr = np.full(spec.dof, float(value))
    elif isinstance(value, Sequence | np.ndarray) and not isinstance(value, str | bytes):
        items = list(value)
        if len(items) != spec.dof:
            raise ParamsError(
                f"{where}.{g.key}: expected {expected} for controller '{controller}', "
                f"got {len(items)} values"
            )
        if not all(_is_number(x) for x in items):
            raise ParamsError(f"{where}.{g.key}: expected {expected}, got {value!r}")
        arr = np.array([float(x) for x in items])
    else:
        raise ParamsError(f"{where}.{g.key}: expected {expected}, got {value!r}")
    if not np.isfinite(arr).all():
        raise ParamsError(f"{where}.{g.key}: must be finite, got {arr.tolist()}")
    if g.nonnegative and (arr < 0).any():
        raise ParamsError(f"{where}.{g.key}: must be >= 0, got {arr.tolist()}")
    return arr


FRICTION_SMOOTH_RAD_S = 0.01
"""Default velocity scale of the friction feed-forward's smooth sign, tanh(qd / v) [rad/s]."""
FRICTION_GAINS = (
    GainSpec("friction_ff", flag=True),
    GainSpec("friction_coulomb_nm", unit="N m", default="0; a nominal MODEL.yaml's"),
    GainSpec("friction_viscous_nm_s_rad", unit="N m s/rad", default="0; a nominal MODEL.yaml's"),
    GainSpec("friction_smooth_rad_s", unit="rad/s", default=f"{FRICTION_SMOOTH_RAD_S:g}"),
)
"""Friction feed-forward (``friction_ff: true``): Coulomb + viscous torque of the
reference velocity, added to a model-based law's command."""


def friction_defaults(spec: RobotSpec) -> dict[str, Any]:
    """Friction feed-forward off, no friction (a nominal model file fills the values in)."""
    return {
        "friction_ff": False,
        "friction_coulomb_nm": [0.0] * spec.dof,
        "friction_viscous_nm_s_rad": [0.0] * spec.dof,
        "friction_smooth_rad_s": [FRICTION_SMOOTH_RAD_S] * spec.dof,
    }


def friction_feedforward(gains: Mapping[str, Any], qd_ref: F64) -> F64 | None:
    """``fc tanh(qd_ref / v) + fv qd_ref`` [N m] when ``friction_ff`` is on, else None.

    The reference velocity, not the measured one: a feed-forward, free of the encoder's
    noise; the smooth sign (scale ``v``, ``friction_smooth_rad_s``) keeps the torque
    continuous through a velocity reversal and zero at rest, where sticking friction
    needs no compensation.
    """
    if not gains["friction_ff"]:
        return None
    v = gains["friction_smooth_rad_s"]
    sign = np.where(v > 0, np.tanh(qd_ref / np.where(v > 0, v, 1.0)), np.sign(qd_ref))
    out: F64 = gains["friction_coulomb_nm"] * sign + gains["friction_viscous_nm_s_rad"] * qd_ref
    return out


TUNING_KEYS = ("omega_n_rad_s", "zeta", "design_at")
"""The knobs that choose the default gains (``params.yaml``: ``controllers.NAME.gains``)."""
DESIGN_INERTIA_KEY = "design_inertia_kg_m2"
"""Recorded beside the knobs: the nominal inertia diagonal the default gains were designed on."""
RECORDED_TUNING_KEYS = (*TUNING_KEYS, DESIGN_INERTIA_KEY)
PLANNED_PATH_KEY = "planned_path_rad"
"""Set by the pipeline (never in ``params.yaml``): the planned motion's configurations
[rad], (K, n), that ``design_at: path`` and ``start`` design the gains on."""
DESIGN_AT_MODES = ("path", "start")
DEFAULT_DESIGN_AT = "path"
"""Default gain-design configuration: the per-joint maximum of the nominal inertia along
the planned motion (docs/control.md, "Where the gains are designed")."""
NO_MOTION = "zero"
"""Recorded ``design_at`` when no planned motion was given (a bare ``make_controller``):
q = 0 clipped into the joint limits."""

DesignAt = str | tuple[float, ...]


@dataclass(frozen=True)
class Tuning:
    """The knobs that choose default gains: closed-loop natural frequency and damping, and
    the configurations whose nominal inertia the per-joint gains are designed on."""

    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S
    zeta: float = DEFAULT_ZETA
    used: bool = True  # False when explicit gains overrode every tuned default
    design_at: DesignAt = NO_MOTION  # "path", "start", a configuration, or NO_MOTION
    design_inertia_kg_m2: tuple[float, ...] = ()  # filled by resolve_tuned_gains

    def knobs_in_effect(self) -> dict[str, Any]:
        """The knobs, if they chose any gain in effect (else they would mislead)."""
        if not self.used:
            return {}
        if self.design_at == NO_MOTION and not self.design_inertia_kg_m2:
            return {"omega_n_rad_s": self.omega_n_rad_s, "zeta": self.zeta}
        at = self.design_at if isinstance(self.design_at, str) else list(self.design_at)
        out: dict[str, Any] = {
            "omega_n_rad_s": self.omega_n_rad_s,
            "zeta": self.zeta,
            "design_at": at,
        }
        if self.design_inertia_kg_m2:
            out[DESIGN_INERTIA_KEY] = list(self.design_inertia_kg_m2)
        return out


def split_tuning(gains: Any, *, where: str) -> tuple[Tuning, Any]:
    """Separate the tuning knobs (``omega_n_rad_s``, ``zeta``, ``design_at``) from explicit
    gains (``design_at`` is checked against the robot by :func:`design_configurations`).

    The knobs choose the default gains (the fair-comparison mapping, see
    docs/control.md); explicit gains such as ``kp`` then override those defaults.
    """
    if not isinstance(gains, Mapping):
        return Tuning(), gains  # None, or a wrong type that resolve_gains reports
    tuning: dict[str, float] = {}
    for key in ("omega_n_rad_s", "zeta"):
        if key in gains:
            value = gains[key]
            if not (_is_number(value) and math.isfinite(value) and value > 0):
                raise ParamsError(f"{where}.{key}: expected a positive number, got {value!r}")
            tuning[key] = float(value)
    rest = {k: v for k, v in gains.items() if k not in (*TUNING_KEYS, PLANNED_PATH_KEY)}
    return (
        Tuning(
            omega_n_rad_s=tuning.get("omega_n_rad_s", DEFAULT_OMEGA_N_RAD_S),
            zeta=tuning.get("zeta", DEFAULT_ZETA),
        ),
        rest,
    )


def design_configurations(
    spec: RobotSpec, gains: Any, *, where: str = "gains"
) -> tuple[DesignAt, F64]:
    """The configurations [rad], (K, n), whose nominal inertia the default gains use.

    ``gains.design_at``: ``path`` (default: every configuration of the planned motion,
    ``gains.planned_path_rad``), ``start`` (its first), or one configuration ``[q...]``
    within the joint limits. Without a planned motion, ``path`` and ``start`` fall back
    to q = 0 clipped into the joint limits (recorded as ``design_at: zero``).

    Raises:
        ParamsError: ``design_at`` is neither ``path``, ``start`` nor ``dof`` finite angles
            within the joint limits (one line naming ``<where>.design_at``).
    """
    mapping = gains if isinstance(gains, Mapping) else {}
    at = mapping.get("design_at", DEFAULT_DESIGN_AT)
    lower, upper = spec.lower, spec.upper
    if isinstance(at, str):
        if at not in DESIGN_AT_MODES:
            raise ParamsError(
                f"{where}.design_at: expected 'path', 'start' or a list of {spec.dof} joint "
                f"angles [rad], got {at!r}"
            )
        planned = mapping.get(PLANNED_PATH_KEY)
        if planned is None:
            return NO_MOTION, np.clip(np.zeros(spec.dof), lower, upper)[None, :]
        qs = np.asarray(planned, dtype=float).reshape(-1, spec.dof)
        return at, (qs if at == "path" else qs[:1])
    if not isinstance(at, list | tuple) or not all(_is_number(v) for v in at):
        raise ParamsError(
            f"{where}.design_at: expected 'path', 'start' or a list of {spec.dof} joint "
            f"angles [rad], got {at!r}"
        )
    q = np.asarray(at, dtype=float)
    if q.shape != (spec.dof,) or not np.isfinite(q).all():
        raise ParamsError(
            f"{where}.design_at: expected {spec.dof} finite joint angles [rad], got {len(at)}: "
            f"{list(at)}"
        )
    outside = np.flatnonzero((q < lower - 1e-9) | (q > upper + 1e-9))
    if outside.size:
        j = int(outside[0])
        raise ParamsError(
            f"{where}.design_at: joint {spec.joints[j].name} = {q[j]:g} rad is outside its "
            f"limits [{lower[j]:g}, {upper[j]:g}]"
        )
    return tuple(float(v) for v in q), q[None, :]


def with_planned_path(gains: Mapping[str, Any] | None, q_path_rad: Any) -> dict[str, Any]:
    """``gains`` plus the planned motion's configurations (K, n) [rad], which ``design_at``
    (``path`` by default, or ``start``) designs the default gains on."""
    q = np.asarray(q_path_rad, dtype=float)
    return {**(gains or {}), PLANNED_PATH_KEY: q.tolist()}


def resolve_tuned_gains(
    controller: str,
    spec: RobotSpec,
    schema: Sequence[GainSpec],
    default_gains: Callable[..., dict[str, Any]],
    gains: Any,
    *,
    where: str = "gains",
) -> tuple[Tuning, dict[str, Any]]:
    """The tuning knobs in ``gains`` choose the defaults; explicit gains override them."""
    tuning, explicit = split_tuning(gains, where=where)
    design_at, q_design = design_configurations(spec, gains, where=where)
    defaults = default_gains(
        spec, omega_n_rad_s=tuning.omega_n_rad_s, zeta=tuning.zeta, q_config=q_design
    )
    keys = {g.key for g in schema}
    # friction feed-forward: off and zero unless given (no tuning knob chooses it)
    untuned = {k: v for k, v in friction_defaults(spec).items() if k in keys - set(defaults)}
    resolved = resolve_gains(
        controller, spec, schema, {**defaults, **untuned}, explicit, where=where
    )
    overridden = isinstance(explicit, Mapping) and set(defaults) <= set(explicit)
    depends = _depends_on_configuration(spec, default_gains, tuning, defaults)
    inertia = tuple(float(m) for m in nominal_mass_diagonal(spec, q_design)) if depends else ()
    return replace(
        tuning,
        used=not overridden,
        design_at=design_at if depends else NO_MOTION,
        design_inertia_kg_m2=inertia,
    ), resolved


def _depends_on_configuration(
    spec: RobotSpec,
    default_gains: Callable[..., dict[str, Any]],
    tuning: Tuning,
    defaults: Mapping[str, Any],
) -> bool:
    """Whether the law's default gains depend on the design configuration (PID's do, CTC's
    do not): the defaults at a second, unrelated configuration differ. Only then is
    ``design_at`` recorded (else it would mislead)."""
    if not spec.has_dynamics:
        return False
    lower, upper = spec.lower, spec.upper
    probe = np.clip(0.37 + 0.61 * np.arange(spec.dof) % 1.3, lower, upper)
    other = default_gains(
        spec, omega_n_rad_s=tuning.omega_n_rad_s, zeta=tuning.zeta, q_config=probe
    )
    return any(not np.array_equal(np.asarray(other[k]), np.asarray(v)) for k, v in defaults.items())


def gains_as_json(gains: Mapping[str, Any]) -> dict[str, Any]:
    """JSON-serializable copy of resolved gains (lists of floats, bools); the friction
    feed-forward's values only when it is on (off, they play no part)."""
    hidden = {g.key for g in FRICTION_GAINS} if gains.get("friction_ff") is False else set()
    return {
        k: (v if isinstance(v, bool) else [float(x) for x in v])
        for k, v in gains.items()
        if k not in hidden
    }


def nominal_mass_diagonal(spec: RobotSpec, q_config: Any = None) -> F64:
    """Diagonal of the nominal joint-space inertia matrix M_n(q) [kg m^2], per joint the
    maximum over the given configurations.

    Args:
        spec: robot with dynamics.
        q_config: one configuration (n,) or several (K, n) [rad] (the planned motion:
            per joint the largest inertia along it, see docs/control.md); ``None`` = all
            zeros.
    """
    spec.require_dynamics("model-based default gains")
    model = build_pinocchio_model(spec)
    q = np.zeros(spec.dof) if q_config is None else np.asarray(q_config, dtype=float)
    qs = q[None, :] if q.ndim == 1 else q
    if qs.ndim != 2 or qs.shape[1] != spec.dof or qs.shape[0] < 1 or not np.isfinite(qs).all():
        raise ParamsError(
            f"q_config: expected {spec.dof} finite angles [rad] per configuration, "
            f"got shape {q.shape}"
        )
    data = model.createData()
    diag = np.array([np.diag(pin.crba(model, data, qk)) for qk in qs], dtype=float)
    out: F64 = diag.max(axis=0)
    return out


def check_tuning(omega_n_rad_s: float, zeta: float) -> None:
    """Refuse a natural frequency or damping ratio that is not a positive finite number."""
    for name, value in (("omega_n_rad_s", omega_n_rad_s), ("zeta", zeta)):
        if not (_is_number(value) and math.isfinite(value) and value > 0):
            raise ParamsError(f"{name}: expected a positive number, got {value!r}")


class NominalPDController:
    """Plumbing of the stateless ``kp``/``kd`` laws on the nominal Pinocchio model.

    A subclass names itself (``NAME``), points at its ``default_gains`` and
    writes ``compute``; gains, ``gains_in_effect()`` and the model are handled here.
    """

    NAME: ClassVar[str]
    GAINS: ClassVar[tuple[GainSpec, ...]] = (GainSpec("kp"), GainSpec("kd"))
    DEFAULT_GAINS: ClassVar[Callable[..., dict[str, Any]]]
    COLOR: ClassVar[tuple[int, int, int] | None] = None
    USES_NOMINAL_MODEL: ClassVar[bool] = True

    def __init__(
        self, spec: RobotSpec, gains: Mapping[str, Any] | None = None, *, where: str = "gains"
    ) -> None:
        spec.require_dynamics(f"the {self.NAME} controller")
        self._tuning, self._gains = resolve_tuned_gains(
            self.NAME, spec, self.GAINS, type(self).DEFAULT_GAINS, gains, where=where
        )
        self._kp: F64 = self._gains["kp"]
        self._kd: F64 = self._gains["kd"]
        self._friction_ff: bool = bool(self._gains.get("friction_ff", False))
        self._model = build_pinocchio_model(spec)
        self._data = self._model.createData()
        # per-step work buffers of the laws' outer loops
        self._a: F64 = np.zeros(spec.dof)
        self._e: F64 = np.zeros(spec.dof)

    @property
    def name(self) -> str:
        return self.NAME

    def gains_in_effect(self) -> dict[str, Any]:
        return {**self._tuning.knobs_in_effect(), **gains_as_json(self._gains)}

    def reset(self) -> None:
        """Stateless: nothing to forget."""
