"""Flat CSV export of any topic (pandas writes it).

Columns come from the message's type, so every row of a topic has the same header: the first
column is ``log_time_ns``, then the message's fields, nested ones dotted (``position_m.x``,
``pose.orientation.w``); lists of numbers or strings and mappings are one cell holding JSON, bytes
one cell holding their length. A message holding a list of records (``Tracks.tracks``,
``GroundTruth.entities``, ``Detections.detections``, ``foxglove.PosesInFrame.poses``) is one row
per element, the message's own fields (``t_ns``) repeated; such a message with an empty list
writes no row. trackctl's messages (dataclasses), Foxglove's (protobuf) and schema-less JSON
(dicts) are flattened.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import IO, Any

import pandas as pd
from google.protobuf.descriptor import Descriptor, FieldDescriptor
from google.protobuf.json_format import MessageToDict
from google.protobuf.message import Message as ProtoMessage

from trackctl.errors import SchemaError
from trackctl.logs.reader import LogMessage
from trackctl.progress import Progress

__all__ = ["Flattener", "flattener_for", "write_csv", "ROWS_PER_CHUNK"]

ROWS_PER_CHUNK = 5000
"""Rows handed to pandas at a time (the export streams: memory is one chunk)."""

Getter = Callable[[Any], Any]
Column = tuple[str, Getter]
MAX_DEPTH = 6


def _plain(value: Any) -> Any:
    """A value as JSON-able plain data (NamedTuples as lists, enums as their values)."""
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, ProtoMessage):
        return MessageToDict(value, preserving_proto_field_name=True)
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    return value


def _cell(value: Any) -> Any:
    """One CSV cell: scalars as they are, bytes as their length, containers as JSON."""
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, (bytes, bytearray, memoryview)):
        return len(value)
    if isinstance(value, (list, tuple, Mapping, ProtoMessage)) or (
        dataclasses.is_dataclass(value) and not isinstance(value, type)
    ):
        return json.dumps(_plain(value), separators=(",", ":"))
    return value


def _field(name: str, inner: Getter) -> Getter:
    def get(obj: Any) -> Any:
        return None if obj is None else inner(getattr(obj, name))

    return get


def _leaf(name: str) -> list[Column]:
    return [(name, _cell)]


# -- trackctl's dataclasses ------------------------------------------------------------------


def _strip_optional(tp: Any) -> Any:
    """``X | None`` -> ``X`` (other unions stay as they are: one cell)."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return args[0] if len(args) == 1 else tp
    return tp


def _record_fields(tp: Any) -> list[tuple[str, Any]] | None:
    """``(name, type)`` of a dataclass's or NamedTuple's fields; None for other types."""
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        hints = typing.get_type_hints(tp)
        return [(f.name, hints[f.name]) for f in dataclasses.fields(tp)]
    if isinstance(tp, type) and issubclass(tp, tuple) and hasattr(tp, "_fields"):
        hints = typing.get_type_hints(tp)
        return [(n, hints.get(n, Any)) for n in tp._fields]
    return None


def _typed_columns(tp: Any, prefix: str, depth: int = 0) -> list[Column]:
    tp = _strip_optional(tp)
    fields = _record_fields(tp) if depth < MAX_DEPTH else None
    if fields is None:
        return _leaf(prefix)
    cols: list[Column] = []
    for name, hint in fields:
        for sub, get in _typed_columns(hint, f"{prefix}.{name}" if prefix else name, depth + 1):
            cols.append((sub, _field(name, get)))
    return cols


def _record_list(hint: Any) -> Any | None:
    """The element type of ``tuple[Record, ...]`` (a list of records), else None."""
    hint = _strip_optional(hint)
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis and _record_fields(args[0]) is not None:
            return args[0]
    return None


# -- protobuf (Foxglove's schemas) -------------------------------------------------------------

_TIME_TYPES = ("google.protobuf.Timestamp", "google.protobuf.Duration")


def _repeated(fd: FieldDescriptor) -> bool:
    flag = getattr(fd, "is_repeated", None)
    return bool(flag) if flag is not None else fd.label == FieldDescriptor.LABEL_REPEATED


def _proto_ns(value: Any) -> int:
    return int(value.seconds) * 1_000_000_000 + int(value.nanos)


def _proto_field(name: str, inner: Getter, has_presence: bool) -> Getter:
    def get(obj: Any) -> Any:
        if obj is None or (has_presence and not obj.HasField(name)):
            return None
        return inner(getattr(obj, name))

    return get


def _proto_columns(desc: Descriptor, prefix: str, depth: int = 0) -> list[Column]:
    cols: list[Column] = []
    for fd in desc.fields:
        name = f"{prefix}.{fd.name}" if prefix else fd.name
        sub: list[Column]
        if fd.message_type is not None and not _repeated(fd):
            if fd.message_type.full_name in _TIME_TYPES:
                sub = [(name, _proto_ns)]
            elif depth < MAX_DEPTH:
                sub = _proto_columns(fd.message_type, name, depth + 1)
            else:
                sub = _leaf(name)
            cols += [(n, _proto_field(fd.name, g, True)) for n, g in sub]
        else:
            cols.append((name, _proto_field(fd.name, _cell, False)))
    return cols


# -- schema-less JSON (dicts) -----------------------------------------------------------------


def _key(name: str, inner: Getter) -> Getter:
    def get(obj: Any) -> Any:
        return inner(obj.get(name)) if isinstance(obj, Mapping) else None

    return get


