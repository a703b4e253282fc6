"""Joint-space controllers behind one interface, chosen by name (built-in or plug-in).

The names below load on first use (PEP 562): importing :mod:`pipeline.control.info`
(what the report needs) does not import the controllers, nor Pinocchio.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pipeline.control.controller import (
        DEFAULT_OMEGA_N_RAD_S,
        DEFAULT_ZETA,
        Controller,
        GainSpec,
    )
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

# Each name's module, by its full import path (what make sync's import scan follows).
_WHERE = {
    "DEFAULT_OMEGA_N_RAD_S": "pipeline.control.controller",
    "DEFAULT_ZETA": "pipeline.control.controller",
    "Controller": "pipeline.control.controller",
    "GainSpec": "pipeline.control.controller",
    "CONTROLLERS": "pipeline.control.registry",
    "ControllerEntry": "pipeline.control.registry",
    "UnknownControllerError": "pipeline.control.registry",
    "controller_entry": "pipeline.control.registry",
    "controller_names": "pipeline.control.registry",
    "controller_origin": "pipeline.control.registry",
    "default_gains": "pipeline.control.registry",
    "installed_controllers": "pipeline.control.registry",
    "make_controller": "pipeline.control.registry",
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
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
