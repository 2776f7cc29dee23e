"""The JSON lines format of ``replay --format jsonl`` and ``record --stdin/--udp``.

One object per message: ``{"topic": str, "log_time_ns": int, "schema": str, "message": ...}``.
``message`` is the decoded payload: trackctl messages as their JSON schema says, Foxglove protobuf
messages in the canonical proto3 JSON mapping (snake_case names, bytes as base64). Reading a line
back re-encodes the payload with the schema's codec, so replay -> record reproduces the messages.

Two more line types carry the log's other records (``replay --records`` emits them first;
``record --stdin/--udp`` stores them), so ``replay --records | record --stdin`` keeps everything:

* ``{"type": "metadata", "name": str, "metadata": {str: str}}``
* ``{"type": "attachment", "name": str, "media_type": str, "log_time_ns": int,
  "data_base64": str}``
"""

from __future__ import annotations

import base64
import binascii
import json
import re
import time
from dataclasses import dataclass
from typing import Any

from trackctl.errors import InputError, SchemaError, UnknownSchemaError
from trackctl.logs.codecs import Codec, codec_for, known_schemas
from trackctl.logs.reader import RawMessage

__all__ = [
    "to_jsonl",
    "parse_jsonl",
    "parse_line",
    "metadata_line",
    "attachment_line",
    "JsonlRecord",
    "MetadataLine",
    "AttachmentLine",
]


class _NonFinite(ValueError):
    def __init__(self, msg: str, token: str = "") -> None:
        super().__init__(msg)
        self.token = token[:40]


def _no_constant(name: str) -> Any:
    raise _NonFinite(f"non-finite number {name}", name)


def _finite_float(text: str) -> float:
    value = float(text)
    if value in (float("inf"), float("-inf")):
        raise _NonFinite(f"number {text[:40]} overflows a 64-bit float", text)
    return value


MAX_INT_DIGITS = 40
"""Longest integer a JSON line may hold (uint64 has 20 digits): Python's own limit (4300 digits)
would raise a ValueError deep in the parser, and a long one costs quadratic time to convert."""


def _bounded_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise _NonFinite(
            f"integer of {digits} digits is out of range (at most {MAX_INT_DIGITS})", text
        )
    return int(text)


_KEY_BEFORE = re.compile(r'"([^"\\]{1,80})"\s*:\s*\[?\s*$')
_TOPIC = re.compile(r'"topic"\s*:\s*"([^"\\]{1,200})"')


def _where_in(line: str, err: _NonFinite) -> str:
    """``topic T: field F: `` for the number ``err`` names, as far as the raw line tells."""
    topic = _TOPIC.search(line[:4096])
    token = err.token
    pos = line.find(token) if token else -1
    key = _KEY_BEFORE.search(line[max(0, pos - 200) : pos]) if pos > 0 else None
    return (f"topic {topic.group(1)}: " if topic else "") + (
        f"field {key.group(1)!r}: " if key else ""
    )


# Payloads holding these are re-encoded (one line per message, strict JSON out).
_NOT_PASSTHROUGH = (b"\n", b"NaN", b"Infinity")


def to_jsonl(raw: RawMessage, codec: Codec) -> str:
    """One JSON line (without the newline) for a stored message."""
    head = (
        f'{{"topic":{json.dumps(raw.topic)},"log_time_ns":{raw.log_time_ns},'
        f'"schema":{json.dumps(raw.schema_name)},"message":'
    )
    data = raw.data
    if raw.message_encoding == "json" and not any(t in data for t in _NOT_PASSTHROUGH):
        # JSON payloads pass through as they are stored: no decode/encode on the hot path.
        return head + data.decode("utf-8") + "}"
    payload = codec.to_jsonable(raw.data)
    # allow_nan=False: a foreign log's NaN must not produce a line that is not JSON
    return head + json.dumps(payload, separators=(",", ":"), allow_nan=False) + "}"


@dataclass(frozen=True, slots=True)
class JsonlRecord:
    """A parsed JSON line, encoded and ready to write."""

    topic: str
    log_time_ns: int
    codec: Codec
    data: bytes


def parse_jsonl(
    line: str | bytes,
    where: str = "<stdin>",
    lineno: int = 0,
    now_ns: int | None = None,
    *,
    records: bool = False,
) -> Any:
    """Parse and encode one JSON line; ``log_time_ns`` defaults to the arrival time.

    Args:
        records: also accept ``metadata`` and ``attachment`` lines (see :func:`parse_line`).

    Raises:
        InputError: the line is not a JSON object with ``topic``, ``schema`` and ``message``.
        UnknownSchemaError: no codec for ``schema``.
        SchemaError: ``message`` does not fit the schema.
    """
    at = f"{where}:{lineno}" if lineno else where
    obj = _json_object(line, at)
    kind = obj.get("type", "message")
    if kind in ("metadata", "attachment") and records:
        return _parse_record_line(obj, at)
    if kind != "message":
        raise InputError(f"{at}: unknown line type {kind!r} (message, metadata or attachment)")
    return _message_line(obj, at, now_ns)


