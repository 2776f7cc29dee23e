"""Defensive decoding of MCAP chunks and records: damage is reported, never passed on or raised.

mcap's own readers trust every length and never check a chunk's CRC: a flipped byte inside a
compressed chunk yields changed messages, a forged length an OverflowError or MemoryError, and
they stop at the first incomplete record (which, for a killed recording, throws away the whole
last chunk). Here every length is checked against the bytes that are really there, every chunk
with a CRC is verified after decompression, and a chunk that fails is skipped whole (no message of
it is emitted) with a :class:`Damage` saying where and how many messages were lost.

:func:`decode_chunk` serves the indexed reader; :func:`scan_damaged` walks a log without a usable
summary (no footer: killed recordings, cut copies; or a damaged summary) record by record, and when
the log ends inside a chunk decompresses that chunk's bytes as far as they go (zstd and lz4 frames
decode incrementally), keeping every complete message in it.
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import IO, Any

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Message, MessageIndex, Metadata, Schema

__all__ = [
    "scan_damaged",
    "ScanEnd",
    "Damage",
    "ChunkHeader",
    "ChunkError",
    "decode_chunk",
    "inflate_chunk",
    "check_chunk_size",
    "MAX_CHUNK_BYTES",
    "parse_chunk_header",
    "parse_message_index",
]

_HEAD = struct.Struct("<BQ")
_CHUNK_FIXED = struct.Struct("<QQQI")  # start, end, uncompressed size, uncompressed crc
_MESSAGE = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_NAMES = {int(op): op.name.lower() for op in Opcode}
_MAGIC_LEN = 8
MAX_CHUNK_BYTES = 256 << 20
"""A chunk claiming more uncompressed bytes than this is skipped as damaged, before anything is
allocated. Writers use chunks of 1-8 MiB (trackctl 1 MiB, the mcap CLI 4 MiB, rosbag2 768 KiB);
one message bigger than the chunk size makes a chunk of its own size."""
MAX_RATIO = {"": 1, "lz4": 256, "zstd": 32768}
"""The most uncompressed bytes one compressed byte can give (lz4 tops out near 255:1, zstd's
RLE blocks at 4 bytes per 128 KiB): a bigger claim is a lie, refused before decompression."""
_RATIO_SLACK = 1 << 10
_PIECE = 1 << 22  # decompress 4 MiB at a time


class ChunkError(ValueError):
    """A chunk's bytes are damaged (bad length, compression, CRC or record inside)."""


@dataclass(frozen=True, slots=True)
class Damage:
    """One damaged piece of a log that was skipped."""

    offset: int
    what: str
    lost_messages: int | None  # None: unknown
    kind: str = "chunk"

    def describe(self) -> str:
        """One line: where, what, and how much was lost."""
        lost = (
            "an unknown number of messages"
            if self.lost_messages is None
            else f"{self.lost_messages} message{'s' if self.lost_messages != 1 else ''}"
        )
        return f"damaged {self.kind} at byte {self.offset} ({self.what}); skipped it, {lost} lost"


@dataclass
class ScanEnd:
    """Where and why a scan stopped, and what it skipped (filled in as the scan runs)."""

    offset: int = 0
    reason: str = ""
    partial_chunk_messages: int = 0
    damage: list[Damage] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class ChunkHeader:
    """The fixed fields of a chunk record and where its compressed data lies in the body."""

    start_ns: int
    end_ns: int
    uncompressed_size: int
    uncompressed_crc: int
    compression: str
    data_start: int
    data_length: int


