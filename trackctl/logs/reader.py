"""Streaming MCAP reader with typed decoding.

:class:`LogReader` iterates a log chunk by chunk (memory bounded by the chunks that overlap in
time, not by the log's length), in log-time order, filtered by topic and time range, and decodes
each message with the codec registered for its schema.

A log without a footer (a recording that was killed, a copy cut short) is read sequentially as far
as it goes; the reader warns with :class:`~trackctl.errors.TruncatedLogWarning` and keeps what it
could read. Such a log is iterated in file order, which trackctl's writer keeps in time order.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Message, MessageIndex, Metadata, Schema, Statistics
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

from trackctl.errors import (
    LogError,
    MissingTopicError,
    NotAFileError,
    NotAnMcapError,
    TruncatedLogWarning,
)
from trackctl.logs.codecs import Codec, codec_for
from trackctl.logs.recovery import ScanEnd, scan_damaged

__all__ = ["LogReader", "RawMessage", "LogMessage", "TopicInfo", "MCAP_MAGIC"]

MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass(frozen=True, slots=True)
class RawMessage:
    """One message as stored: channel and schema facts plus the encoded bytes."""

    topic: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    channel_metadata: Mapping[str, str] = field(default_factory=dict)

    @classmethod
    def from_records(cls, schema: Any, channel: Any, message: Any) -> RawMessage:
        """From mcap's Schema (or None), Channel and Message records."""
        return cls(
            topic=channel.topic,
            schema_name=schema.name if schema else "",
            schema_encoding=schema.encoding if schema else "",
            schema_data=schema.data if schema else b"",
            message_encoding=channel.message_encoding,
            log_time_ns=message.log_time,
            publish_time_ns=message.publish_time,
            data=message.data,
            channel_metadata=channel.metadata,
        )


@dataclass(frozen=True, slots=True)
class LogMessage:
    """One decoded message: a trackctl dataclass, a protobuf message or a plain dict."""

    topic: str
    log_time_ns: int
    schema_name: str
    message: Any


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """What a log holds on one topic."""

    topic: str
    schema_name: str
    message_encoding: str
    count: int
    first_ns: int | None
    last_ns: int | None

    @property
    def rate_hz(self) -> float:
        """Mean message rate over the topic's own span (0 for fewer than two messages)."""
        if self.count < 2 or self.first_ns is None or self.last_ns is None:
            return 0.0
        span = self.last_ns - self.first_ns
        return (self.count - 1) * 1e9 / span if span > 0 else 0.0


_READ_ERRORS = (McapError, EOFError, ValueError, OSError, KeyError, IndexError)


def _is_damage(err: BaseException) -> bool:
    """True for errors that mean "the bytes end or break here" (zstd/lz4 raise their own types)."""
    return (
        isinstance(err, _READ_ERRORS)
        or type(err).__module__.split(".")[0]
        in (
            "zstandard",
            "lz4",
            "struct",
        )
        or type(err).__name__ in ("ZstdError", "error")
    )


