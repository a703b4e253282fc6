"""Joint-space controllers behind one interface, chosen by name: pid, ctc, pd_gravity."""

from __future__ import annotations

from pipeline.control.base import DEFAULT_OMEGA_N_RAD_S, DEFAULT_ZETA, Controller
from pipeline.control.registry import (
    CONTROLLERS,
    UnknownControllerError,
    controller_names,
    default_gains,
    make_controller,
)

__all__ = [
    "CONTROLLERS",
    "DEFAULT_OMEGA_N_RAD_S",
    "DEFAULT_ZETA",
    "Controller",
    "UnknownControllerError",
    "controller_names",
    "default_gains",
    "make_controller",
]
