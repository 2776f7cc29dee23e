"""Message codecs, looked up by (message encoding, schema name) like mcap's ``DecoderFactory``.

Two families are registered:

* ``json`` + ``jsonschema``: trackctl's own messages (:mod:`trackctl.logs.messages`), schema text
  from ``formats/``;
* ``protobuf``: Foxglove's well-known schemas (``foxglove.CompressedImage``...), classes from
  ``foxglove-schemas-protobuf`` so Foxglove and Lichtblick render them unchanged.

Channels of foreign logs with a schema no codec knows still decode: protobuf ones through the
descriptor set the log carries (mcap-protobuf-support), ROS 2 CDR ones through the message
definition it carries (:mod:`trackctl.logs.ros2`), JSON ones as plain dicts.

Adding a message type touches one schema file and one :func:`register` call.
"""

from __future__ import annotations

import base64
import importlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, Protocol

from google.protobuf import json_format
from google.protobuf.message import DecodeError
from google.protobuf.message import Message as ProtoMessage
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from mcap_protobuf.schema import build_file_descriptor_set

from trackctl.errors import SchemaError, UnknownSchemaError
from trackctl.logs import messages as m

__all__ = [
    "Codec",
    "JsonMessageCodec",
    "ProtobufCodec",
    "PlainJsonCodec",
    "DynamicProtobufCodec",
    "register",
    "codec_for",
    "codec_for_type",
    "known_schemas",
    "formats_dir",
    "FOXGLOVE_SCHEMAS",
]


class Codec(Protocol):
    """Encodes and decodes one schema's messages.

    ``to_jsonable``/``from_jsonable`` convert between encoded bytes and the JSON value used by
    ``replay --format jsonl`` and ``record --stdin`` (bytes fields as base64).
    """

    # read-only members: frozen dataclasses and plain classes both satisfy them
    @property
    def schema_name(self) -> str: ...

    @property
    def schema_encoding(self) -> str: ...

    @property
    def message_encoding(self) -> str: ...

    @property
    def schema_data(self) -> bytes: ...

    def encode(self, message: Any) -> bytes: ...

    def decode(self, data: bytes) -> Any: ...

    def to_jsonable(self, data: bytes) -> Any: ...

    def from_jsonable(self, value: Any) -> bytes: ...


def formats_dir() -> Path:
    """Folder holding the JSON schemas: the wheel's copy, else the source tree's ``formats/``."""
    here = Path(__file__).resolve().parent.parent
    for candidate in (here / "_formats", here.parent / "formats"):
        if candidate.is_dir():
            return candidate
    raise SchemaError(
        f"JSON schema folder not found (looked for {here / '_formats'} and "
        f"{here.parent / 'formats'}); reinstall trackctl"
    )


def _json_dumps(obj: Any) -> bytes:
    # allow_nan=False: NaN/inf are not JSON and break other readers; sensor values are checked
    # before they get here, so hitting this is a bug worth a loud error.
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


@dataclass(frozen=True)
class JsonMessageCodec:
    """JSON codec of one trackctl dataclass message (``to_json``/``from_json``)."""

    message_type: type
    schema_name: str
    schema_data: bytes
    schema_encoding: str = "jsonschema"
    message_encoding: str = "json"

    def encode(self, message: Any) -> bytes:
        return _json_dumps(message.to_json())

    def decode(self, data: bytes) -> Any:
        try:
            return self.message_type.from_json(json.loads(data))  # type: ignore[attr-defined]
        except (ValueError, KeyError, TypeError) as err:
            raise SchemaError(f"{self.schema_name}: cannot decode message: {err}") from err

    def to_jsonable(self, data: bytes) -> Any:
        return json.loads(data)

    def from_jsonable(self, value: Any) -> bytes:
        # Round-trip through the dataclass so a malformed payload fails here, naming the field.
        try:
            message = self.message_type.from_json(value)  # type: ignore[attr-defined]
        except KeyError as err:
            raise SchemaError(f"{self.schema_name}: missing field {err}") from err
        except (ValueError, TypeError, AttributeError) as err:
            raise SchemaError(f"{self.schema_name}: {err}") from err
        return self.encode(message)


@dataclass(frozen=True)
class PlainJsonCodec:
    """JSON channels whose schema trackctl does not know: decoded as plain dicts."""

    schema_name: str
    schema_data: bytes = b""
    schema_encoding: str = "jsonschema"
    message_encoding: str = "json"

    def encode(self, message: Any) -> bytes:
        return _json_dumps(message)

    def decode(self, data: bytes) -> Any:
        return json.loads(data)

    def to_jsonable(self, data: bytes) -> Any:
        return json.loads(data)

    def from_jsonable(self, value: Any) -> bytes:
        return _json_dumps(value)


class ProtobufCodec:
    """Protobuf codec of one generated message class (Foxglove well-known schemas)."""

    schema_encoding = "protobuf"
    message_encoding = "protobuf"

    def __init__(self, message_class: type[ProtoMessage]) -> None:
        self.message_class = message_class
        self.schema_name: str = message_class.DESCRIPTOR.full_name
        self.schema_data: bytes = build_file_descriptor_set(message_class).SerializeToString()

    def encode(self, message: Any) -> bytes:
        if not isinstance(message, self.message_class):
            raise SchemaError(
                f"{self.schema_name}: expected a {self.message_class.__name__}, "
                f"got {type(message).__name__}"
            )
        return bytes(message.SerializeToString())

    def decode(self, data: bytes) -> Any:
        msg = self.message_class()
        try:
            msg.ParseFromString(data)
        except DecodeError as err:
            raise SchemaError(f"{self.schema_name}: cannot decode message: {err}") from err
        return msg

    def to_jsonable(self, data: bytes) -> Any:
        return _proto_to_jsonable(self.decode(data))

    def from_jsonable(self, value: Any) -> bytes:
        msg = self.message_class()
        try:
            json_format.ParseDict(value, msg)
        except json_format.ParseError as err:
            raise SchemaError(f"{self.schema_name}: {err}") from err
        return bytes(msg.SerializeToString())


