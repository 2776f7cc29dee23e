"""ROS 2 messages (CDR) in MCAP: a decoder plug-in built from the schema the log carries.

A ROS 2 bag stored as MCAP (``ros2 bag record -s mcap``) has channels with message encoding
``cdr`` and schemas with encoding ``ros2msg`` holding the full message definition text (the type
and every type it uses, separated by ``====`` lines). :class:`Ros2CdrCodec` registers those
definitions in a private `rosbags <https://gitlab.com/ternaris/rosbags>`_ type store and
(de)serializes with it, so ``info``, ``replay`` and every reader see ROS 2 channels decoded,
without a ROS installation. Decoded messages are rosbags' dataclasses (``msg.header.stamp.sec``,
``msg.twist.twist.linear.x``...); :func:`ros_to_jsonable` turns them into JSON values.
"""

from __future__ import annotations

import base64
import dataclasses
import json
from functools import cache
from typing import Any

import numpy as np

from trackctl.errors import SchemaError, UnknownSchemaError

__all__ = ["Ros2CdrCodec", "ros2_codec", "ros_to_jsonable", "stamp_ns"]


def ros_to_jsonable(value: Any) -> Any:
    """A rosbags message (dataclass) as JSON values: byte arrays as base64, other arrays as
    lists, nested messages as objects (without rosbags' ``__msgtype__``)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {
            f.name: ros_to_jsonable(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if not f.name.startswith("__")
        }
    if isinstance(value, np.ndarray):
        if value.dtype == np.uint8:
            return base64.b64encode(value.tobytes()).decode("ascii")
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [ros_to_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def stamp_ns(stamp: Any) -> int:
    """A ``builtin_interfaces/Time`` as nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class Ros2CdrCodec:
    """One ROS 2 message type in CDR, from its ``ros2msg`` definition text."""

    schema_encoding = "ros2msg"
    message_encoding = "cdr"

    def __init__(self, schema_name: str, schema_data: bytes) -> None:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.schema_name = schema_name
        self.schema_data = schema_data
        self._type = _normalized(schema_name)
        try:
            store = get_typestore(Stores.EMPTY)
            store.register(get_types_from_msg(schema_data.decode("utf-8"), self._type))
        except Exception as err:  # rosbags raises its own parse errors and UnicodeDecodeError
            raise UnknownSchemaError(
                f"schema {schema_name!r}: the ROS 2 message definition does not parse ({err})"
            ) from err
        self._store = store

    def decode(self, data: bytes) -> Any:
        try:
            return self._store.deserialize_cdr(bytes(data), self._type)
        except Exception as err:  # truncated or foreign bytes: struct/index/assertion errors
            raise SchemaError(f"{self.schema_name}: cannot decode CDR message ({err})") from err

    def encode(self, message: Any) -> bytes:
        return bytes(self._store.serialize_cdr(message, self._type))

    def to_jsonable(self, data: bytes) -> Any:
        return ros_to_jsonable(self.decode(data))

    def from_jsonable(self, value: Any) -> bytes:
        raise SchemaError(
            f"{self.schema_name}: writing ROS 2 messages from JSON is not supported "
            f"(got {json.dumps(value)[:60]}); record ROS 2 bags with `record --ros2`"
        )


def _normalized(name: str) -> str:
    """``pkg/Type`` (ROS 1 style, some writers) as ``pkg/msg/Type``."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


@cache
def ros2_codec(schema_name: str, schema_data: bytes) -> Ros2CdrCodec:
    """The (cached) codec of one ROS 2 schema."""
    return Ros2CdrCodec(schema_name, schema_data)
