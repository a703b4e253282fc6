"""The declared-validation machinery behind a recording's settings (:mod:`pipeline.settings`).

A field's type says what it accepts (``NonNegative``, ``Names``, ...): each is an
``Annotated`` type carrying one rule, pydantic walks the frozen dataclasses built on
:class:`Contract` with those rules, and ``Contract.from_dict`` raises :class:`SettingsError`
naming the field path (``planner.trajectory_duration_s: expected a finite number >= 0,
got -1``). Every field must be present unless the class names it in ``_may_be_absent``;
unknown keys are ignored.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import MISSING, Field, dataclass, field, fields
from typing import Annotated, Any, ClassVar, Self, cast

from pydantic import BeforeValidator, GetCoreSchemaHandler, PlainValidator, TypeAdapter
from pydantic import ValidationError as _ValidationError
from pydantic_core import CoreSchema, PydanticCustomError, core_schema

from pipeline.errors import RecordingError


class SettingsError(RecordingError):
    """A recording's settings do not follow the contract (names the field path)."""


# --- the rules a field's type declares ------------------------------------------------


def expected_error(what: str) -> PydanticCustomError:
    """The error a rule raises: "expected <what>"."""
    return PydanticCustomError("contract", "expected {expected}", {"expected": what})


def stated_error(message: str) -> PydanticCustomError:
    """An error whose message names its field and value itself (a nested parser's)."""
    return PydanticCustomError("contract_stated", "{message}", {"message": message})


def rule(expected: str, ok: Callable[[Any], bool], cast: Callable[[Any], Any] = lambda v: v) -> Any:
    """A leaf: ``cast(value)`` if ``ok(value)``, else "expected <expected>"."""

    def check(value: Any) -> Any:
        if not ok(value):
            raise expected_error(expected)
        return cast(value)

    return PlainValidator(check)


def guard(expected: str, ok: Callable[[Any], bool]) -> Any:
    """A container's own type, checked before pydantic checks its items."""

    def check(value: Any) -> Any:
        if not ok(value):
            raise expected_error(expected)
        return value

    return BeforeValidator(check)


def listed(expected: str, *, tuples: bool = True, length: int = 0, sized: str = "") -> Any:
    """A JSON list (or a tuple): of ``length`` items if given, else "expected <sized>"."""

    def check(value: Any) -> Any:
        if not isinstance(value, list | tuple if tuples else list):
            raise expected_error(expected)
        if length and len(value) != length:
            raise expected_error(sized or expected)
        return value

    return BeforeValidator(check)


def number(minimum: float | None = None, *, strict: bool = False) -> Any:
    def check(value: Any) -> float:
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise expected_error("a finite number")
        if minimum is not None and (value <= minimum if strict else value < minimum):
            raise expected_error(f"a finite number {'>' if strict else '>='} {minimum:g}")
        return float(value)

    return PlainValidator(check)


def integer(minimum: int) -> Any:
    return rule(
        f"an integer >= {minimum}",
        lambda v: not isinstance(v, bool) and isinstance(v, int) and v >= minimum,
        int,
    )


def is_mapping(value: Any) -> bool:
    return isinstance(value, Mapping)


def is_scalar(value: Any) -> bool:
    return value is None or isinstance(value, str | int | float | bool)


Finite = Annotated[float, number()]
NonNegative = Annotated[float, number(0)]
Positive = Annotated[float, number(0, strict=True)]
Count = Annotated[int, integer(0)]
CountFromOne = Annotated[int, integer(1)]
Text = Annotated[str, rule("a string", lambda v: isinstance(v, str))]
Flag = Annotated[bool, rule("true or false", lambda v: isinstance(v, bool))]
MaybeFlag = Annotated[
    bool | None, rule("true, false or null", lambda v: v is None or isinstance(v, bool))
]
Numbers = Annotated[tuple[Finite, ...], listed("a list of numbers")]
NonNegatives = Annotated[tuple[NonNegative, ...], listed("a list of numbers")]
Names = Annotated[tuple[Text, Text], listed("two names", length=2)]
Plain = Annotated[Mapping[str, Any], rule("a mapping", is_mapping, dict)]
Scalar = Annotated[Any, rule("a JSON scalar", is_scalar)]


# --- what a field means, for people (the report's setup lines) and for params ---------


@dataclass(frozen=True)
class Meta:
    """A settings field's declaration beyond its type, kept with it (``knob``).

    Attributes:
        label: its name in the report's setup lines ("": the field name, as recorded).
        unit: its unit ("" for none; the name's suffix says it too: ``_s``, ``_kg``).
        description: what it is, in one line.
        shown: listed in its group's setup line (in declaration order).
        bounds: the range params accept (pydantic ``Field`` keywords: ``ge``, ``le``,
            ``lt``, ...); a recording's settings accept what the field's type does.
        given: params take it as it is recorded (a plant field params pass through:
            :func:`given_fields`); its default is the neutral value (the exact plant).
        added: added after bags were written: absent in theirs (its default stands in),
            and left out of settings and params dumps while at its default, so what
            does not use it records the same bytes as before it existed.
        refines: the field this one only refines (``velocity_cutoff_hz`` refines
            ``velocity``): it plays no part while that one is at its default, so
            :func:`at_defaults` does not look at it.
    """

    label: str = ""
    unit: str = ""
    description: str = ""
    shown: bool = True
    bounds: Mapping[str, float] = field(default_factory=dict)
    given: bool = False
    added: bool = False
    refines: str = ""


