"""Plug-ins by name, as pluginlib finds them for ros2_control: built-in, entry point, import path.

A name resolves to, in order:

1. a built-in (the registry's dict from name to entry);
2. an installed entry point in the family's group (``armlab.controllers``,
   ``armlab.ik_solvers``), found through :mod:`importlib.metadata` on ``sys.path``;
3. ``package.module:Object`` (``Object`` may be dotted), imported: only for a name
   written in params (``imports=True``). A name read from data (a bag's controller
   label or recorded type) is looked up among 1 and 2 only, never imported, so reading
   a recording cannot run code.

Nothing is registered at run time: a pool or Ray worker resolves the same name by
import, afresh. Each resolution also says where the code came from (its origin),
which a recording keeps beside the gains.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.metadata as md
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.errors import PipelineError, unknown_name_message

BUILTIN_ORIGIN: Mapping[str, str] = {"kind": "builtin"}


@dataclass(frozen=True)
class Resolved:
    """An object found by name, and where it came from.

    Attributes:
        obj: the object (an entry, a class, a factory: the family decides).
        origin: ``{"kind": "builtin"}``; ``{"kind": "entry_point", "group", "name",
            "value", "distribution", "version"}``; or ``{"kind": "module", "object",
            "path", "sha256"}`` (the module's file and the SHA-256 of its bytes).
    """

    obj: object
    origin: Mapping[str, str]


def installed_names(group: str) -> tuple[str, ...]:
    """Names of the entry points installed in ``group``, sorted."""
    return tuple(sorted({ep.name for ep in md.entry_points(group=group)}))


def resolve(
    name: str,
    builtins: Mapping[str, object],
    *,
    group: str,
    what: str,
    error: type[PipelineError],
    where: str = "",
    imports: bool = True,
) -> Resolved:
    """Find ``name``: a built-in, else an entry point of ``group``, else ``module:Object``.

    Args:
        name: the name as written in params.
        builtins: the shipped entries, by name.
        group: entry-point group, e.g. ``armlab.controllers``.
        what: the family in messages, e.g. ``controller``.
        error: the error raised (one line, listing built-in and installed names).
        where: prefix of error messages (e.g. ``controllers.mine.type: ``).
        imports: whether a ``module:Object`` name is imported; False for a name read
            from data (a bag), which then resolves to built-ins and entry points only.

    Raises:
        error: unknown name (with the near miss), an entry point or module that fails
            to import, or a missing object.
    """
    if not isinstance(name, str) or not name:
        raise error(where + unknown_name_message(what, name, sorted(builtins)))
    if name in builtins:
        return Resolved(builtins[name], BUILTIN_ORIGIN)
    try:
        return _external(name, group, what, imports)
    except _NotFound:
        pass
    except PipelineError as err:
        raise error(f"{where}{err}") from err.__cause__
    installed = installed_names(group)
    message = unknown_name_message(what, name, sorted(builtins), also=installed)
    extra = f"; installed ({group}): {', '.join(installed)}" if installed else ""
    plugin = "; or 'package.module:Object'" if imports else " (not imported: read from data)"
    raise error(f"{where}{message}{extra}{plugin}")


class _NotFound(Exception):
    """Neither an entry point nor an import path."""


@functools.lru_cache(maxsize=64)
def _external(name: str, group: str, what: str, imports: bool) -> Resolved:
    """Entry point or ``module:Object`` (cached: a campaign resolves one name per episode)."""
    eps = [ep for ep in md.entry_points(group=group) if ep.name == name]
    if eps:
        ep = eps[0]
        dist = ep.dist
        label = f"{what} '{name}' (entry point {ep.value} in {group})"
        try:
            obj = ep.load()
        except Exception as err:
            raise PipelineError(f"{label}: cannot load: {type(err).__name__}: {err}") from err
        return Resolved(
            obj,
            {
                "kind": "entry_point",
                "group": group,
                "name": name,
                "value": ep.value,
                "distribution": dist.name if dist is not None else "",
                "version": dist.version if dist is not None else "",
            },
        )
    if ":" not in name or not imports:
        raise _NotFound
    module_name, _, attr = name.partition(":")
    if not module_name or not attr:
        raise PipelineError(f"{what} '{name}': expected 'package.module:Object'")
    try:
        module = importlib.import_module(module_name)
    except Exception as err:
        raise PipelineError(
            f"{what} '{name}': cannot import {module_name}: {type(err).__name__}: {err}"
        ) from err
    found: Any = module
    for part in attr.split("."):
        if not hasattr(found, part):
            raise PipelineError(f"{what} '{name}': module {module_name} has no '{attr}'")
        found = getattr(found, part)
    file = getattr(module, "__file__", None)
    path = Path(file).resolve() if file else None
    return Resolved(
        found,
        {
            "kind": "module",
            "object": name,
            "path": str(path) if path else "",
            "sha256": hashlib.sha256(path.read_bytes()).hexdigest() if path else "",
        },
    )
