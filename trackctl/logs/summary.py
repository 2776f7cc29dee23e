"""A log's summary section parsed compactly.

mcap's :class:`~mcap.records.ChunkIndex` holds a ``dict`` from channel id to message-index offset.
A city-scale log has tens of thousands of channels spread over thousands of chunks: 1.9 million
entries, about 200 MB as Python ints in dicts. :class:`CompactOffsets` keeps the same mapping as
two numpy arrays (10 bytes an entry, as on disk) behind the ``Mapping`` interface, so every reader
of ``ci.message_index_offsets`` works unchanged. mcap has no lazy or compact form of the summary,
hence this module; every other record is still parsed by mcap's own reader.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterable, Iterator, Mapping

import numpy as np
from mcap.opcode import Opcode
from mcap.records import (
    AttachmentIndex,
    Channel,
    ChunkIndex,
    MetadataIndex,
    Schema,
    Statistics,
)
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

__all__ = ["CompactOffsets", "parse_summary", "has_any_channel"]

_ENTRY = np.dtype([("id", "<u2"), ("offset", "<u8")])


class CompactOffsets(Mapping[int, int]):
    """Channel id -> message-index offset of one chunk, as sorted numpy arrays."""

    __slots__ = ("ids", "offsets")

    def __init__(self, ids: np.ndarray, offsets: np.ndarray) -> None:
        order = np.argsort(ids, kind="stable")
        self.ids = np.ascontiguousarray(ids[order], dtype=np.uint16)
        self.offsets = np.ascontiguousarray(offsets[order], dtype=np.uint64)

    @classmethod
    def from_bytes(cls, raw: bytes) -> CompactOffsets:
        """From the record's ``map<uint16, uint64>`` body (no length prefix)."""
        entries = np.frombuffer(raw, dtype=_ENTRY)
        return cls(entries["id"], entries["offset"])

    def _find(self, key: object) -> int:
        if not isinstance(key, (int, np.integer)) or not 0 <= int(key) <= 0xFFFF:
            return -1
        i = int(np.searchsorted(self.ids, key))
        return i if i < len(self.ids) and int(self.ids[i]) == int(key) else -1

    def __getitem__(self, key: int) -> int:
        i = self._find(key)
        if i < 0:
            raise KeyError(key)
        return int(self.offsets[i])

    def __contains__(self, key: object) -> bool:
        return self._find(key) >= 0

    def __iter__(self) -> Iterator[int]:
        return iter(self.ids.tolist())

    def __len__(self) -> int:
        return len(self.ids)

    def __repr__(self) -> str:
        return f"CompactOffsets({dict(self)!r})"


def has_any_channel(offsets: Mapping[int, int], channel_ids: Iterable[int]) -> bool:
    """Whether a chunk's message indexes name any of ``channel_ids`` (vectorised when compact)."""
    if isinstance(offsets, CompactOffsets):
        wanted = np.fromiter(channel_ids, dtype=np.int64)
        return bool(np.isin(offsets.ids, wanted, assume_unique=True).any())
    return any(c in offsets for c in channel_ids)


def _chunk_index(body: bytes) -> ChunkIndex:
    start, end, offset, length, map_len = struct.unpack_from("<QQQQI", body, 0)
    pos = 36
    offsets = CompactOffsets.from_bytes(body[pos : pos + map_len])
    pos += map_len
    (index_length, name_len) = struct.unpack_from("<QI", body, pos)
    pos += 12
    compression = body[pos : pos + name_len].decode()
    pos += name_len
    compressed, uncompressed = struct.unpack_from("<QQ", body, pos)
    return ChunkIndex(
        message_start_time=start,
        message_end_time=end,
        chunk_start_offset=offset,
        chunk_length=length,
        message_index_offsets=offsets,  # type: ignore[arg-type]  # a Mapping, read-only
        message_index_length=index_length,
        compression=compression,
        compressed_size=compressed,
        uncompressed_size=uncompressed,
    )


def parse_summary(section: bytes) -> Summary:
    """The summary section (followed by the footer record and magic) as a :class:`Summary`
    whose chunk indexes hold :class:`CompactOffsets`.

    Raises:
        struct.error, ValueError, UnicodeDecodeError, EOFError: the section does not parse.
    """
    summary = Summary()
    rest = bytearray()
    pos = 0
    while pos + 9 <= len(section):
        opcode = section[pos]
        (length,) = struct.unpack_from("<Q", section, pos + 1)
        end = pos + 9 + length
        if end > len(section):
            raise EOFError("summary record runs past the section")
        if opcode == Opcode.CHUNK_INDEX:
            summary.chunk_indexes.append(_chunk_index(section[pos + 9 : end]))
        else:
            rest += section[pos:end]
        if opcode == Opcode.FOOTER:
            rest += section[end:]
            break
        pos = end
    for record in StreamReader(io.BytesIO(bytes(rest)), skip_magic=True).records:
        if isinstance(record, Statistics):
            summary.statistics = record
        elif isinstance(record, Schema):
            summary.schemas[record.id] = record
        elif isinstance(record, Channel):
            summary.channels[record.id] = record
        elif isinstance(record, MetadataIndex):
            summary.metadata_indexes.append(record)
        elif isinstance(record, AttachmentIndex):
            summary.attachment_indexes.append(record)
    return summary
