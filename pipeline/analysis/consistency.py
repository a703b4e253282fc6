"""Settings that differ within a group of episodes the report compares.

Episodes of one group (a scenario, or a campaign condition) are compared as if run with
the same settings; an interrupted re-run with a changed value (``hold_s: 0.3`` then
``0.8``) mixes two set-ups in one group, and every number of that group is then a blend.
:func:`mixed_settings` finds each recorded setting with more than one value in a group:
the scenario's settings across the whole group, a controller's gains within its episodes.
A setting one episode's bag leaves out (a field added after others were recorded, or one
left out of the dump while at its default: ``plant.profile``) counts as its declared
default, so it differs from an episode that sets it.
"""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel

from pipeline.log.recording import Recording

SHOWN_VALUES = 3
"""Values named per field before the rest are counted."""


@dataclass(frozen=True)
class MixedSetting:
    """One setting recorded with more than one value in a group.

    Attributes:
        group: the group (scenario, or ``campaign/condition``).
        field: the setting (``hold_s``, ``plant.payload_kg``, ``ctc gains.kp``).
        values: (value as JSON, episodes) pairs, most common first.
        episodes: the group's episodes that record the setting.
        minority: episodes with a value other than the most common one, sorted.
    """

    group: str
    field: str
    values: tuple[tuple[str, int], ...]
    episodes: int
    minority: tuple[str, ...]

    def note(self) -> str:
        """E.g. ``hold_s: 0.8 vs 0.3 in 2 of 6 episodes (c.s4, c.s5)``."""
        others = [v for v, _ in self.values[1:]]
        shown = ", ".join(others[:SHOWN_VALUES]) + (
            f" (+{len(others) - SHOWN_VALUES} more)" if len(others) > SHOWN_VALUES else ""
        )
        names = ", ".join(self.minority[:SHOWN_VALUES])
        if len(self.minority) > SHOWN_VALUES:
            names += ", ..."
        return (
            f"{self.field}: {self.values[0][0]} vs {shown} in {len(self.minority)} of "
            f"{self.episodes} episodes ({names})"
        )


def _flat(node: Any, prefix: str = "") -> Iterable[tuple[str, Any]]:
    if isinstance(node, Mapping) and node:
        for key in sorted(node):
            yield from _flat(node[key], f"{prefix}.{key}" if prefix else str(key))
    else:
        yield prefix, node


Declared = Callable[[str], tuple[bool, Any]]
"""A flattened key -> (whether a declared field, its value): what an episode whose bag
leaves the key out ran with."""


def _json(value: Any) -> Any:
    """A settings value as its dump holds it (plain JSON data)."""
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json")
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    return value


def _field_names(node: Any) -> Iterable[str]:
    """The declared fields of a settings value (a params model or a settings dataclass)."""
    if isinstance(node, BaseModel):
        return type(node).model_fields.keys()
    if dataclasses.is_dataclass(node) and not isinstance(node, type):
        return [f.name for f in dataclasses.fields(node)]
    return ()


def _declared_in(root: Any, *, skip: str = "") -> Declared:
    """The value at a flattened key (``plant.profile``) of ``root``, a settings value read
    back (a field its bag leaves out holds its declared default there); none for a key
    that names no declared field or starts with ``skip``."""

    def at(key: str) -> tuple[bool, Any]:
        if skip and key.startswith(skip):
            return False, None
        node = root
        for part in key.split("."):
            if part not in _field_names(node):
                return False, None
            node = getattr(node, part)
        return True, _json(node)

    return at


def _differences(group: str, rows: Sequence[tuple[str, Mapping[str, Any], Declared]], *,
                 label: str = "") -> list[MixedSetting]:  # fmt: skip
    keys = {key: None for _, fields, _ in rows for key in fields}  # in first-seen order
    values: dict[str, dict[str, list[str]]] = {}
    for episode, fields, declared in rows:
        for key in keys:
            if key in fields:
                value = fields[key]
            else:  # left out of this bag: its declared default, if the key is a field
                known, value = declared(key)
                if not known:
                    continue
            text = json.dumps(value, sort_keys=True, default=str)
            values.setdefault(key, {}).setdefault(text, []).append(episode)
    found = []
    for key, by_value in values.items():
        if len(by_value) < 2:
            continue
        counts = Counter({v: len(eps) for v, eps in by_value.items()})
        ranked = tuple(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))
        minority = sorted(e for v, eps in by_value.items() if v != ranked[0][0] for e in eps)
        found.append(
            MixedSetting(group, f"{label}{key}", ranked, sum(counts.values()), tuple(minority))
        )
    return found


def mixed_settings(groups: Mapping[str, Sequence[Recording]]) -> list[MixedSetting]:
    """Every setting with more than one value within a group (see the module doc); empty
    when each group's episodes agree. Recordings without our settings, and failed episodes
    (which take no part in the comparisons), are left out."""
    found: list[MixedSetting] = []
    for group, recs in groups.items():
        scenario_rows: list[tuple[str, Mapping[str, Any], Declared]] = []
        gains_rows: dict[str, list[tuple[str, Mapping[str, Any], Declared]]] = {}
        for rec in recs:
            s = rec.settings
            if s is None or rec.status != "ok":  # a failed episode is compared with nothing
                continue
            scenario = {k: v for k, v in s.scenario.recorded().items() if k != "name"}
            # a controller's own plant (params controllers.NAME.plant) differs on purpose:
            # compared among that controller's episodes only
            own_plant = s.controller.plant is not None
            plant = scenario.pop("plant", None) if own_plant else None
            # (the scenario's plant of such an episode is the controller's: not filled in)
            scenario_rows.append(
                (
                    rec.episode,
                    dict(_flat(scenario)),
                    _declared_in(s.scenario, skip="plant." if own_plant else ""),
                )
            )
            gains = dict(s.controller.gains)
            gains_rows.setdefault(rec.controller, []).append(
                (
                    rec.episode,
                    {f"gains.{k}": v for k, v in _flat(gains)}
                    | ({f"plant.{k}": v for k, v in _flat(plant)} if own_plant else {}),
                    # a controller's own plant is its scenario's as recorded; gains as a whole
                    _declared_in(s.scenario, skip="" if own_plant else "plant."),
                )
            )
        found += _differences(group, scenario_rows)
        for controller, rows in sorted(gains_rows.items()):
            found += _differences(group, rows, label=f"{controller} ")
    return found