def _proto_to_jsonable(msg: ProtoMessage) -> Any:
    # Field names as in the .proto (snake_case, as Foxglove's JSON schemas spell them); bytes
    # become base64, int64 strings, Timestamps RFC 3339: the canonical proto3 JSON mapping, which
    # ParseDict reads back losslessly.
    return json_format.MessageToDict(
        msg, preserving_proto_field_name=True, always_print_fields_with_no_presence=False
    )


class DynamicProtobufCodec:
    """Protobuf channels of foreign logs: classes built from the descriptor set in the log."""

    schema_encoding = "protobuf"
    message_encoding = "protobuf"

    def __init__(self, schema: Schema) -> None:
        self.schema_name = schema.name
        self.schema_data = schema.data
        decoder = ProtobufDecoderFactory().decoder_for("protobuf", schema)
        if decoder is None:
            raise UnknownSchemaError(f"{schema.name}: not a protobuf schema")
        self._decoder: Callable[[bytes], Any] = decoder
        self._message_class = type(self._decoder(b""))

    def encode(self, message: Any) -> bytes:
        return bytes(message.SerializeToString())

    def decode(self, data: bytes) -> Any:
        return self._decoder(data)

    def to_jsonable(self, data: bytes) -> Any:
        return _proto_to_jsonable(self.decode(data))

    def from_jsonable(self, value: Any) -> bytes:
        msg = self._message_class()
        json_format.ParseDict(value, msg)
        return bytes(msg.SerializeToString())


_REGISTRY: dict[tuple[str, str], Codec] = {}
_BY_TYPE: dict[type, Codec] = {}

FOXGLOVE_SCHEMAS: tuple[str, ...] = (
    "CompressedImage",
    "RawImage",
    "CameraCalibration",
    "FrameTransform",
    "FrameTransforms",
    "PoseInFrame",
    "PosesInFrame",
    "SceneUpdate",
    "ImageAnnotations",
    "LocationFix",
    "Log",
)


def register(codec: Codec, message_type: type | None = None) -> None:
    """Make ``codec`` the one used for its (message encoding, schema name)."""
    _REGISTRY[(codec.message_encoding, codec.schema_name)] = codec
    if message_type is not None:
        _BY_TYPE[message_type] = codec


@cache
def _dynamic_codec(message_encoding: str, schema_name: str, schema_data: bytes) -> Codec:
    schema = Schema(id=1, name=schema_name, encoding="protobuf", data=schema_data)
    try:
        return DynamicProtobufCodec(schema)
    except Exception as err:  # malformed descriptor sets come in many exception types
        raise UnknownSchemaError(
            f"schema {schema_name!r}: cannot build a protobuf decoder from the log ({err})"
        ) from err


def codec_for(
    schema_name: str,
    message_encoding: str,
    schema_encoding: str | None = None,
    schema_data: bytes | None = None,
) -> Codec:
    """The codec for a channel; falls back to the schema the log carries for foreign types.

    Raises:
        UnknownSchemaError: neither a registered codec nor the log's schema can decode it.
    """
    codec = _REGISTRY.get((message_encoding, schema_name))
    if codec is not None:
        return codec
    if message_encoding == "json":
        return PlainJsonCodec(schema_name, schema_data or b"", schema_encoding or "jsonschema")
    if message_encoding == "protobuf" and schema_data:
        return _dynamic_codec(message_encoding, schema_name, schema_data)
    if message_encoding == "cdr" and schema_encoding in (None, "ros2msg") and schema_data:
        from trackctl.logs.ros2 import ros2_codec  # rosbags loads only for ROS 2 logs

        return ros2_codec(schema_name, schema_data)
    known = ", ".join(sorted(name for _, name in _REGISTRY))
    raise UnknownSchemaError(
        f"unknown schema {schema_name!r} with encoding {message_encoding!r} (known: {known})"
    )


def codec_for_type(message_type: type) -> Codec:
    """The codec of a message class (trackctl dataclass or Foxglove protobuf class)."""
    codec = _BY_TYPE.get(message_type)
    if codec is None:
        raise UnknownSchemaError(f"no codec registered for type {message_type.__name__}")
    return codec


def known_schemas() -> list[str]:
    """Names of every schema with a registered codec."""
    return sorted(name for _, name in _REGISTRY)


def _register_builtin() -> None:
    folder = formats_dir()
    for message_type in m.MESSAGE_TYPES:
        name = message_type.SCHEMA  # type: ignore[attr-defined]
        path = folder / f"{name}.json"
        try:
            data = path.read_bytes()
        except OSError as err:
            raise SchemaError(f"{path}: schema file missing for {name}") from err
        register(JsonMessageCodec(message_type, name, data), message_type)
    for short in FOXGLOVE_SCHEMAS:
        module = importlib.import_module(f"foxglove_schemas_protobuf.{short}_pb2")
        cls = getattr(module, short)
        register(ProtobufCodec(cls), cls)


def b64(data: bytes) -> str:
    """Base64 text of bytes (the JSON lines convention for binary payloads)."""
    return base64.b64encode(data).decode("ascii")


_register_builtin()
