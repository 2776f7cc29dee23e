"""``export``: one topic of a log to a file in another tool's format."""

from __future__ import annotations

import os
from pathlib import Path

from trackctl.errors import MissingTopicError, SchemaError
from trackctl.export import csv as csv_format
from trackctl.export import mot, tum
from trackctl.export.config import ExportConfig, ExportFormat, ExportResult
from trackctl.export.output import atomic_outputs, check_not_input
from trackctl.logs.reader import LogReader
from trackctl.progress import Progress

__all__ = ["export", "exportable_topics", "ids_path", "FORMAT_SCHEMAS"]

FORMAT_SCHEMAS: dict[ExportFormat, tuple[str, ...] | None] = {
    ExportFormat.MOT: mot.SCHEMAS,
    ExportFormat.TUM: tum.SCHEMAS,
    ExportFormat.CSV: None,
}
"""The schemas each format takes (None: any)."""


def ids_path(out: str | os.PathLike[str]) -> Path:
    """Where a MOT export's id mapping goes: ``FILE.ids.csv`` beside ``FILE``."""
    out = Path(out)
    return out.with_name(out.name + ".ids.csv")


def exportable_topics(reader: LogReader, fmt: ExportFormat) -> list[str]:
    """The log's topics that ``fmt`` can take, sorted."""
    schemas = FORMAT_SCHEMAS[fmt]
    return sorted(
        topic
        for topic, info in reader.topics().items()
        if schemas is None or info.schema_name in schemas
    )


def _check_topic(reader: LogReader, config: ExportConfig) -> int:
    """The topic's message count, after checking the log has it and the format takes it.

    Raises:
        MissingTopicError: the log has no such topic (the message lists what it can export).
        SchemaError: the format cannot take the topic's schema.
    """
    present = reader.topics()
    info = present.get(config.topic)
    fmt = config.format
    if info is None:
        can = exportable_topics(reader, fmt)
        raise MissingTopicError(
            f"{reader.path}: no topic {config.topic}; topics it can export as {fmt}: "
            + (", ".join(can) or "none")
        )
    schemas = FORMAT_SCHEMAS[fmt]
    if schemas is not None and info.schema_name not in schemas:
        raise SchemaError(
            f"{reader.path}: {config.topic} holds {info.schema_name or 'schema-less messages'}; "
            f"{fmt} export takes {' or '.join(schemas)}"
        )
    return info.count


def export(
    log: str | os.PathLike[str],
    out: str | os.PathLike[str],
    config: ExportConfig,
    progress: Progress | None = None,
) -> ExportResult:
    """Export ``config.topic`` of ``log`` to ``out`` in ``config.format``.

    The topic is streamed in log-time order (a damaged log is read as far as it is sound, with
    a warning); ``out`` (and a MOT export's ``out.ids.csv``) is written through a temporary file
    beside it and renamed when complete, so an error leaves no partial output.

    Raises:
        LogError: the log cannot be read.
        MissingTopicError: no such topic.
        SchemaError: the format cannot take the topic's schema.
        InputError: an option does not fit the log (no such camera, robot).
        OutputError: ``out`` is the input, or cannot be written.
    """
    reader = LogReader(log)
    target = check_not_input(out, log)
    total = _check_topic(reader, config)
    messages = reader.messages([config.topic])
    if config.format is ExportFormat.MOT:
        extra = check_not_input(ids_path(target), log)
        boxes = (
            None
            if config.camera is None
            else mot.PersonBoxes(mot.load_camera(reader, config.camera), config.person_height_m)
        )
        with atomic_outputs([target, extra]) as (f, ids_f):
            count, rows = mot.write_mot(messages, f, ids_f, boxes, progress, total)
        return ExportResult(target, count, rows, (extra,))
    if config.format is ExportFormat.TUM:
        robot = config.robot
        if reader.topics()[config.topic].schema_name != tum.POSE_IN_FRAME:
            robot = tum.pick_robot(reader, config.topic, robot)
        with atomic_outputs([target]) as (f,):
            count, rows = tum.write_tum(messages, f, robot, progress, total)
        return ExportResult(target, count, rows)
    with atomic_outputs([target]) as (f,):
        count, rows = csv_format.write_csv(messages, f, progress, total)
    return ExportResult(target, count, rows)
