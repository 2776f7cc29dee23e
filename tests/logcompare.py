"""Compare two MCAP logs by their decoded content, with a float tolerance.

Simulators are deterministic for one set of library versions, but a newer numpy, pandas or OpenCV
may change the last digit of a float or the bytes of a JPEG. A sample log is stale when its
*content* differs from a fresh run, not when a float's last bit does: this module says which.
"""

from __future__ import annotations

import base64
import math
from itertools import zip_longest
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from trackctl.logs.reader import LogReader, RawMessage

__all__ = ["assert_same_log", "diff_logs"]

REL_TOL = 1e-6
ABS_TOL = 1e-9
# JPEG bytes change with the libjpeg in OpenCV's wheel; the decoded pixels barely move.
IMAGE_MEAN_TOL = 1.0
IMAGE_MAX_TOL = 48


def _close(a: Any, b: Any, path: str) -> str | None:
    if isinstance(a, bool) or isinstance(b, bool):
        return None if a == b else f"{path}: {a!r} != {b!r}"
    if isinstance(a, int | float) and isinstance(b, int | float):
        if isinstance(a, int) and isinstance(b, int) and abs(a) > 2**53:
            return None if a == b else f"{path}: {a} != {b}"
        if math.isclose(float(a), float(b), rel_tol=REL_TOL, abs_tol=ABS_TOL):
            return None
        return f"{path}: {a!r} != {b!r}"
    if isinstance(a, dict) and isinstance(b, dict):
        if a.keys() != b.keys():
            return f"{path}: keys {sorted(a)} != {sorted(b)}"
        for key in a:
            found = _close(a[key], b[key], f"{path}.{key}")
            if found:
                return found
        return None
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{path}: {len(a)} items != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            found = _close(x, y, f"{path}[{i}]")
            if found:
                return found
        return None
    if isinstance(a, str) and isinstance(b, str) and a != b:
        # proto3 JSON writes int64 as strings
        try:
            return _close(int(a), int(b), path)
        except ValueError:
            pass
    return None if a == b else f"{path}: {a!r} != {b!r}"


def _image_close(a: dict[str, Any], b: dict[str, Any], path: str) -> str | None:
    pa = cv2.imdecode(np.frombuffer(base64.b64decode(a.pop("data", "")), np.uint8), -1)
    pb = cv2.imdecode(np.frombuffer(base64.b64decode(b.pop("data", "")), np.uint8), -1)
    if pa is None or pb is None or pa.shape != pb.shape:
        return f"{path}.data: images differ in shape or do not decode"
    diff = np.abs(pa.astype(np.int16) - pb.astype(np.int16))
    if diff.mean() > IMAGE_MEAN_TOL or diff.max() > IMAGE_MAX_TOL:
        return f"{path}.data: pixels differ (mean {diff.mean():.2f}, max {diff.max()})"
    return _close(a, b, path)


def _message_diff(reader: LogReader, a: RawMessage, b: RawMessage, where: str) -> str | None:
    if (a.topic, a.schema_name, a.message_encoding) != (b.topic, b.schema_name, b.message_encoding):
        return f"{where}: {a.topic} ({a.schema_name}) != {b.topic} ({b.schema_name})"
    if abs(a.log_time_ns - b.log_time_ns) > 1:
        return f"{where} {a.topic}: log time {a.log_time_ns} != {b.log_time_ns}"
    if a.data == b.data:
        return None
    codec = reader.codec(a)
    ja, jb = codec.to_jsonable(a.data), codec.to_jsonable(b.data)
    if a.schema_name == "foxglove.CompressedImage":
        return _image_close(ja, jb, f"{where} {a.topic}")
    return _close(ja, jb, f"{where} {a.topic}")


def diff_logs(fresh: Path, shipped: Path) -> str | None:
    """The first content difference between two logs, or None when they hold the same content.

    Same topics, schemas and messages in the same order; floats equal within ``REL_TOL``; images
    equal after decoding within a few grey levels; metadata and attachments equal.
    """
    ra, rb = LogReader(fresh), LogReader(shipped)
    if ra.metadata() != rb.metadata():
        return "metadata differ"
    if ra.attachments() != rb.attachments():
        return "attachments differ"
    for i, (a, b) in enumerate(zip_longest(ra.raw(), rb.raw())):
        if a is None or b is None:
            return f"message {i}: one log ends early"
        found = _message_diff(ra, a, b, f"message {i}")
        if found:
            return found
    return None


def assert_same_log(fresh: Path, shipped: Path) -> None:
    """Fail with the first difference (and the regeneration command) when the logs differ."""
    found = diff_logs(fresh, shipped)
    assert found is None, f"{shipped} is stale ({found}): regenerate with `make sample-logs`"