def parse_chunk_header(body: bytes) -> ChunkHeader:
    """The header of a chunk record body (the bytes after opcode and length).

    Raises:
        ChunkError: a field runs past the body.
    """
    if len(body) < _CHUNK_FIXED.size + 4:
        raise ChunkError("chunk header cut short")
    start, end, size, crc, name_len = struct.unpack_from("<QQQII", body)
    pos = _CHUNK_FIXED.size + 4
    if pos + name_len + 8 > len(body):
        raise ChunkError("compression name runs past the chunk")
    try:
        compression = body[pos : pos + name_len].decode("utf-8")
    except UnicodeDecodeError:
        raise ChunkError("compression name is not UTF-8") from None
    pos += name_len
    (data_len,) = struct.unpack_from("<Q", body, pos)
    pos += 8
    return ChunkHeader(start, end, size, crc, compression, pos, data_len)


def check_chunk_size(head: ChunkHeader) -> None:
    """Refuse a chunk whose claimed uncompressed size is over :data:`MAX_CHUNK_BYTES` or more
    than its compression can produce from the compressed bytes it has (a forged size must not
    allocate anything).

    Raises:
        ChunkError: the claim is implausible.
    """
    size = head.uncompressed_size
    if size > MAX_CHUNK_BYTES:
        raise ChunkError(
            f"implausible uncompressed size {size}: over the {MAX_CHUNK_BYTES >> 20} MiB limit"
        )
    ratio = MAX_RATIO.get(head.compression)
    if ratio is not None and size > ratio * head.data_length + _RATIO_SLACK:
        raise ChunkError(
            f"implausible uncompressed size {size} for {head.data_length} bytes of "
            f"{head.compression or 'uncompressed'} data"
        )


def _stream(head: ChunkHeader, data: bytes) -> Any:
    """A file-like reader of the decompressed bytes (the frame's own content size is never
    trusted for an allocation: the caller reads bounded pieces)."""
    if head.compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().stream_reader(data, read_across_frames=True)
    if head.compression == "lz4":
        import lz4.frame

        return lz4.frame.LZ4FrameFile(io.BytesIO(data), mode="rb")
    if head.compression == "":
        return io.BytesIO(data)
    raise ChunkError(f"unknown compression {head.compression[:20]!r}")


def _inflate(head: ChunkHeader, data: bytes, *, lenient: bool = False) -> bytearray:
    """Decompress piece by piece (streaming: the output grows only as the data really
    decompresses and never past the claimed size, whatever the compressed frame says).

    Args:
        lenient: return what decompresses before an error or the end of the data instead of
            raising (a cut chunk).

    Raises:
        ChunkError: the data does not decompress to exactly the claimed size.
    """
    size = min(head.uncompressed_size, MAX_CHUNK_BYTES)
    buf = bytearray()
    extra = b""
    try:
        reader = _stream(head, data)
        while len(buf) < size:
            piece = reader.read(min(_PIECE, size - len(buf)))
            if not piece:
                break
            buf += piece
        if not lenient:
            extra = reader.read(1)
    except ChunkError:
        raise
    except Exception as err:  # noqa: BLE001 - zstd/lz4 raise their own error types
        if not lenient:
            reason = " ".join(str(err).split())[:200] or type(err).__name__
            raise ChunkError(f"{head.compression} data does not decompress: {reason}") from None
    if not lenient and (len(buf) != head.uncompressed_size or extra):
        got = f"more than {len(buf)}" if extra else str(len(buf))
        raise ChunkError(f"decompressed to {got} bytes, header says {head.uncompressed_size}")
    return buf


def _records(data: bytes | bytearray, *, lenient: bool = False) -> Iterator[tuple[int, bytes]]:
    """(opcode, body) of the records in ``data``; a record running past the end is an error
    (or, with ``lenient``, the end), and so is opcode 0 (no MCAP record has it: a run of zeros,
    which would otherwise be millions of empty records)."""
    view = memoryview(data)
    pos, end = 0, len(data)
    while pos < end:
        if pos + _HEAD.size > end:
            if lenient:
                return
            raise ChunkError("record header cut short inside the chunk")
        opcode, length = _HEAD.unpack_from(data, pos)
        pos += _HEAD.size
        if length > end - pos:
            if lenient:
                return
            raise ChunkError(f"record length {length} runs past the chunk")
        if opcode == 0:
            if lenient:
                return
            raise ChunkError("a record with opcode 0 inside the chunk")
        yield opcode, bytes(view[pos : pos + length])
        pos += length


