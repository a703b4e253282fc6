"""Joint-space controllers behind one interface, chosen by name (built-in or plug-in)."""

from __future__ import annotations

from pipeline.control.controller import DEFAULT_OMEGA_N_RAD_S, DEFAULT_ZETA, Controller, GainSpec
from pipeline.control.registry import (
    CONTROLLERS,
    ControllerEntry,
    UnknownControllerError,
    controller_entry,
    controller_names,
    controller_origin,
    default_gains,
    installed_controllers,
    make_controller,
)

__all__ = [
    "CONTROLLERS",
    "DEFAULT_OMEGA_N_RAD_S",
    "DEFAULT_ZETA",
    "Controller",
    "ControllerEntry",
    "GainSpec",
    "UnknownControllerError",
    "controller_entry",
    "controller_names",
    "controller_origin",
    "default_gains",
    "installed_controllers",
    "make_controller",
]
