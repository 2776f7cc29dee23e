"""Messages from one definition: JSON encoding, decoding and JSON Schema derived from the types.

A trackctl message is a frozen dataclass; its field types say everything the JSON layer needs:

* ``t_ns: int`` is written as Foxglove's time object ``{"sec", "nsec"}`` under ``timestamp``;
* ``int``, ``float``, ``str``, ``bool`` map to JSON numbers, strings and booleans;
* ``X | None`` is X or null (a missing key takes the field's default);
* ``tuple[X, ...]`` is an array; ``Annotated[tuple[X, ...], Length(n)]`` one of exactly n items;
* ``Literal["a", "b"]`` and ``Enum`` members are strings restricted to their values;
* a ``NamedTuple`` (``Vec3``, ``Quat``...) is an object of its fields; a nested dataclass an
  object of its own;
* ``Mapping[str, MetricValue]`` is an object of scalars.

Descriptions come from the class docstring (its first paragraph, plus the ``TOPIC`` class
variable) and its Google-style ``Attributes:`` section. :func:`json_schema` builds the schema
that ``formats/<SCHEMA>.json`` holds (``make formats`` writes them all with
:func:`write_schemas`; a test checks the committed files are current).

Converters are built once per class and cached: decoding a message costs one pass over its
fields, as the hand-written methods did.
"""

from __future__ import annotations

import dataclasses
import enum
import inspect
import json
import math
import re
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

__all__ = ["Length", "Range", "JsonMessage", "to_json", "from_json", "json_schema", "write_schemas"]

NS_PER_S = 1_000_000_000
TIME_FIELD = "t_ns"
TIME_KEY = "timestamp"
TIME_SUFFIX = (
    ": seconds and nanoseconds since the log's epoch (Foxglove time object); log_time of the "
    "MCAP message equals it."
)


@dataclass(frozen=True)
class Length:
    """``Annotated`` metadata: an array of exactly ``n`` items."""

    n: int


@dataclass(frozen=True)
class Range:
    """``Annotated`` metadata: bounds of a number (``gt``: exclusive lower bound)."""

    ge: float | None = None
    le: float | None = None
    gt: float | None = None


Encoder = Callable[[Any], Any]
Decoder = Callable[[Any], Any]


def _identity(value: Any) -> Any:
    return value


def _time_to_json(t_ns: int) -> dict[str, int]:
    sec, nsec = divmod(int(t_ns), NS_PER_S)
    return {"sec": sec, "nsec": nsec}


MAX_JSON_FLOAT = 1e15
"""Largest magnitude of a finite decoded float field: no physical value a trackctl message
carries (metres, m/s, radians, pixels, dBm) comes near it, and squaring it cannot overflow. NaN
and infinities (which another tool may write as ``NaN``/``Infinity``) pass: the check processor
counts them and processors treat them as missing."""
_INT64 = (-(1 << 63), (1 << 63) - 1)


def _int64(value: Any) -> int:
    """An int field: an integral JSON number within int64."""
    if isinstance(value, float):
        if not (value.is_integer() and abs(value) < 2.0**63):
            raise ValueError(f"{_short(value)} is not an integer within int64")
        value = int(value)
    if not isinstance(value, int):
        raise TypeError(f"{_short(value)} is not an integer")
    if not _INT64[0] <= value <= _INT64[1]:
        raise ValueError(f"{_short(value)} does not fit int64")
    return value


def _float(value: Any) -> float:
    """A float field: a JSON number of magnitude at most :data:`MAX_JSON_FLOAT` (or NaN/inf)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"{_short(value)} is not a number")
    if isinstance(value, int) and abs(value) > MAX_JSON_FLOAT:
        raise ValueError(f"{_short(value)} is out of range (|x| <= {MAX_JSON_FLOAT:g})")
    number = float(value)
    if MAX_JSON_FLOAT < abs(number) < math.inf:
        raise ValueError(f"{_short(value)} is out of range (|x| <= {MAX_JSON_FLOAT:g})")
    return number


def _short(value: Any) -> str:
    text = repr(value) if not isinstance(value, int) or abs(value) < 10**30 else "a huge integer"
    return text if len(text) <= 40 else text[:37] + "..."


def _time_from_json(obj: Mapping[str, Any]) -> int:
    t_ns = _int64(obj["sec"]) * NS_PER_S + _int64(obj.get("nsec", 0))
    if not _INT64[0] <= t_ns <= _INT64[1]:
        raise ValueError(f"timestamp {_short(obj['sec'])} s does not fit int64 nanoseconds")
    return t_ns


def _is_named_tuple(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, tuple) and hasattr(tp, "_fields")


def _strip(tp: Any) -> Any:
    """``T`` of ``Annotated[T, ...]`` (the JSON mapping ignores schema-only metadata)."""
    return typing.get_args(tp)[0] if typing.get_origin(tp) is typing.Annotated else tp


def _optional_arg(tp: Any) -> Any | None:
    """X for ``X | None`` (one non-None member), else None."""
    if typing.get_origin(tp) in (types.UnionType, typing.Union):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return args[0]
    return None


def _converters(tp: Any) -> tuple[Encoder, Decoder]:
    """Encoder and decoder of one field type."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Annotated:
        return _converters(args[0])
    inner = _optional_arg(tp)
    if inner is not None:
        return _optional_converters(inner)
    generic = _generic_converters(tp, origin, args)
    if generic is not None:
        return generic
    return _class_converters(tp)


