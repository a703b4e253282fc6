"""ROS 2 message definitions (``ros2msg``): parse the ``.msg`` text into typed fields.

The subset ROS 2 interface files use: primitive types, ``string``/``wstring`` (optionally
bounded, ``string<=10``), fixed arrays ``T[3]``, bounded sequences ``T[<=3]``, unbounded
sequences ``T[]``, nested types (``pkg/Type``, ``pkg/msg/Type`` or a same-package ``Type``),
constants (``int32 X=1``) and default values (``float64 w 1``). A concatenated MCAP schema is
the root type's text followed by ``=====`` separated ``MSG: pkg/Type`` sections, as rosbag2
writes it.

The parsed :data:`MsgTypes` drive both sides of the CDR codec (:mod:`pipeline.log.cdr`): the
writer lays a message out from them and the reader walks bytes with them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

# Primitive ROS 2 types -> numpy dtype code (no byte order).
PRIMITIVES: dict[str, str] = {
    "bool": "u1",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "int64": "i8",
    "uint64": "u8",
    "float32": "f4",
    "float64": "f8",
}
STRINGS = ("string", "wstring")
TIME_TYPES = ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")
SECTION_DELIMITER = "=" * 80

_SECTION_RE = re.compile(r"^={3,}\s*$", re.MULTILINE)
_ARRAY_RE = re.compile(r"^(?P<base>[^\[]+)(\[(?P<bound><=)?(?P<size>\d*)\])?$")
_NAME_RE = re.compile(r"^[a-zA-Z][a-zA-Z0-9_]*$")


@dataclass(frozen=True)
class MsgField:
    """One field of a message type.

    Attributes:
        name: field name.
        base: primitive name (``float64``, ``string``) or full type (``pkg/msg/Type``).
        array: None for a single value, -1 for a sequence (bounded or not), N for a fixed
            array of N.
        bound: the upper bound of a bounded sequence (``T[<=N]``), else None.
        default: the default value's text, if the definition gives one.
    """

    name: str
    base: str
    array: int | None = None
    bound: int | None = None
    default: str | None = None

    @property
    def is_primitive(self) -> bool:
        return self.base in PRIMITIVES

    @property
    def is_string(self) -> bool:
        return self.base in STRINGS


@dataclass(frozen=True)
class MsgConstant:
    """A constant of a message type (``uint8 FOO=1``); not on the wire."""

    name: str
    base: str
    value: str


@dataclass(frozen=True)
class MsgType:
    """A message type: its fields in wire order, and its constants."""

    name: str
    fields: tuple[MsgField, ...]
    constants: tuple[MsgConstant, ...] = ()

    def field_names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.fields)


MsgTypes = dict[str, MsgType]


def normalize_type(name: str, package: str) -> str:
    """A type as written in a ``.msg`` file -> its full name (``pkg/msg/Type``).

    Primitives and strings (bounds dropped) stay as they are; ``Header``, ``time`` and
    ``duration`` get their ROS 2 homes; unqualified names belong to ``package``.
    """
    if name in PRIMITIVES or name in STRINGS:
        return name
    if name.startswith(("string<=", "wstring<=")):
        return name.split("<=")[0]
    if name in ("time", "duration"):
        return f"builtin_interfaces/msg/{name.capitalize()}"
    parts = name.split("/")
    if len(parts) == 3:
        return name
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if name == "Header":
        return "std_msgs/msg/Header"
    return f"{package}/msg/{name}"


def root_type_name(schema_name: str) -> str:
    """The full name (``pkg/msg/Type``) of a schema's root type.

    MCAP schema names come as ``sensor_msgs/msg/JointState`` (ROS 2) or
    ``sensor_msgs/JointState`` (older writers); both mean the same type.
    """
    return normalize_type(schema_name, schema_name.split("/")[0])


def short_name(type_name: str) -> str:
    """``pkg/msg/Type`` -> ``pkg/Type`` (the spelling of ``MSG:`` lines)."""
    parts = type_name.split("/")
    return f"{parts[0]}/{parts[-1]}"


def parse_fields(name: str, text: str) -> MsgType:
    """Parse one ``.msg`` text (no ``MSG:`` sections) of the type ``name`` (full name).

    Raises:
        ValueError: a line that is not a field or constant definition.
    """
    package = name.split("/")[0]
    fields: list[MsgField] = []
    constants: list[MsgConstant] = []
    for raw_line in text.splitlines():
        line = raw_line.split("#", 1)[0].strip()
        if not line:
            continue
        type_token, _, rest = line.partition(" ")
        rest = rest.strip()
        if not rest:
            raise ValueError(f"{name}: cannot parse line {raw_line!r}")
        head, _, tail = rest.partition(" ")
        if "=" in head or tail.lstrip().startswith("="):
            cname, _, value = rest.partition("=")
            base = normalize_type(type_token, package)
            constants.append(MsgConstant(cname.strip(), base, value.strip()))
            continue
        fname, _, default = rest.partition(" ")
        if not _NAME_RE.match(fname):
            raise ValueError(f"{name}: bad field name {fname!r} in {raw_line!r}")
        match = _ARRAY_RE.match(type_token)
        if match is None:
            raise ValueError(f"{name}: cannot parse type {type_token!r}")
        array: int | None = None
        bound: int | None = None
        if match.group(0) != match.group("base"):
            size = match.group("size")
            if match.group("bound"):
                array, bound = -1, int(size)
            else:
                array = int(size) if size else -1
        base = normalize_type(match.group("base"), package)
        fields.append(MsgField(fname, base, array, bound, default.strip() or None))
    return MsgType(name, tuple(fields), tuple(constants))


def parse_msgdef(root_type: str, text: str) -> MsgTypes:
    """Parse a ``ros2msg`` schema (the root definition plus ``MSG: pkg/Type`` sections).

    Returns:
        Every type it defines by full name (``pkg/msg/Type``; the root under
        :func:`root_type_name`). ``Time`` and ``Duration`` are added when the schema
        leaves them out (rosbag2 omits them in some versions).

    Raises:
        ValueError: unparseable text, or a type used but not defined.
    """
    root = root_type_name(root_type)
    types: MsgTypes = {}
    for i, section in enumerate(_SECTION_RE.split(text)):
        body = section.strip("\n")
        if i == 0:
            name = root
        else:
            first, _, body = body.partition("\n")
            if not first.startswith("MSG:"):
                raise ValueError(f"section {i} does not start with 'MSG: <type>'")
            name = normalize_type(first.removeprefix("MSG:").strip(), "")
        types[name] = parse_fields(name, body)
    for t in TIME_TYPES:
        types.setdefault(t, MsgType(t, (MsgField("sec", "int32"), MsgField("nanosec", "uint32"))))
    for mt in types.values():
        for f in mt.fields:
            if not (f.is_primitive or f.is_string) and f.base not in types:
                raise ValueError(f"type {f.base} is used but not defined")
    return types


def dependencies(types: MsgTypes, name: str) -> list[str]:
    """Full names of the non-primitive types ``name``'s fields use directly, sorted."""
    return sorted({f.base for f in types[name].fields if not (f.is_primitive or f.is_string)})
