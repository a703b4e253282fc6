"""Controllers by name: one file per controller, one line here per controller."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.control import ctc, ctc_pid, pd_gravity, pid
from pipeline.control.base import DEFAULT_OMEGA_N_RAD_S, DEFAULT_ZETA, Controller
from pipeline.errors import ParamsError, unknown_name_message
from pipeline.robots.spec import RobotSpec


class UnknownControllerError(ParamsError):
    """A controller name that is not in the registry."""


@dataclass(frozen=True)
class ControllerEntry:
    """How to build a controller and its default gains.

    Attributes:
        factory: ``factory(spec, gains, where=...)``; gains override the defaults key
            by key; ``where`` prefixes error messages.
        default_gains: ``default_gains(spec, *, omega_n_rad_s, zeta, q_config)``.
    """

    factory: Callable[..., Controller]
    default_gains: Callable[..., dict[str, Any]]


CONTROLLERS: dict[str, ControllerEntry] = {
    pid.NAME: ControllerEntry(pid.PidController, pid.default_gains),
    ctc.NAME: ControllerEntry(ctc.ComputedTorqueController, ctc.default_gains),
    ctc_pid.NAME: ControllerEntry(ctc_pid.ComputedTorquePidController, ctc_pid.default_gains),
    pd_gravity.NAME: ControllerEntry(pd_gravity.PdGravityController, pd_gravity.default_gains),
}


def controller_names() -> tuple[str, ...]:
    """Registered controller names, sorted."""
    return tuple(sorted(CONTROLLERS))


def _entry(name: str, source: str = "") -> ControllerEntry:
    try:
        return CONTROLLERS[name]
    except (KeyError, TypeError):
        where = f"{source}.type" if source else ""
        raise UnknownControllerError(
            unknown_name_message("controller", name, controller_names(), where=where)
        ) from None


def make_controller(
    name: str,
    spec: RobotSpec,
    gains: Mapping[str, Any] | None = None,
    *,
    source: str = "",
) -> Controller:
    """Build controller ``name`` for ``spec``; ``gains`` override its defaults key by key.

    ``source`` says where the settings came from, to prefix error messages
    (``source="controllers.pid_slow"`` gives ``controllers.pid_slow.gains.kp: ...``).

    Raises:
        UnknownControllerError: ``name`` is not registered (the message lists valid names).
        ParamsError: an unknown gain key or a bad gain value.
    """
    where = f"{source}.gains" if source else "gains"
    return _entry(name, source).factory(spec, gains, where=where)


def default_gains(
    spec: RobotSpec,
    controller_name: str,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: Sequence[float] | None = None,
) -> dict[str, Any]:
    """Default gains of ``controller_name`` for the closed loop (omega_n [rad/s], zeta).

    Model-free gains are scaled by the nominal mass-matrix diagonal at
    ``q_config`` [rad] (default: zeros, the paper's start pose); see docs/control.md.
    """
    return _entry(controller_name).default_gains(
        spec, omega_n_rad_s=omega_n_rad_s, zeta=zeta, q_config=q_config
    )
