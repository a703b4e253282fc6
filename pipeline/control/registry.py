"""Controllers by name: one file per controller, one line here per built-in
(``"pipeline.control.<module>:<Class>"`` in :data:`BUILTIN`).

A name resolves to a built-in (:data:`CONTROLLERS`), else an installed entry point in
the group ``armlab.controllers``, else ``package.module:Object`` (see
:mod:`pipeline.plugins`). A plug-in points at a :class:`ControllerEntry`, or at a
controller class that declares ``GAINS`` (a tuple of :class:`GainSpec`) and
``DEFAULT_GAINS`` (and optionally ``COLOR`` and ``DESCRIPTION``), as
:class:`~pipeline.control.controller.NominalPDController` subclasses do.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from numpy.typing import ArrayLike

from pipeline.control.controller import DEFAULT_OMEGA_N_RAD_S, DEFAULT_ZETA, Controller, GainSpec
from pipeline.control.info import GROUP, RGB
from pipeline.errors import ParamsError, PipelineError
from pipeline.plugins import installed_names, resolve
from pipeline.robots.spec import RobotSpec


class UnknownControllerError(ParamsError):
    """A controller name that resolves to nothing (or to something that is not a controller)."""


@dataclass(frozen=True)
class ControllerEntry:
    """How to build a controller, and what the rest of the pipeline needs to know of it.

    Attributes:
        factory: ``factory(spec, gains, where=...)``; gains override the defaults key
            by key; ``where`` prefixes error messages.
        default_gains: ``default_gains(spec, *, omega_n_rad_s, zeta, q_config)``.
        gains: the accepted gains (key, unit, default rule, which are stiffnesses);
            empty: the factory's ``GAINS``.
        color: display colour (RGB bytes); None: the next free palette colour.
        description: one line; empty: the first line of the factory's docstring.
    """

    factory: Callable[..., Controller]
    default_gains: Callable[..., dict[str, Any]]
    gains: tuple[GainSpec, ...] = ()
    color: RGB | None = None
    description: str = ""

    @property
    def gain_specs(self) -> tuple[GainSpec, ...]:
        """The declared gains (the entry's, else the factory's ``GAINS``)."""
        return self.gains or tuple(getattr(self.factory, "GAINS", ()))

    @property
    def summary(self) -> str:
        """One-line description."""
        doc = inspect.getdoc(self.factory) or ""
        return self.description or (doc.splitlines()[0] if doc else "")


def controller_entry_of_class(cls: Any) -> ControllerEntry:
    """The entry of a controller class, from what it declares
    (:mod:`pipeline.control.controller`)."""
    color = getattr(cls, "COLOR", None)
    return ControllerEntry(
        cls,
        cls.DEFAULT_GAINS,
        gains=tuple(cls.GAINS),
        color=tuple(color) if color is not None else None,
        description=str(getattr(cls, "DESCRIPTION", "")),
    )


# One line per built-in controller, "module:Class" (the class declares its name, gains,
# colour, ...), in the order of their colours (matplotlib's tab10) and of the info table.
BUILTIN: tuple[str, ...] = (
    "pipeline.control.pid:PidController",
    "pipeline.control.ctc:ComputedTorqueController",
    "pipeline.control.ctc_pid:ComputedTorquePidController",
    "pipeline.control.pd_gravity:PdGravityController",
    "pipeline.control.pid_ff:PidFeedForwardController",
    "pipeline.control.pid_humble:PidHumbleController",
    "pipeline.control.passivity:PassivityController",
    "pipeline.control.adaptive:AdaptiveController",
)


def _builtin(path: str) -> tuple[str, type]:
    """The name and class a :data:`BUILTIN` line names (a typo fails at import, naming it)."""
    module, _, attr = path.partition(":")
    cls = getattr(importlib.import_module(module), attr, None)
    name = getattr(cls, "NAME", None)
    if not isinstance(cls, type) or not isinstance(name, str):
        raise TypeError(f"pipeline.control.registry.BUILTIN: {path!r} is no controller class")
    return name, cls


CONTROLLERS: dict[str, ControllerEntry] = {
    name: controller_entry_of_class(cls) for name, cls in map(_builtin, BUILTIN)
}
"""The built-in controllers, by name (their colours are matplotlib's tab10)."""


def controller_names() -> tuple[str, ...]:
    """Built-in controller names, sorted."""
    return tuple(sorted(CONTROLLERS))


def installed_controllers() -> tuple[str, ...]:
    """Names of the controllers installed as entry points (group ``armlab.controllers``)."""
    return installed_names(GROUP)


def controller_entry(name: str, *, source: str = "") -> ControllerEntry:
    """The entry of controller ``name``: built-in, entry point or ``module:Object``.

    Raises:
        UnknownControllerError: unknown name (lists built-in and installed names), a
            plug-in that fails to import, or an object that is not a controller.
    """
    where = f"{source}.type: " if source else ""
    found = resolve(
        name, CONTROLLERS, group=GROUP, what="controller", error=UnknownControllerError, where=where
    )
    return _as_entry(found.obj, name, where)


def controller_origin(name: str) -> dict[str, str]:
    """Where controller ``name``'s code comes from, for the recording.

    ``{"kind": "builtin"}``; an entry point's distribution and version; or a module's
    file path and SHA-256 (see :class:`pipeline.plugins.Resolved`).
    """
    found = resolve(name, CONTROLLERS, group=GROUP, what="controller", error=UnknownControllerError)
    return dict(found.origin)


def known_entry(name: str) -> ControllerEntry | None:
    """The entry of a controller name read from data (a bag's label or recorded type):
    a built-in or an installed entry point, else None. Never imports ``module:Object``
    (a bag folder named ``this:s`` must not run code); such a name is plain text."""
    try:
        found = resolve(
            name, CONTROLLERS, group=GROUP, what="controller", error=UnknownControllerError,
            imports=False,
        )  # fmt: skip
        return _as_entry(found.obj, name, "")
    except PipelineError:
        return None


def _as_entry(obj: object, name: str, where: str) -> ControllerEntry:
    """A plug-in's object as an entry: an entry itself, or a class declaring its gains."""
    if isinstance(obj, ControllerEntry):
        entry = obj
    elif callable(obj) and hasattr(obj, "GAINS") and callable(getattr(obj, "DEFAULT_GAINS", None)):
        entry = controller_entry_of_class(obj)
    else:
        raise UnknownControllerError(
            f"{where}controller '{name}' is not a controller: expected a ControllerEntry or a "
            f"class with GAINS and DEFAULT_GAINS, got {type(obj).__name__} {obj!r:.60}"
        )
    bad = [g for g in entry.gain_specs if not isinstance(g, GainSpec)]
    if bad or not entry.gain_specs:
        raise UnknownControllerError(
            f"{where}controller '{name}': GAINS must be a non-empty tuple of GainSpec, "
            f"got {entry.gain_specs!r:.80}"
        )
    if entry.color is not None and not (
        len(entry.color) == 3 and all(isinstance(c, int) and 0 <= c <= 255 for c in entry.color)
    ):
        raise UnknownControllerError(
            f"{where}controller '{name}': colour must be three bytes (R, G, B), got {entry.color!r}"
        )
    return entry


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
        UnknownControllerError: ``name`` resolves to no controller (the message lists
            valid names).
        ParamsError: an unknown gain key or a bad gain value.
    """
    where = f"{source}.gains" if source else "gains"
    return controller_entry(name, source=source).factory(spec, gains, where=where)


def default_gains(
    spec: RobotSpec,
    controller_name: str,
    *,
    omega_n_rad_s: float = DEFAULT_OMEGA_N_RAD_S,
    zeta: float = DEFAULT_ZETA,
    q_config: ArrayLike | None = None,
) -> dict[str, Any]:
    """Default gains of ``controller_name`` for the closed loop (omega_n [rad/s], zeta).

    Model-free gains are scaled by the nominal mass-matrix diagonal at
    ``q_config`` [rad] (default: zeros, the paper's start pose); see docs/control.md.
    """
    return controller_entry(controller_name).default_gains(
        spec, omega_n_rad_s=omega_n_rad_s, zeta=zeta, q_config=q_config
    )