def _message(body: bytes) -> Message:
    if len(body) < _MESSAGE.size:
        raise ChunkError("message record too short")
    channel_id, sequence, log_time, publish_time = _MESSAGE.unpack_from(body)
    return Message(
        channel_id=channel_id,
        sequence=sequence,
        log_time=log_time,
        publish_time=publish_time,
        data=body[_MESSAGE.size :],
    )


def _record(opcode: int, body: bytes) -> Any:
    """A Schema, Channel or Message record from its body, None for other kinds."""
    if opcode == Opcode.MESSAGE:
        return _message(body)
    if opcode not in (Opcode.SCHEMA, Opcode.CHANNEL):
        return None
    stream = ReadDataStream(io.BytesIO(body))
    try:
        record = Schema.read(stream) if opcode == Opcode.SCHEMA else Channel.read(stream)
    except Exception as err:  # noqa: BLE001 - mcap raises struct/unicode/EOF errors
        raise ChunkError(f"{_NAMES[opcode]} record does not parse ({type(err).__name__})") from None
    if stream.count > len(body):
        raise ChunkError(f"{_NAMES[opcode]} record runs past its length")
    return record


def inflate_chunk(body: bytes) -> bytes | bytearray:
    """The uncompressed records of a chunk record body, CRC-checked when the chunk has a CRC.

    The claimed size is checked (:func:`check_chunk_size`) before anything is allocated.

    Raises:
        ChunkError: the chunk is damaged or its size implausible.
    """
    head = parse_chunk_header(body)
    data = body[head.data_start : head.data_start + head.data_length]
    if len(data) != head.data_length:
        raise ChunkError(f"compressed length {head.data_length} runs past the chunk")
    check_chunk_size(head)
    raw = _inflate(head, data)
    if head.uncompressed_crc and zlib.crc32(raw) != head.uncompressed_crc:
        raise ChunkError("CRC mismatch")
    return raw


def decode_chunk(body: bytes, *, lenient: bool = False) -> list[Any]:
    """The Schema, Channel and Message records of a chunk record body, all or none.

    The CRC of the uncompressed data is checked when the chunk has one.

    Args:
        lenient: the body was cut short (the last chunk of a killed recording): decompress as
            far as the bytes go and keep every complete record instead of failing.

    Raises:
        ChunkError: the chunk is damaged; no record of it should be used.
    """
    if lenient:
        head = parse_chunk_header(body)
        raw = _partial_decompress(head, body[head.data_start : head.data_start + head.data_length])
        out = []
        try:
            for opcode, rec_body in _records(raw, lenient=True):
                record = _record(opcode, rec_body)
                if record is not None:
                    out.append(record)
        except ChunkError:
            pass
        return out
    raw = inflate_chunk(body)
    return [r for opcode, rec_body in _records(raw) if (r := _record(opcode, rec_body)) is not None]


def _partial_decompress(head: ChunkHeader, data: bytes) -> bytes | bytearray:
    """What a cut chunk's bytes decompress to, as far as they go (nothing for an implausible
    claim; the buffer is bounded by what the bytes that are there can give)."""
    ratio = MAX_RATIO.get(head.compression)
    if head.uncompressed_size > MAX_CHUNK_BYTES or ratio is None:
        return b""
    bounded = min(head.uncompressed_size, ratio * len(data) + _RATIO_SLACK)
    return _inflate(replace(head, uncompressed_size=bounded), data, lenient=True)


def parse_message_index(body: bytes) -> MessageIndex:
    """A message index record from its body.

    Raises:
        ChunkError: it does not parse.
    """
    if len(body) < 6:
        raise ChunkError("message index too short")
    channel_id, size = struct.unpack_from("<HI", body)
    if 6 + size > len(body) or size % 16:
        raise ChunkError("message index length is inconsistent")
    records = list(struct.iter_unpack("<QQ", body[6 : 6 + size]))
    return MessageIndex(channel_id=channel_id, records=records)