def _optional_converters(inner: Any) -> tuple[Encoder, Decoder]:
    """Converters of ``inner | None``: None passes through."""
    enc, dec = _converters(inner)
    return (lambda v: None if v is None else enc(v)), (lambda v: None if v is None else dec(v))


def _generic_converters(
    tp: Any, origin: Any, args: tuple[Any, ...]
) -> tuple[Encoder, Decoder] | None:
    """Converters of a scalar union, ``tuple[X, ...]``, a mapping or a ``Literal`` (None for
    other types)."""
    if origin in (types.UnionType, typing.Union) or tp is Any:
        return _identity, _identity  # a scalar union (MetricValue): JSON as is
    if origin is tuple:
        enc, dec = _converters(args[0])
        enc_all: Encoder = list if enc is _identity else (lambda v: [enc(x) for x in v])
        return enc_all, (lambda v: tuple(map(dec, v)))
    if origin in (dict, Mapping) or tp in (dict, Mapping):
        return (lambda v: dict(v)), (lambda v: dict(v))
    if origin is typing.Literal:
        return _identity, str
    return None


def _class_converters(tp: Any) -> tuple[Encoder, Decoder]:
    """Converters of a scalar, an ``Enum``, a ``NamedTuple`` or a dataclass.

    Raises:
        TypeError: any other type.
    """
    if tp is int:
        return _identity, _int64
    if tp is float:
        return _identity, _float
    if tp in (str, bool):
        return _identity, tp
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return (lambda v: v.value), tp
    if _is_named_tuple(tp):
        return _named_tuple_converters(tp)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        cls: type = tp
        return to_json, (lambda v: from_json(cls, v))
    raise TypeError(f"no JSON mapping for type {tp!r}")


def _named_tuple_converters(tp: type) -> tuple[Encoder, Decoder]:
    hints = typing.get_type_hints(tp)
    names: tuple[str, ...] = tp._fields  # type: ignore[attr-defined]
    ns: dict[str, Any] = {"tp": tp}
    enc_items, dec_args = [], []
    for i, name in enumerate(names):
        enc, dec = _converters(hints[name])
        ns[f"e{i}"], ns[f"d{i}"] = enc, dec
        enc_items.append(f"{name!r}: " + (f"v[{i}]" if enc is _identity else f"e{i}(v[{i}])"))
        dec_args.append(f"d{i}(v[{name!r}])")
    return _compile(
        f"def enc(v):\n    return {{{', '.join(enc_items)}}}\n"
        f"def dec(v):\n    return tp({', '.join(dec_args)})\n",
        ns,
    )


def _compile(source: str, ns: dict[str, Any]) -> tuple[Encoder, Decoder]:
    """``enc`` and ``dec`` defined by ``source``. Generated once per type, as the standard
    library's dataclasses generates ``__init__``: a loop over fields per message would cost a
    third of the decoding speed of hand-written code."""
    exec(compile(source, "<trackctl.logs.jsonmap>", "exec"), ns)  # noqa: S102 - our own source
    return ns["enc"], ns["dec"]


@dataclass(frozen=True)
class _Field:
    name: str
    key: str
    enc: Encoder
    dec: Decoder
    has_default: bool
    default: Any
    factory: bool


@cache
def _plan(cls: Any) -> tuple[_Field, ...]:
    hints = typing.get_type_hints(cls, include_extras=True)
    out = []
    for f in dataclasses.fields(cls):
        enc: Encoder
        dec: Decoder
        if f.name == TIME_FIELD:
            enc, dec, key = _time_to_json, _time_from_json, TIME_KEY
        else:
            enc, dec = _converters(hints[f.name])
            key = f.name
        default: Any = dataclasses.MISSING
        factory = f.default_factory is not dataclasses.MISSING
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif factory:
            default = f.default_factory
        out.append(
            _Field(f.name, key, enc, dec, default is not dataclasses.MISSING, default, factory)
        )
    return tuple(out)