def _json_object(line: str | bytes, at: str) -> dict[str, Any]:
    """Strict JSON (UTF-8, no NaN or infinity) holding an object."""
    if isinstance(line, bytes):
        try:
            line = line.decode("utf-8")
        except UnicodeDecodeError as err:
            raise InputError(
                f"{at}: not UTF-8 text (byte 0x{line[err.start]:02x} at column {err.start + 1})"
            ) from None
    try:
        obj: Any = json.loads(
            line, parse_constant=_no_constant, parse_float=_finite_float, parse_int=_bounded_int
        )
    except json.JSONDecodeError as err:
        raise InputError(f"{at}: not valid JSON ({err.msg} at column {err.colno})") from err
    except _NonFinite as err:
        hint = "" if "integer" in str(err) else " (JSON has no NaN or infinity)"
        raise InputError(f"{at}: {_where_in(line, err)}{err}{hint}") from None
    except RecursionError:
        raise InputError(f"{at}: JSON nested too deeply") from None
    except ValueError as err:  # any other number the parser cannot convert
        raise InputError(f"{at}: not valid JSON ({str(err)[:120]})") from None
    if not isinstance(obj, dict):
        raise InputError(f"{at}: expected a JSON object, got {type(obj).__name__}")
    return obj


def _message_line(obj: dict[str, Any], at: str, now_ns: int | None) -> JsonlRecord:
    for key in ("topic", "schema", "message"):
        if key not in obj:
            raise InputError(f"{at}: field {key!r} is missing (need topic, schema, message)")
    topic, schema = obj["topic"], obj["schema"]
    if not isinstance(topic, str) or not topic:
        raise InputError(f"{at}: field 'topic' must be a non-empty string")
    t = obj.get("log_time_ns")
    if t is None:
        t = time.time_ns() if now_ns is None else now_ns
    elif isinstance(t, bool) or not isinstance(t, int) or not 0 <= t < 1 << 64:
        raise InputError(
            f"{at}: topic {topic}: field 'log_time_ns' must be an integer in 0..2^64-1 (got {t!r})"
        )
    codec = _codec(str(schema), at, topic)
    try:
        data = codec.from_jsonable(obj["message"])
    except SchemaError as err:
        raise SchemaError(f"{at}: topic {topic}: {err}") from err
    except (TypeError, ValueError, KeyError, AttributeError, OverflowError) as err:
        # a payload of the right JSON shape but wrong types deep inside (e.g. a list for a number)
        raise SchemaError(f"{at}: topic {topic}: message does not fit {schema}: {err}") from err
    return JsonlRecord(topic, int(t), codec, data)


def _codec(schema: str, at: str, topic: str) -> Codec:
    encoding = "protobuf" if schema.startswith("foxglove.") else "json"
    try:
        codec = codec_for(schema, encoding)
    except UnknownSchemaError as err:
        raise UnknownSchemaError(f"{at}: topic {topic}: {err}") from err
    if not codec.schema_data and schema not in known_schemas():
        raise UnknownSchemaError(
            f"{at}: topic {topic}: unknown schema {schema!r} (known: {', '.join(known_schemas())})"
        )
    return codec


@dataclass(frozen=True, slots=True)
class MetadataLine:
    """A parsed metadata line."""

    name: str
    metadata: dict[str, str]


@dataclass(frozen=True, slots=True)
class AttachmentLine:
    """A parsed attachment line."""

    name: str
    media_type: str
    log_time_ns: int
    data: bytes


def metadata_line(name: str, metadata: dict[str, str]) -> str:
    """The JSON line of one metadata record."""
    return json.dumps(
        {"type": "metadata", "name": name, "metadata": metadata}, separators=(",", ":")
    )


def attachment_line(name: str, media_type: str, data: bytes, log_time_ns: int = 0) -> str:
    """The JSON line of one attachment (data as base64)."""
    obj = {
        "type": "attachment",
        "name": name,
        "media_type": media_type,
        "log_time_ns": log_time_ns,
        "data_base64": base64.b64encode(data).decode("ascii"),
    }
    return json.dumps(obj, separators=(",", ":"))


def _parse_record_line(obj: dict[str, Any], at: str) -> MetadataLine | AttachmentLine:
    kind, name = obj.get("type"), obj.get("name")
    if not isinstance(name, str) or not name:
        raise InputError(f"{at}: {kind} line: field 'name' must be a non-empty string")
    if kind == "metadata":
        md = obj.get("metadata")
        if not isinstance(md, dict) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in md.items()
        ):
            raise InputError(f"{at}: metadata {name}: field 'metadata' must map strings to strings")
        return MetadataLine(name, dict(md))
    t = obj.get("log_time_ns", 0)
    if isinstance(t, bool) or not isinstance(t, int) or not 0 <= t < 1 << 64:
        raise InputError(f"{at}: attachment {name}: field 'log_time_ns' must be in 0..2^64-1")
    media_type = obj.get("media_type", "application/octet-stream")
    if not isinstance(media_type, str):
        raise InputError(f"{at}: attachment {name}: field 'media_type' must be a string")
    try:
        data = base64.b64decode(str(obj.get("data_base64", "")), validate=True)
    except (binascii.Error, ValueError):
        raise InputError(f"{at}: attachment {name}: field 'data_base64' is not base64") from None
    return AttachmentLine(name, media_type, t, data)


def parse_line(
    line: str | bytes, where: str = "<stdin>", lineno: int = 0, now_ns: int | None = None
) -> JsonlRecord | MetadataLine | AttachmentLine:
    """Parse any JSON line: a message, or a ``metadata``/``attachment`` record line.

    Raises:
        InputError, SchemaError: as :func:`parse_jsonl`, or a malformed record line.
    """
    parsed: JsonlRecord | MetadataLine | AttachmentLine = parse_jsonl(
        line, where, lineno, now_ns, records=True
    )
    return parsed