def _top_level(opcode: int, head: bytes, body: bytes) -> Any:
    if opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE):
        return _record(opcode, body)
    if opcode not in (Opcode.METADATA, Opcode.ATTACHMENT):
        return None
    from mcap.stream_reader import StreamReader

    try:
        record = next(StreamReader(io.BytesIO(head + body), skip_magic=True).records)
    except Exception as err:  # noqa: BLE001 - mcap raises struct/unicode/EOF/CRC errors
        raise ChunkError(f"{_NAMES[opcode]} record does not parse ({type(err).__name__})") from None
    return record if isinstance(record, Metadata | Attachment) else None


def _cut_chunk(body: bytes, end: ScanEnd) -> Iterator[Any]:
    """The complete records of a chunk the log ends inside (counted in ``end``)."""
    try:
        records = decode_chunk(body, lenient=True)
    except ChunkError:
        records = []
    for record in records:
        if isinstance(record, Message):
            end.partial_chunk_messages += 1
        yield record


def _count_lost(lost: Damage, index_body: bytes) -> Damage:
    """Add the messages a damaged chunk's message index lists to its loss."""
    try:
        counted = len(parse_message_index(index_body).records)
    except ChunkError:
        return lost
    return Damage(lost.offset, lost.what, (lost.lost_messages or 0) + counted, lost.kind)


@dataclass(frozen=True, slots=True)
class _RecordAt:
    """One top-level record met by :func:`_walk`."""

    start: int
    opcode: int
    length: int
    head: bytes
    """The opcode and length bytes."""
    body: bytes
    """Empty, not read, when the record is ``cut``."""
    cut: bool = False
    """The record runs past the end of the file (the file then stands after its header)."""
    tail: int = 0
    """Bytes of the file after the header (as long as the file was when the walk began)."""


def _walk(f: IO[bytes], end: ScanEnd) -> Iterator[_RecordAt]:
    """The top-level records after the magic, up to the end of the file or a record that runs
    past it (yielded ``cut``, last); ``end`` says where and why the walk stopped. The caller ends
    the walk at the footer."""
    size = os.fstat(f.fileno()).st_size
    f.seek(_MAGIC_LEN)
    while True:
        start = f.tell()
        head = f.read(_HEAD.size)
        if len(head) < _HEAD.size:
            end.offset, end.reason = start, "inside a record header" if head else "end"
            return
        opcode, length = _HEAD.unpack(head)
        tail = size - start - _HEAD.size
        if length > tail:
            end.offset, end.reason = start, f"inside a {_NAMES.get(opcode, hex(opcode))} record"
            yield _RecordAt(start, opcode, length, head, b"", cut=True, tail=tail)
            return
        yield _RecordAt(start, opcode, length, head, f.read(length), tail=tail)


def _sound_top_level(rec: _RecordAt, end: ScanEnd) -> Any:
    """The Schema, Channel, Message, Metadata or Attachment outside a chunk (None for other
    records, and for a damaged one, which is listed in ``end.damage``)."""
    try:
        return _top_level(rec.opcode, rec.head, rec.body)
    except ChunkError as err:
        kind = _NAMES.get(rec.opcode, "record")
        lost = 1 if rec.opcode == Opcode.MESSAGE else 0
        end.damage.append(Damage(rec.start, str(err), lost, kind))
        return None