@cache
def _functions(cls: Any) -> tuple[Encoder, Decoder]:
    """Generated ``enc(msg) -> dict`` and ``dec(obj) -> msg`` of one message class."""
    ns: dict[str, Any] = {"cls": cls}
    hints = typing.get_type_hints(cls, include_extras=True)
    enc_items, dec_args = [], []
    for i, f in enumerate(_plan(cls)):
        ns[f"e{i}"], ns[f"d{i}"], ns[f"D{i}"] = f.enc, f.dec, f.default
        value, key = f"msg.{f.name}", repr(f.key)
        inner = None if f.name == TIME_FIELD else _optional_arg(_strip(hints[f.name]))
        if inner is not None:  # X | None inline: no wrapper call per field
            ns[f"e{i}"], ns[f"d{i}"] = _converters(inner)
            enc = value if ns[f"e{i}"] is _identity else f"e{i}({value})"
            enc_items.append(f"{key}: (None if {value} is None else {enc})")
            got = f"obj.get({key})" if f.has_default and f.default is None else f"obj[{key}]"
            arg = f"(None if (x{i} := {got}) is None else d{i}(x{i}))"
        else:
            enc_items.append(f"{key}: " + (value if f.enc is _identity else f"e{i}({value})"))
            arg = f"d{i}(obj[{key}])"
            if f.has_default:
                default = f"D{i}()" if f.factory else f"D{i}"
                arg = f"({arg} if {key} in obj else {default})"
        dec_args.append(f"{f.name}={arg}")
    return _compile(
        f"def enc(msg):\n    return {{{', '.join(enc_items)}}}\n"
        f"def dec(obj):\n    return cls({', '.join(dec_args)})\n",
        ns,
    )


def to_json(msg: Any) -> dict[str, Any]:
    """A message as its JSON object (every field, null for None)."""
    cls: Any = type(msg)
    enc, _ = _functions(cls)
    return typing.cast(dict[str, Any], enc(msg))


def from_json(cls: type, obj: Mapping[str, Any]) -> Any:
    """A message of ``cls`` from its JSON object; a missing key takes the field's default.

    Raises:
        KeyError: a required key is missing.
        TypeError, ValueError: a value does not convert to its field's type.
    """
    _, dec = _functions(cls)
    return dec(obj)


class JsonMessage:
    """Mixin of every trackctl message: ``to_json``/``from_json`` derived from the fields."""

    __slots__ = ()

    def to_json(self) -> dict[str, Any]:
        """This message as its JSON object."""
        return to_json(self)

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Any:
        """A message from its JSON object (see :func:`from_json`)."""
        return from_json(cls, obj)


# -- JSON Schema ----------------------------------------------------------------------------------


_ATTRIBUTE = re.compile(r"^\s{4}([A-Za-z_][\w, ]*):\s*(.*)$")
"""An ``Attributes:`` entry: ``    name: text`` or ``    a, b: text``."""


def _docs(cls: type) -> tuple[str, dict[str, str]]:
    """The first docstring paragraph and the ``Attributes:`` entries (``a, b: text`` documents
    both a and b)."""
    lines = inspect.cleandoc(cls.__doc__ or "").splitlines()
    return _summary(lines), _attributes(lines)


def _summary(lines: list[str]) -> str:
    """The first paragraph, joined into one line."""
    summary: list[str] = []
    for line in lines:
        if not line.strip():
            break
        summary.append(line.strip())
    return " ".join(summary)


def _attributes(lines: list[str]) -> dict[str, str]:
    """The entries of the ``Attributes:`` section, each joined into one line."""
    attrs: dict[str, str] = {}
    current: list[str] = []
    names: list[str] = []
    in_attrs = False
    for line in lines:
        stripped = line.strip()
        if stripped == "Attributes:":
            in_attrs = True
            continue
        if not in_attrs:
            continue
        m = _ATTRIBUTE.match(line)
        if m and not line.startswith(" " * 8):
            for n in names:
                attrs[n] = " ".join(current)
            names = [n.strip() for n in m.group(1).split(",")]
            current = [m.group(2).strip()]
        elif stripped and names:
            current.append(stripped)
    for n in names:
        attrs[n] = " ".join(current)
    return attrs