def _dict_columns(sample: Mapping[str, Any], prefix: str, depth: int = 0) -> list[Column]:
    cols: list[Column] = []
    for key, value in sample.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, Mapping) and value and depth < MAX_DEPTH:
            cols += [(n, _key(key, g)) for n, g in _dict_columns(value, name, depth + 1)]
        else:
            cols.append((name, _key(key, _cell)))
    return cols


# -- rows -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Flattener:
    """How one message type becomes rows: the message's columns and, for a message holding a
    list of records, the list's field and its elements' columns."""

    columns: tuple[str, ...]
    own: tuple[Getter, ...]
    rows_of: str | None = None
    element: tuple[Getter, ...] = ()

    def rows(self, log_time_ns: int, message: Any) -> Iterable[list[Any]]:
        """The rows of one message (``log_time_ns`` first)."""
        base = [log_time_ns, *(g(message) for g in self.own)]
        if self.rows_of is None:
            yield base
            return
        items = (
            message.get(self.rows_of, ())
            if isinstance(message, Mapping)
            else getattr(message, self.rows_of)
        )
        for item in items:
            yield [*base, *(g(item) for g in self.element)]


def _build(own: list[Column], rows_of: str | None, element: list[Column]) -> Flattener:
    taken = {"log_time_ns", *(n for n, _ in own)}
    elem_names = [n if n not in taken else f"{rows_of}.{n}" for n, _ in element]
    return Flattener(
        columns=("log_time_ns", *(n for n, _ in own), *elem_names),
        own=tuple(g for _, g in own),
        rows_of=rows_of,
        element=tuple(g for _, g in element),
    )


def _typed_flattener(cls: type) -> Flattener:
    fields = _record_fields(cls) or []
    rows_of = next((n for n, h in fields if _record_list(h) is not None), None)
    own: list[Column] = []
    element: list[Column] = []
    for name, hint in fields:
        if name == rows_of:
            element = _typed_columns(_record_list(hint), "")
            continue
        own += [(n, _field(name, g)) for n, g in _typed_columns(hint, name)]
    return _build(own, rows_of, element)


def _proto_flattener(message: ProtoMessage) -> Flattener:
    desc = message.DESCRIPTOR
    lists = [fd for fd in desc.fields if fd.message_type is not None and _repeated(fd)]
    # the list of records the first message fills (SceneUpdate: entities, not its deletions)
    rows_fd = next((fd for fd in lists if len(getattr(message, fd.name))), None)
    if rows_fd is None and lists:
        rows_fd = lists[0]
    skip = None if rows_fd is None else rows_fd.name
    own = [(n, g) for n, g in _proto_columns(desc, "") if n != skip]
    element = [] if rows_fd is None else _proto_columns(rows_fd.message_type, "")
    return _build(own, None if rows_fd is None else rows_fd.name, element)


def _dict_flattener(sample: Mapping[str, Any]) -> Flattener:
    rows_of = next(
        (
            k
            for k, v in sample.items()
            if isinstance(v, list) and v and all(isinstance(x, Mapping) for x in v)
        ),
        None,
    )
    own = _dict_columns({k: v for k, v in sample.items() if k != rows_of}, "")
    element = [] if rows_of is None else _dict_columns(sample[rows_of][0], "")
    return _build(own, rows_of, element)


def flattener_for(message: Any, topic: str, schema: str) -> Flattener:
    """The flattener of a message's type (columns from the type; for schema-less JSON, from
    this first message).

    Raises:
        SchemaError: the message is none of a dataclass, a protobuf message or a JSON object.
    """
    if dataclasses.is_dataclass(message) and not isinstance(message, type):
        return _typed_flattener(type(message))
    if isinstance(message, ProtoMessage):
        return _proto_flattener(message)
    if isinstance(message, Mapping):
        return _dict_flattener(message)
    raise SchemaError(
        f"{topic}: {schema or 'schema-less'} messages decode to {type(message).__name__}, "
        "which has no columns to export as csv"
    )


def write_csv(
    messages: Iterable[LogMessage],
    out: IO[str],
    progress: Progress | None = None,
    total: int | None = None,
) -> tuple[int, int]:
    """Write ``messages`` (one topic, log-time order) as CSV to ``out``, a chunk of
    :data:`ROWS_PER_CHUNK` rows at a time.

    Returns:
        ``(messages, rows)`` read and written.
    """
    flat: Flattener | None = None
    chunk: list[list[Any]] = []
    count = rows = 0
    for msg in messages:
        if flat is None:
            flat = flattener_for(msg.message, msg.topic, msg.schema_name)
        count += 1
        chunk.extend(flat.rows(msg.log_time_ns, msg.message))
        if len(chunk) >= ROWS_PER_CHUNK:
            rows += _write_chunk(out, flat.columns, chunk, header=rows == 0)
            chunk = []
        if progress is not None:
            progress(count, total, "exporting")
    columns = flat.columns if flat is not None else ("log_time_ns",)
    if chunk or rows == 0:
        rows += _write_chunk(out, columns, chunk, header=rows == 0)
    return count, rows


def _write_chunk(
    out: IO[str], columns: tuple[str, ...], chunk: list[list[Any]], header: bool
) -> int:
    frame = pd.DataFrame(chunk, columns=list(columns), dtype=object)
    frame.to_csv(out, header=header, index=False, lineterminator="\n")
    return len(chunk)
