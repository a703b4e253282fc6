"""YAML at the edge: parse once, fast (libyaml when present), errors with the line.

Duplicate mapping keys are an error, not "the last one wins": a params or robot file
with two ``hold_s:`` lines (or two ``paper:`` scenarios) would otherwise silently run
something other than what the reader of the file sees.
"""

from __future__ import annotations

import typing
from collections.abc import Hashable
from typing import Any

import yaml

from pipeline.errors import PipelineError

_Base: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml: ~20x faster


class _DuplicateKeyError(yaml.constructor.ConstructorError):
    pass


class _UniqueKeyLoader(_Base):  # type: ignore[misc]
    """SafeLoader that refuses a mapping with the same key twice."""


def _construct_mapping(loader: Any, node: yaml.MappingNode, deep: bool = False) -> Any:
    seen: dict[Any, int] = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue  # `<<: *anchor` merges; explicit keys may override merged ones
        key = loader.construct_object(key_node, deep=True)
        if not isinstance(key, Hashable):
            continue  # SafeConstructor reports unhashable keys itself
        line = key_node.start_mark.line + 1
        if key in seen:
            raise _DuplicateKeyError(
                None,
                None,
                f"duplicate key '{key}' (first at line {seen[key]})",
                key_node.start_mark,
            )
        seen[key] = line
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def parse_yaml(text: str, *, source: str, error: type[PipelineError]) -> Any:
    """Parse YAML text; a syntax error becomes ``error("<source>: not valid YAML at line N")``.

    A duplicate key becomes ``error("<source>: duplicate key 'k' (first at line M) at line N")``.
    """
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # a SafeLoader subclass
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        if isinstance(err, _DuplicateKeyError):
            raise error(f"{source}: {err.problem}{where}") from err
        raise error(f"{source}: not valid YAML{where}") from err


def _admits_bool(annotation: Any) -> bool:
    if annotation is bool or annotation is Any or annotation is object:
        return True
    return any(_admits_bool(a) for a in typing.get_args(annotation))


def _holds_bool(value: Any) -> bool:
    if isinstance(value, bool):
        return True
    return isinstance(value, list | tuple) and any(_holds_bool(v) for v in value)


def refuse_bool_numbers(fields: dict[str, Any], data: Any) -> None:
    """Refuse ``true``/``false`` given where a number is expected.

    pydantic (lax mode) reads ``hold_s: true`` as 1.0; YAML users mean something else.

    Args:
        fields: the model's ``model_fields`` (name -> FieldInfo).
        data: the raw mapping about to be validated.

    Raises:
        ValueError: naming the field and the value.
    """
    if not isinstance(data, dict):
        return
    for key, value in data.items():
        info = fields.get(key) if isinstance(key, str) else None
        if info is None or _admits_bool(info.annotation) or not _holds_bool(value):
            continue
        shown = str(value).lower() if isinstance(value, bool) else str(value)
        raise ValueError(f"{key}: expected a number, got the boolean {shown}")
