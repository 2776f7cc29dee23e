"""``trackctl info``: what a log holds."""

from __future__ import annotations

from typing import Any

from trackctl.logs.reader import LogReader

__all__ = ["log_info"]


def log_info(reader: LogReader) -> dict[str, Any]:
    """The ``info --json`` object: topics (schema, encoding, count, rate), span, metadata, warnings.

    Calling it may add warnings to ``reader.warnings`` (a truncated log is scanned to the end).
    """
    topics = reader.topics()
    metadata = reader.metadata()
    attachments = reader.attachment_sizes()
    start, end = reader.start_ns, reader.end_ns
    return {
        "path": str(reader.path),
        "topics": {
            t.topic: {
                "schema": t.schema_name,
                "encoding": t.message_encoding,
                "count": t.count,
                "rate_hz": round(t.rate_hz, 6),
                "first_ns": t.first_ns,
                "last_ns": t.last_ns,
            }
            for t in sorted(topics.values(), key=lambda t: t.topic)
        },
        "message_count": sum(t.count for t in topics.values()),
        "start_ns": start if start is not None else 0,
        "end_ns": end if end is not None else 0,
        "duration_s": 0.0 if start is None or end is None else (end - start) / 1e9,
        "metadata": metadata,
        "attachments": {
            name: {"media_type": mt, "bytes": size} for name, (mt, size) in attachments.items()
        },
        "truncated": reader.truncated,
        "warnings": list(reader.warnings),
    }