def scan_damaged(f: IO[bytes], end: ScanEnd) -> Iterator[Any]:
    """Yield Schema, Channel, Message, Metadata and Attachment records in file order.

    Damaged chunks and records are skipped (listed in ``end.damage``); a record whose length runs
    past the end of the file ends the scan there (a cut log: the complete messages of a cut-off
    last chunk are still recovered). ``end`` says where and why the scan stopped.
    """
    lost_chunk: Damage | None = None  # counted from the message indexes that follow it
    for rec in _walk(f, end):
        if rec.cut:
            if rec.opcode == Opcode.CHUNK:
                yield from _cut_chunk(f.read(rec.tail), end)
            break
        if rec.opcode == Opcode.MESSAGE_INDEX and lost_chunk is not None:
            lost_chunk = _count_lost(lost_chunk, rec.body)
            continue
        if lost_chunk is not None:
            end.damage.append(lost_chunk)
            lost_chunk = None
        if rec.opcode in (Opcode.FOOTER, Opcode.DATA_END):
            end.offset, end.reason = rec.start, "end"
            break
        if rec.opcode == Opcode.CHUNK:
            try:
                records = decode_chunk(rec.body)
            except ChunkError as err:
                lost_chunk = Damage(rec.start, str(err), None)
                continue
            yield from records
            continue
        record = _sound_top_level(rec, end)
        if record is not None:
            yield record
    if lost_chunk is not None:
        end.damage.append(lost_chunk)


@dataclass
class RebuiltIndex:
    """A summary rebuilt from the records of a log that has none (see :func:`rebuild_index`).

    Attributes:
        summary: schemas, channels, chunk indexes (pointing at the message index records that
            follow each chunk), metadata and attachment indexes, and statistics.
        end: where and why the walk stopped, and the damage met.
        cut_chunk_messages: complete messages in a chunk the log ends inside (not indexed).
        unindexed_messages: messages outside any chunk (the log then cannot be used indexed).
    """

    summary: Any
    end: ScanEnd
    cut_chunk_messages: int = 0
    unindexed_messages: int = 0


def _chunk_index(start: int, length: int, head: ChunkHeader) -> Any:
    from mcap.records import ChunkIndex

    return ChunkIndex(
        message_start_time=head.start_ns,
        message_end_time=head.end_ns,
        chunk_start_offset=start,
        chunk_length=_HEAD.size + length,
        message_index_offsets={},
        message_index_length=0,
        compression=head.compression,
        compressed_size=head.data_length,
        uncompressed_size=head.uncompressed_size,
    )