def _type_schema(tp: Any) -> dict[str, Any]:
    """The JSON Schema of one field type."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Annotated:
        return _annotated_schema(args[0], args[1:])
    inner = _optional_arg(tp)
    if inner is not None:
        return _nullable_schema(inner)
    generic = _generic_schema(tp, origin, args)
    if generic is not None:
        return generic
    return _class_schema(tp)


def _annotated_schema(tp: Any, metadata: tuple[Any, ...]) -> dict[str, Any]:
    """``tp``'s schema with the bounds of its ``Length`` and ``Range`` metadata."""
    out = _type_schema(tp)
    for meta in metadata:
        if isinstance(meta, Length):
            out["minItems"] = out["maxItems"] = meta.n
        elif isinstance(meta, Range):
            bounds = {"minimum": meta.ge, "maximum": meta.le, "exclusiveMinimum": meta.gt}
            out.update({k: v for k, v in bounds.items() if v is not None})
    return out


def _nullable_schema(inner: Any) -> dict[str, Any]:
    """The schema of ``inner | None``: ``inner``'s, with null allowed."""
    out = _type_schema(inner)
    t = out.get("type")
    out["type"] = [*t, "null"] if isinstance(t, list) else [t, "null"]
    if "enum" in out:
        out["enum"] = [*out["enum"], None]
    return out


_SCALARS = ["number", "string", "boolean", "null"]


def _generic_schema(tp: Any, origin: Any, args: tuple[Any, ...]) -> dict[str, Any] | None:
    """The schema of a scalar union, ``tuple[X, ...]``, a mapping or a ``Literal`` (None for
    other types)."""
    if origin in (types.UnionType, typing.Union):
        return {"type": list(_SCALARS)}
    if origin is tuple:
        return {"type": "array", "items": _type_schema(args[0])}
    if origin in (dict, Mapping) or tp in (dict, Mapping):
        return {
            "type": "object",
            "additionalProperties": {"type": "string" if args[1:] == (str,) else list(_SCALARS)},
        }
    if origin is typing.Literal:
        return {"type": "string", "enum": list(args)}
    return None


_SIMPLE = {int: "integer", float: "number", str: "string", bool: "boolean"}


def _class_schema(tp: Any) -> dict[str, Any]:
    """The schema of a scalar, an ``Enum``, a ``NamedTuple`` or a dataclass.

    Raises:
        TypeError: any other type.
    """
    if tp in _SIMPLE:
        return {"type": _SIMPLE[tp]}
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return {"type": "string", "enum": [m.value for m in tp]}
    if _is_named_tuple(tp):
        hints = typing.get_type_hints(tp)
        return {
            "type": "object",
            "properties": {n: _type_schema(hints[n]) for n in tp._fields},
            "required": list(tp._fields),
        }
    if dataclasses.is_dataclass(tp):
        return _object_schema(typing.cast(type, tp))
    raise TypeError(f"no JSON schema for type {tp!r}")


def _time_schema(description: str) -> dict[str, Any]:
    return {
        "type": "object",
        "description": description.rstrip(".") + TIME_SUFFIX,
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": NS_PER_S - 1},
        },
        "required": ["sec", "nsec"],
        "additionalProperties": False,
    }


def _object_schema(cls: type) -> dict[str, Any]:
    _, attrs = _docs(cls)
    hints = typing.get_type_hints(cls, include_extras=True)
    props: dict[str, Any] = {}
    required = []
    for f in dataclasses.fields(cls):
        if f.name == TIME_FIELD:
            props[TIME_KEY] = _time_schema(attrs.get(f.name, "Sample time"))
            key = TIME_KEY
        else:
            prop = _type_schema(hints[f.name])
            if f.name in attrs:
                prop["description"] = attrs[f.name]
            props[f.name] = prop
            key = f.name
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            required.append(key)
    return {"type": "object", "properties": props, "required": required}


def json_schema(cls: type) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a message class, as ``formats/`` holds it."""
    name = typing.cast(str, getattr(cls, "SCHEMA"))  # noqa: B009 - ClassVar of each message
    summary, _ = _docs(cls)
    topic = getattr(cls, "TOPIC", "")
    description = summary + (f" Topic {topic}." if topic else "")
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"https://trackctl.dev/formats/{name}.json",
        "title": name,
        "description": description,
        **_object_schema(cls),
    }


def schema_text(cls: type) -> str:
    """The schema file's exact text (2-space indent, newline at the end)."""
    return json.dumps(json_schema(cls), indent=2, ensure_ascii=False) + "\n"


def write_schemas(folder: str | Path) -> list[Path]:
    """Write ``<SCHEMA>.json`` of every message type into ``folder``; the paths written."""
    from trackctl.logs.messages import MESSAGE_TYPES

    out = []
    for cls in MESSAGE_TYPES:
        path = Path(folder) / f"{cls.SCHEMA}.json"  # type: ignore[attr-defined]
        path.write_text(schema_text(cls))
        out.append(path)
    return out
