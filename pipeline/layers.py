"""The package's layers, declared once: a part imports only from parts in lower layers.

A *part* is a top-level module (``errors``) or a subpackage (``robots``) of ``pipeline``.
Every import counts: at module level or inside a function, relative or absolute,
``importlib.import_module("pipeline....")`` and registry strings such as
``"pipeline.robots.dh_yaml:load_dh_yaml"`` (``tests/test_layers.py`` reads them all with
``ast``). Two parts in the same layer do not import each other. A new module or subpackage
is placed here, in the lowest layer above everything it imports (docs/architecture.md).
"""

from __future__ import annotations

LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    # (name, parts), lowest first
    (
        "foundation",
        (
            "argv",
            "constants",
            "errors",
            "layers",
            "memory",
            "pathlist",
            "supervise",
            "trajectory",
            "transforms",
        ),
    ),
    ("plumbing", ("contract", "fsutil", "plugins", "yamlio")),
    ("descriptions", ("knobs", "robots")),
    ("params", ("params",)),
    ("recorded", ("settings",)),
    ("models", ("model",)),
    ("algorithms", ("control", "kinematics", "planning")),
    ("simulation", ("sim",)),
    ("episode", ("experiment", "log")),
    ("analysis", ("analysis", "identify")),
    ("report", ("report",)),
    ("stages", ("stages", "teach")),
    ("cli", ("cli",)),
    ("entry", ("__main__",)),
    ("tools", ("devtools",)),
)
"""The layers, lowest first: ``(name, parts)``."""

REPORT_MAY_REACH: frozenset[str] = frozenset()
"""Parts `report/` may reach although they load a physics engine: none (the report reads
the controllers' facts from `pipeline.control.info`, which imports no controller)."""

PHYSICS_ENGINES: tuple[str, ...] = ("pinocchio", "mujoco")
"""Libraries ``report/`` never loads, directly or through another part of the package."""


def layer_of() -> dict[str, int]:
    """Part -> its layer's index (0 = lowest)."""
    return {part: i for i, (_, parts) in enumerate(LAYERS) for part in parts}