class LogReader:
    """Reads an MCAP log lazily.

    Args:
        path: the log file.

    Raises:
        NotAFileError: the path is missing or not a regular file.
        NotAnMcapError: the file does not start with the MCAP magic.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise NotAFileError(f"{self.path}: no such file")
        if not self.path.is_file():
            raise NotAFileError(f"{self.path}: not a regular file")
        with self.path.open("rb") as f:
            head = f.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise NotAnMcapError(
                f"{self.path}: not an MCAP file (it does not start with the MCAP magic bytes)"
            )
        self.warnings: list[str] = []
        self._summary: Summary | None = None
        self.truncated = False
        try:
            with self.path.open("rb") as f:
                self._summary = SeekingReader(f).get_summary()
        except Exception as err:  # noqa: BLE001 - any failure here means the footer is unusable
            if not _is_damage(err):
                raise
            self.truncated = True
            self._warn(
                f"{self.path}: no valid footer or summary (unfinished recording or cut copy); "
                "reading it sequentially as far as it goes"
            )
        self._stats_cache: dict[str, TopicInfo] | None = None
        self._codecs: dict[int, Codec] = {}

    # -- warnings -----------------------------------------------------------------------------
    def _warn(self, text: str) -> None:
        if text not in self.warnings:
            self.warnings.append(text)
            warnings.warn(text, TruncatedLogWarning, stacklevel=3)

    # -- iteration ----------------------------------------------------------------------------
    def _iter_records(
        self,
        f: IO[bytes],
        topics: list[str] | None,
        start_ns: int | None,
        end_ns: int | None,
    ) -> Iterator[tuple[Schema | None, Channel, Message]]:
        if not self.truncated:
            try:
                yield from SeekingReader(f).iter_messages(
                    topics=topics, starting_at=start_ns, ending_before=end_ns, log_time_order=True
                )
            except McapError as err:
                raise LogError(f"{self.path}: corrupt log: {err}") from err
            return
        end = ScanEnd()
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        wanted = None if topics is None else set(topics)
        count = 0
        for record in scan_damaged(f, end):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                channel = channels.get(record.channel_id)
                if channel is None:
                    continue
                if wanted is not None and channel.topic not in wanted:
                    continue
                if start_ns is not None and record.log_time < start_ns:
                    continue
                if end_ns is not None and record.log_time >= end_ns:
                    continue
                count += 1
                yield schemas.get(channel.schema_id), channel, record
        if end.reason != "end":
            partial = (
                f", {end.partial_chunk_messages} of them recovered from the cut-off chunk"
                if end.partial_chunk_messages
                else ""
            )
            size = self.path.stat().st_size
            self._warn(
                f"{self.path}: log is cut at byte {size}, {end.reason} starting at byte "
                f"{end.offset}; read {count} messages{partial}; the rest is lost"
            )

    def raw(
        self,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> Iterator[RawMessage]:
        """Encoded messages in log-time order, ``start_ns <= log_time < end_ns``."""
        topic_list = None if topics is None else list(topics)
        with self.path.open("rb") as f:
            for schema, channel, message in self._iter_records(f, topic_list, start_ns, end_ns):
                yield RawMessage.from_records(schema, channel, message)

    def codec(self, raw: RawMessage) -> Codec:
        """The codec that decodes ``raw``'s channel."""
        return codec_for(
            raw.schema_name, raw.message_encoding, raw.schema_encoding, raw.schema_data
        )

    def messages(
        self,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        """Decoded messages in log-time order (see :meth:`raw` for the filters)."""
        codecs: dict[tuple[str, str, bytes], Codec] = {}
        for raw in self.raw(topics, start_ns, end_ns):
            key = (raw.schema_name, raw.message_encoding, raw.schema_data)
            codec = codecs.get(key)
            if codec is None:
                codec = codecs[key] = self.codec(raw)
            try:
                decoded = codec.decode(raw.data)
            except Exception as err:
                raise LogError(
                    f"{self.path}: {raw.topic} at {raw.log_time_ns} ns: cannot decode "
                    f"{raw.schema_name}: {err}"
                ) from err
            yield LogMessage(raw.topic, raw.log_time_ns, raw.schema_name, decoded)

    # -- summary ------------------------------------------------------------------------------
    def topics(self) -> dict[str, TopicInfo]:
        """Per-topic schema, encoding, count and time span (from the index when there is one)."""
        if self._stats_cache is None:
            stats = None
            if self._summary is not None and self._summary.statistics is not None:
                stats = self._topics_from_summary(self._summary)
            self._stats_cache = stats if stats is not None else self._topics_by_scan()
        return self._stats_cache

    def _topics_from_summary(self, summary: Summary) -> dict[str, TopicInfo] | None:
        statistics: Statistics = summary.statistics  # type: ignore[assignment]
        first: dict[int, int] = {}
        last: dict[int, int] = {}
        with self.path.open("rb") as f:
            for chunk_index in summary.chunk_indexes:
                for channel_id, offset in chunk_index.message_index_offsets.items():
                    f.seek(offset)
                    record = next(StreamReader(f, skip_magic=True).records, None)
                    if not isinstance(record, MessageIndex) or not record.records:
                        continue
                    times = [t for t, _ in record.records]
                    first[channel_id] = min(first.get(channel_id, times[0]), min(times))
                    last[channel_id] = max(last.get(channel_id, times[0]), max(times))
        if summary.chunk_indexes and not first and statistics.message_count:
            return None  # no message indexes: count by scanning instead
        out: dict[str, TopicInfo] = {}
        for channel_id, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            out[channel.topic] = TopicInfo(
                topic=channel.topic,
                schema_name=schema.name if schema else "",
                message_encoding=channel.message_encoding,
                count=statistics.channel_message_counts.get(channel_id, 0),
                first_ns=first.get(channel_id),
                last_ns=last.get(channel_id),
            )
        return out

    def _topics_by_scan(self) -> dict[str, TopicInfo]:
        counts: dict[str, list[Any]] = {}
        for raw in self.raw():
            entry = counts.get(raw.topic)
            if entry is None:
                counts[raw.topic] = [
                    raw.schema_name,
                    raw.message_encoding,
                    1,
                    raw.log_time_ns,
                    raw.log_time_ns,
                ]
            else:
                entry[2] += 1
                entry[3] = min(entry[3], raw.log_time_ns)
                entry[4] = max(entry[4], raw.log_time_ns)
        return {
            topic: TopicInfo(topic, e[0], e[1], e[2], e[3], e[4]) for topic, e in counts.items()
        }

    @property
    def start_ns(self) -> int | None:
        """Log time of the first message, or None for an empty log."""
        firsts = [t.first_ns for t in self.topics().values() if t.first_ns is not None]
        return min(firsts) if firsts else None

    @property
    def end_ns(self) -> int | None:
        """Log time of the last message, or None for an empty log."""
        lasts = [t.last_ns for t in self.topics().values() if t.last_ns is not None]
        return max(lasts) if lasts else None

    @property
    def message_count(self) -> int:
        """Total number of messages (readable ones, for a truncated log)."""
        return sum(t.count for t in self.topics().values())

    def metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records by name (a later record of the same name wins)."""
        out: dict[str, dict[str, str]] = {}
        with self.path.open("rb") as f:
            try:
                if self.truncated:
                    for record in scan_damaged(f, ScanEnd()):
                        if isinstance(record, Metadata):
                            out[record.name] = dict(record.metadata)
                else:
                    for md in SeekingReader(f).iter_metadata():
                        out[md.name] = dict(md.metadata)
            except McapError as err:
                raise LogError(f"{self.path}: cannot read metadata: {err}") from err
        return out

    def attachments(self) -> dict[str, tuple[str, bytes]]:
        """Attachments by name: (media type, data)."""
        out: dict[str, tuple[str, bytes]] = {}
        with self.path.open("rb") as f:
            if self.truncated:
                for record in scan_damaged(f, ScanEnd()):
                    if isinstance(record, Attachment):
                        out[record.name] = (record.media_type, record.data)
            else:
                for att in SeekingReader(f).iter_attachments():
                    out[att.name] = (att.media_type, att.data)
        return out

    def require(self, topics: Iterable[str], needed_by: str, why: str = "") -> None:
        """Raise :class:`MissingTopicError` naming the first absent topic and who needs it."""
        present = self.topics()
        for topic in topics:
            if topic not in present:
                reason = f" ({why})" if why else ""
                raise MissingTopicError(
                    f"{self.path}: topic {topic} is missing; {needed_by} needs it{reason}. "
                    f"The log has: {', '.join(sorted(present)) or 'no topics'}"
                )


class IndexedWindowReader:
    """Exact (topic, time range) reads through the MCAP chunk and message indexes.

    Where :meth:`LogReader.raw` decodes every record of each chunk it visits, this reader looks up
    the topic's message index in each chunk overlapping the range and parses only the messages of
    that topic inside it, so reading one message of one topic costs one chunk inflation (cached,
    most recent ``cache_chunks``) and one record. The summary is read once. Used when a processor
    fetches a few (topic, window) pieces out of a large log (EV-Matching's V-scenarios).

    Args:
        reader: an open :class:`LogReader` (an indexed, not truncated, log).
        cache_chunks: decompressed chunks kept for the next reads.

    Raises:
        LogError: the log has no usable index (truncated or written without chunk indexes).
    """

    def __init__(self, reader: LogReader, cache_chunks: int = 4) -> None:
        import numpy as np

        if reader.truncated or reader._summary is None or not reader._summary.chunk_indexes:
            raise LogError(f"{reader.path}: no chunk index, cannot read a topic window directly")
        self.path = reader.path
        self._summary = reader._summary
        self._f = reader.path.open("rb")
        self._by_topic = {ch.topic: ch for ch in self._summary.channels.values()}
        self._chunks = sorted(self._summary.chunk_indexes, key=lambda c: c.message_start_time)
        self._starts = np.array([c.message_start_time for c in self._chunks], dtype=np.int64)
        self._ends = np.array([c.message_end_time for c in self._chunks], dtype=np.int64)
        self._cache: dict[int, bytes] = {}
        self._cache_order: list[int] = []
        self._cache_size = max(1, cache_chunks)
        self._index: dict[tuple[int, int], list[tuple[int, int]]] = {}
        self.bytes_inflated = 0

    def close(self) -> None:
        """Close the file."""
        self._f.close()

    def __enter__(self) -> IndexedWindowReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def has_topic(self, topic: str) -> bool:
        return topic in self._by_topic

    def _message_index(
        self, chunk_offset: int, offset: int, channel_id: int
    ) -> list[tuple[int, int]]:
        key = (chunk_offset, channel_id)
        found = self._index.get(key)
        if found is None:
            self._f.seek(offset)
            record = next(StreamReader(self._f, skip_magic=True).records, None)
            found = list(record.records) if isinstance(record, MessageIndex) else []
            self._index[key] = found
        return found

    def _chunk_data(self, chunk_index: Any) -> bytes:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Chunk
        from mcap.stream_reader import get_chunk_data_stream

        key = chunk_index.chunk_start_offset
        data = self._cache.get(key)
        if data is None:
            # skip the chunk record's opcode (1 byte) and length (8 bytes)
            self._f.seek(key + 1 + 8)
            chunk = Chunk.read(ReadDataStream(self._f))
            stream, length = get_chunk_data_stream(chunk)
            data = stream.read(length)
            self.bytes_inflated += len(data)
            self._cache[key] = data
            self._cache_order.append(key)
            if len(self._cache_order) > self._cache_size:
                self._cache.pop(self._cache_order.pop(0), None)
        return data

    def read(self, topic: str, start_ns: int, end_ns: int) -> list[RawMessage]:
        """The messages of ``topic`` with ``start_ns <= log_time < end_ns``, in log-time order.

        Raises:
            MissingTopicError: the log has no such topic.
        """
        import io

        from mcap.data_stream import ReadDataStream

        channel = self._by_topic.get(topic)
        if channel is None:
            raise MissingTopicError(f"{self.path}: topic {topic} is missing")
        schema = self._summary.schemas.get(channel.schema_id)
        out: list[RawMessage] = []
        hit = (self._starts < end_ns) & (self._ends >= start_ns)
        for i in hit.nonzero()[0]:
            ci = self._chunks[int(i)]
            offset = ci.message_index_offsets.get(channel.id)
            if offset is None:
                continue
            entries = [
                (t, off)
                for t, off in self._message_index(ci.chunk_start_offset, offset, channel.id)
                if start_ns <= t < end_ns
            ]
            if not entries:
                continue
            data = self._chunk_data(ci)
            for _, off in entries:
                length = int.from_bytes(data[off + 1 : off + 9], "little")
                body = data[off + 9 : off + 9 + length]
                message = Message.read(ReadDataStream(io.BytesIO(body)), length)
                out.append(RawMessage.from_records(schema, channel, message))
        out.sort(key=lambda r: r.log_time_ns)
        return out


__all__ += ["IndexedWindowReader"]
