"""An example armlab controller plug-in (see the package README)."""

from __future__ import annotations

from armlab_example_controller.controller import PdGravityAccFF

__all__ = ["PdGravityAccFF"]
