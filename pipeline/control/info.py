"""What the rest of the pipeline knows of a controller, without importing one.

A controller class declares its facts (:mod:`pipeline.control.controller` lists them: colour,
whether it holds the arm against gravity, whether it uses the nominal model, which gains
are stiffnesses). :class:`ControllerInfo` is that record; the built-ins' records are a
generated table (:data:`BUILTIN_INFO` below, written by ``make sync`` from the classes; a
test fails when it is stale), so this module, and the report that reads it,
import neither Pinocchio nor MuJoCo.

A name read from data (a bag's label or recorded type) is looked up among the built-ins,
then the installed entry points (group ``armlab.controllers``; only then is the plug-in
imported, as the registry does); a ``module:Object`` name is never imported (a bag folder
named ``this:s`` must not run code): it is plain text, with no record.
"""

from __future__ import annotations

import functools
import inspect
from dataclasses import dataclass

from pipeline.errors import PipelineError
from pipeline.plugins import installed_names, resolve

GROUP = "armlab.controllers"
"""Entry-point group of installed controllers (the registry's)."""

RGB = tuple[int, int, int]


@dataclass(frozen=True)
class ControllerInfo:
    """A controller's declared facts.

    Attributes:
        name: registry name.
        color: plot colour (RGB bytes); None: the next free palette colour.
        steady_offset: why it does not hold gravity ("" when it does; ``holds_gravity``).
        uses_nominal_model: its law evaluates the nominal rigid-body model.
        stiffness_gains: keys of its gains that are joint stiffnesses [N m/rad].
        summary: one line.
    """

    name: str
    color: RGB | None
    steady_offset: str
    uses_nominal_model: bool
    stiffness_gains: tuple[str, ...]
    summary: str

    @property
    def holds_gravity(self) -> bool:
        """At its default gains it holds the arm still against gravity (no steady offset)."""
        return not self.steady_offset


def info_of(name: str, obj: object) -> ControllerInfo | None:
    """The record of a registry entry (``ControllerEntry``: its ``factory`` and what it
    overrides) or of a controller class, from the attributes the class declares; None
    for anything else."""
    factory = getattr(obj, "factory", obj)
    if not hasattr(factory, "GAINS") and not hasattr(obj, "gain_specs"):
        return None
    gains = getattr(obj, "gain_specs", None) or tuple(getattr(factory, "GAINS", ()))
    color = getattr(obj, "color", None) if factory is not obj else None
    color = color if color is not None else getattr(factory, "COLOR", None)
    if not gains or not all(hasattr(g, "key") for g in gains):
        return None  # not a controller the registry would accept
    if color is not None and not (
        isinstance(color, tuple | list)
        and len(color) == 3
        and all(isinstance(c, int) and 0 <= c <= 255 for c in color)
    ):
        return None
    offset = str(getattr(factory, "KIT_STEADY_OFFSET", ""))
    doc = inspect.getdoc(factory) or ""
    summary = str(getattr(obj, "description", "") or getattr(factory, "DESCRIPTION", ""))
    return ControllerInfo(
        name=name,
        color=(int(color[0]), int(color[1]), int(color[2])) if color is not None else None,
        steady_offset=offset,
        uses_nominal_model=bool(getattr(factory, "USES_NOMINAL_MODEL", False)),
        stiffness_gains=tuple(g.key for g in gains if getattr(g, "stiffness", False)),
        summary=summary or (doc.splitlines()[0] if doc else ""),
    )


@functools.cache
def builtin_info() -> dict[str, ControllerInfo]:
    """The built-in controllers' records, by name (:data:`BUILTIN_INFO`)."""
    return {i.name: i for i in BUILTIN_INFO}


def controller_info(name: str) -> ControllerInfo | None:
    """The record of a controller name read from data: a built-in or an installed entry
    point, else None (never imports ``module:Object``)."""
    found = builtin_info().get(name)
    if found is not None or name not in installed_names(GROUP):
        return found
    try:  # an installed plug-in: imported, as the registry does
        plugin = resolve(name, {}, group=GROUP, what="controller", error=PipelineError)
    except PipelineError:
        return None
    return info_of(name, plugin.obj)


def stiffness_gains(name: str) -> tuple[str, ...] | None:
    """Keys of controller ``name``'s gains that are joint stiffnesses [N m/rad]; None
    when the name is no built-in or installed entry point."""
    info = controller_info(name)
    return None if info is None else info.stiffness_gains


def declared_color(name: str) -> RGB | None:
    """Controller ``name``'s own colour, if it is a built-in or an installed entry point
    that declares one."""
    info = controller_info(name)
    return None if info is None else info.color


# The built-in controllers' records, read from their classes
# (pipeline.control.registry.CONTROLLERS) by `make sync`: do not edit.
BUILTIN_INFO: tuple[ControllerInfo, ...] = (
    # begin generated: built-in controllers (make sync)
    ControllerInfo(
        name="pid",
        color=(31, 119, 180),
        steady_offset="",
        uses_nominal_model=False,
        stiffness_gains=("kp",),
        summary="Independent joint PID on effort (ros2_control JTC + control_toolbox::Pid).",
    ),
    ControllerInfo(
        name="ctc",
        color=(255, 127, 14),
        steady_offset="",
        uses_nominal_model=True,
        stiffness_gains=(),
        summary="Model-based CTC; the model is always the nominal one built from the YAML.",
    ),
    ControllerInfo(
        name="ctc_pid",
        color=(44, 160, 44),
        steady_offset="",
        uses_nominal_model=True,
        stiffness_gains=(),
        summary="CTC whose outer loop is a PID with a clamped integral state.",
    ),
    ControllerInfo(
        name="pd_gravity",
        color=(148, 103, 189),
        steady_offset="",
        uses_nominal_model=True,
        stiffness_gains=("kp",),
        summary="Joint PD plus the nominal gravity torque ``g_n(q)``.",
    ),
    ControllerInfo(
        name="pid_ff",
        color=(214, 39, 40),
        steady_offset="",
        uses_nominal_model=True,
        stiffness_gains=("kp",),
        summary="Effort PID + nominal inverse dynamics of the reference (Jazzy JTC with efforts).",
    ),
    ControllerInfo(
        name="pid_humble",
        color=(23, 190, 207),
        steady_offset=(
            "i_clamp = 0 (Humble's default) switches the integral off: under gravity the arm "
            "settles g / kp away from the reference"
        ),
        uses_nominal_model=False,
        stiffness_gains=("kp",),
        summary=(
            "Humble JTC + control_toolbox 3.x ``Pid``: no anti-windup, output-clamped integral."
        ),
    ),
    ControllerInfo(
        name="passivity",
        color=(140, 86, 75),
        steady_offset="",
        uses_nominal_model=True,
        stiffness_gains=(),
        summary="Slotine–Li passivity-based tracking on the nominal model (the YAML robot).",
    ),
    ControllerInfo(
        name="adaptive",
        color=(227, 119, 194),
        steady_offset="",
        uses_nominal_model=True,
        stiffness_gains=(),
        summary="Slotine–Li adaptive control with a projected gradient update of ``theta_hat``.",
    ),
    # end generated: built-in controllers
)