def knob(
    default: Any = MISSING,
    *,
    label: str = "",
    unit: str = "",
    description: str = "",
    shown: bool = True,
    given: bool = False,
    added: bool = False,
    refines: str = "",
    **bounds: float,
) -> Any:
    """A dataclass field with its :class:`Meta` (``delay_s: NonNegative = knob(0.0,
    le=0.1, unit="s", description="...")``)."""
    meta = Meta(label, unit, description, shown, dict(bounds), given, added, refines)
    return field(default=default, metadata={"meta": meta})


def meta_of(f: Field[Any]) -> Meta:
    """A field's :class:`Meta` (the defaults when it declares none)."""
    found = f.metadata.get("meta")
    return found if isinstance(found, Meta) else Meta()


def shown_fields(cls: type) -> Iterator[tuple[str, str]]:
    """(field name, label) of each field of a settings dataclass its group's setup line
    shows, in declaration order."""
    for f in fields(cls):
        meta = meta_of(f)
        if meta.shown:
            yield f.name, meta.label or f.name


def given_fields(cls: type) -> tuple[Field[Any], ...]:
    """The fields of a settings dataclass that params take as they are recorded
    (``knob(..., given=True)``), in declaration order."""
    return tuple(f for f in fields(cls) if meta_of(f).given)


def added_defaults(cls: type) -> dict[str, Any]:
    """Field name -> default as plain JSON data, for each field declared ``added``
    (left out of dumps while it holds this value)."""
    return {f.name: plain(f.default) for f in fields(cls) if meta_of(f).added}


def omit_added(cls: type, data: dict[str, Any]) -> dict[str, Any]:
    """``data`` (a dump of ``cls``, plain JSON data) without the ``added`` fields that
    hold their default, in place."""
    for key, default in added_defaults(cls).items():
        if key in data and data[key] == default:
            del data[key]
    return data


def at_defaults(value: Any, names: Iterable[str] | None = None) -> bool:
    """Every field of a settings value (or those of ``names``) at its declared default,
    but those that only refine another (``knob(refines=...)``): the neutral setting."""
    wanted = None if names is None else set(names)
    return all(
        getattr(value, f.name) == f.default
        for f in fields(value)
        if not meta_of(f).refines and (wanted is None or f.name in wanted)
    )


class Contract:
    """What every settings dataclass shares: ``from_dict``, validated by its field types.

    Subclasses set ``_where`` (the field path their errors start with) and may name
    ``_may_be_absent`` fields (added after bags were written; their default stands in);
    a field declared ``knob(..., added=True)`` may be absent too.
    """

    _where: ClassVar[str]
    _may_be_absent: ClassVar[frozenset[str]] = frozenset()

    @classmethod
    def from_dict(cls, data: Any, path: str | None = None) -> Self:
        """Validate plain data (parsed JSON) into settings; the inverse of ``to_dict``.

        Args:
            data: the parsed JSON.
            path: the field path errors start with (default: where the class sits in
                :class:`pipeline.settings.EpisodeSettings`).

        Raises:
            SettingsError: a missing or ill-typed field, a value out of range (names it).
        """
        try:
            value: Self = _adapter(cls).validate_python(data)
        except _ValidationError as err:
            raise _settings_error(err, cls._where if path is None else path) from err
        return value

    @classmethod
    def __get_pydantic_core_schema__(cls, source: Any, handler: GetCoreSchemaHandler) -> CoreSchema:
        """pydantic's schema of the dataclass, behind a check that the data is a mapping
        holding every field (a dataclass default is the recorder's, not an old bag's)."""
        absent = cls._may_be_absent | set(added_defaults(cls))
        required = sorted(f.name for f in fields(cls) if f.name not in absent)  # type: ignore[arg-type]

        def check(value: Any) -> Any:
            if not isinstance(value, Mapping):
                raise expected_error("a mapping")
            for name in required:
                if name not in value:
                    raise PydanticCustomError("contract_missing", "missing", {"field": name})
            return dict(value)

        # the check takes the schema's reference, so every use of the class goes through it
        schema = dict(handler(source))
        ref = schema.pop("ref", None)
        return core_schema.no_info_before_validator_function(
            check, cast(CoreSchema, schema), ref=ref
        )


_ADAPTERS: dict[type, TypeAdapter[Any]] = {}


def _adapter(cls: type) -> TypeAdapter[Any]:
    if cls not in _ADAPTERS:  # built on first use: the schema needs every class defined
        _ADAPTERS[cls] = TypeAdapter(cls)
    return _ADAPTERS[cls]


def _settings_error(err: _ValidationError, where: str) -> SettingsError:
    """pydantic's first error as one line naming the field path."""
    first = err.errors()[0]
    path = where
    for part in first["loc"]:
        path += f"[{part}]" if isinstance(part, int) else f"{'.' if path else ''}{part}"
    if first["type"] == "contract_stated":
        return SettingsError(str(first["msg"]))
    if first["type"] == "contract_missing":
        field_name = (first.get("ctx") or {}).get("field", "")
        path += f"{'.' if path else ''}{field_name}"
        return SettingsError(f"{path}: missing (required by the contract)")
    return SettingsError(f"{path or 'settings'}: {first['msg']}, got {first['input']!r}")


def plain(value: Any) -> Any:
    """JSON-ready: tuples to lists, recursively."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return value