class _IndexBuilder:
    """State of :func:`rebuild_index`: the chunk being completed by its message indexes."""

    def __init__(self) -> None:
        from mcap.summary import Summary

        self.summary = Summary()
        self.counts: dict[int, int] = {}
        self.chunk: Any = None
        self.body = b""
        self.damage: list[Damage] = []

    def finish_chunk(self) -> None:
        """Keep the chunk in progress; decompress it only when it declares a channel (or has no
        message index to say which channels it holds)."""
        ci, self.chunk = self.chunk, None
        if ci is None:
            return
        known = self.summary.channels
        if not ci.message_index_offsets or not ci.message_index_offsets.keys() <= known.keys():
            try:
                records = decode_chunk(self.body)
            except ChunkError as err:
                lost = sum(self._indexed.values()) if ci.message_index_offsets else None
                self.damage.append(Damage(ci.chunk_start_offset, str(err), lost))
                for channel_id in ci.message_index_offsets:
                    self.counts[channel_id] -= self._indexed.get(channel_id, 0)
                return
            for record in records:
                self.add(record)
            if not ci.message_index_offsets:
                for record in records:
                    if isinstance(record, Message):
                        self.counts[record.channel_id] = self.counts.get(record.channel_id, 0) + 1
        self.summary.chunk_indexes.append(ci)

    def add(self, record: Any) -> None:
        if isinstance(record, Schema):
            self.summary.schemas[record.id] = record
        elif isinstance(record, Channel):
            self.summary.channels[record.id] = record

    def message_index(self, start: int, length: int, body: bytes) -> None:
        index = parse_message_index(body)
        self.chunk.message_index_offsets[index.channel_id] = start
        self.chunk.message_index_length += _HEAD.size + length
        n = len(index.records)
        self._indexed[index.channel_id] = n
        self.counts[index.channel_id] = self.counts.get(index.channel_id, 0) + n

    def start_chunk(self, start: int, length: int, body: bytes) -> None:
        self.finish_chunk()
        self.chunk = _chunk_index(start, length, parse_chunk_header(body))
        self.body = body
        self._indexed: dict[int, int] = {}

    def take_chunk_part(self, rec: _RecordAt) -> bool:
        """Take a chunk, or a message index of the chunk in progress; for any other record
        finish the chunk in progress and return False.

        Raises:
            ChunkError: the chunk header or message index does not parse.
        """
        if rec.opcode == Opcode.MESSAGE_INDEX and self.chunk is not None:
            self.message_index(rec.start, rec.length, rec.body)
            return True
        if rec.opcode == Opcode.CHUNK:
            self.start_chunk(rec.start, rec.length, rec.body)
            return True
        self.finish_chunk()
        return False

    def index_top_level(self, rec: _RecordAt, record: Any, out: RebuiltIndex) -> None:
        """Index a record outside any chunk (a message there is only counted)."""
        from mcap.records import AttachmentIndex, MetadataIndex

        if isinstance(record, Message):
            out.unindexed_messages += 1
        elif isinstance(record, Metadata):
            self.summary.metadata_indexes.append(
                MetadataIndex(offset=rec.start, length=_HEAD.size + rec.length, name=record.name)
            )
        elif isinstance(record, Attachment):
            self.summary.attachment_indexes.append(
                AttachmentIndex(
                    offset=rec.start,
                    length=_HEAD.size + rec.length,
                    log_time=record.log_time,
                    create_time=record.create_time,
                    data_size=len(record.data),
                    name=record.name,
                    media_type=record.media_type,
                )
            )
        else:
            self.add(record)

    def statistics(self) -> Any:
        """The statistics of everything indexed (channels whose messages all were lost are left
        out of the counts)."""
        from mcap.records import Statistics

        summary = self.summary
        chunks = summary.chunk_indexes
        counts = {k: v for k, v in self.counts.items() if v > 0}
        return Statistics(
            message_count=sum(counts.values()),
            schema_count=len(summary.schemas),
            channel_count=len(summary.channels),
            attachment_count=len(summary.attachment_indexes),
            metadata_count=len(summary.metadata_indexes),
            chunk_count=len(chunks),
            message_start_time=min((c.message_start_time for c in chunks), default=0),
            message_end_time=max((c.message_end_time for c in chunks), default=0),
            channel_message_counts=counts,
        )


def rebuild_index(f: IO[bytes]) -> RebuiltIndex:
    """Walk a log without a usable summary once and rebuild one, as far as the log is sound.

    Chunks are indexed through the message index records the writer put after each of them; a
    chunk is decompressed only when it declares a schema or channel not seen before (or has no
    message index), so the walk costs about one read of the file. A chunk the log ends inside is
    not indexed (its complete messages are counted); a damaged chunk met while decompressing is
    left out and listed in ``end.damage``.
    """
    b = _IndexBuilder()
    end = ScanEnd()
    out = RebuiltIndex(b.summary, end)
    for rec in _walk(f, end):
        if rec.cut:
            if rec.opcode == Opcode.CHUNK:
                out.cut_chunk_messages = sum(
                    isinstance(r, Message) for r in _cut_chunk(f.read(), ScanEnd())
                )
            break
        try:
            if b.take_chunk_part(rec):
                continue
            if rec.opcode in (Opcode.FOOTER, Opcode.DATA_END):
                end.offset, end.reason = rec.start, "end"
                break
            record = _top_level(rec.opcode, rec.head, rec.body)
        except ChunkError as err:
            b.chunk = None
            end.damage.append(Damage(rec.start, str(err), None, _NAMES.get(rec.opcode, "record")))
            continue
        b.index_top_level(rec, record, out)
    b.finish_chunk()
    end.damage.extend(b.damage)
    b.summary.statistics = b.statistics()
    return out
