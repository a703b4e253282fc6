"""Joint-space controllers behind one interface, chosen by name (built-in or plug-in).

The names below load on first use (PEP 562): importing :mod:`pipeline.control.info`
(what the report needs) does not import the controllers, nor Pinocchio.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pipeline.control.base import DEFAULT_OMEGA_N_RAD_S, DEFAULT_ZETA, Controller, GainSpec
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

_WHERE = {
    "DEFAULT_OMEGA_N_RAD_S": "base",
    "DEFAULT_ZETA": "base",
    "Controller": "base",
    "GainSpec": "base",
    "CONTROLLERS": "registry",
    "ControllerEntry": "registry",
    "UnknownControllerError": "registry",
    "controller_entry": "registry",
    "controller_names": "registry",
    "controller_origin": "registry",
    "default_gains": "registry",
    "installed_controllers": "registry",
    "make_controller": "registry",
}

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


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(f"pipeline.control.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
