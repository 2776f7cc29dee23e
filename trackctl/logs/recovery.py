"""Sequential reading of damaged MCAP logs (no footer: killed recordings, cut copies).

mcap's own readers stop at the first incomplete record, which for a chunked log throws away the
whole last chunk (by default up to 1 MiB of messages). This scanner walks the top-level records
itself and, when the log ends inside a chunk, decompresses that chunk's bytes as far as they go
(zstd and lz4 frames decode incrementally; uncompressed chunks trivially), keeping every complete
message in it.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import IO, Any

from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

__all__ = ["scan_damaged", "ScanEnd"]

_HEAD = struct.Struct("<BQ")
_NAMES = {int(op): op.name.lower() for op in Opcode}
_MAGIC_LEN = 8


@dataclass
class ScanEnd:
    """Where and why a scan stopped (filled in as the scan runs)."""

    offset: int = 0
    reason: str = ""
    partial_chunk_messages: int = 0


def _partial_chunk(body: bytes) -> list[Any]:
    """Records of a chunk whose bytes end early (possibly empty)."""
    fixed = struct.Struct("<QQQII")
    if len(body) < fixed.size:
        return []
    _, _, uncompressed_size, _, comp_len = fixed.unpack_from(body)
    pos = fixed.size
    compression = body[pos : pos + comp_len].decode("utf-8", "replace")
    pos += comp_len + 8  # skip records length
    data = body[pos:]
    try:
        if compression == "zstd":
            import zstandard

            raw = zstandard.ZstdDecompressor().decompressobj().decompress(data)
        elif compression == "lz4":
            import lz4.frame

            raw = lz4.frame.LZ4FrameDecompressor().decompress(data)
        elif compression == "":
            raw = data
        else:
            return []
    except Exception:  # noqa: BLE001 - a damaged frame simply yields nothing more
        return []
    raw = raw[:uncompressed_size]
    out: list[Any] = []
    reader = StreamReader(io.BytesIO(raw), skip_magic=True)
    try:
        for record in reader.records:
            out.append(record)
    except Exception:  # noqa: BLE001 - the last record is cut: keep the complete ones
        pass
    return out


def scan_damaged(f: IO[bytes], end: ScanEnd) -> Iterator[Any]:
    """Yield Schema, Channel, Message, Metadata and Attachment records of a damaged log in file
    order, recovering the complete messages of a cut-off last chunk. ``end`` says where it stopped.
    """
    f.seek(_MAGIC_LEN)
    while True:
        start = f.tell()
        head = f.read(_HEAD.size)
        if len(head) < _HEAD.size:
            end.offset, end.reason = start, "inside a record header" if head else "end"
            return
        opcode, length = _HEAD.unpack(head)
        body = f.read(length)
        if len(body) < length:
            end.offset, end.reason = start, f"inside a {_NAMES.get(opcode, hex(opcode))} record"
            if opcode == Opcode.CHUNK:
                for record in _partial_chunk(body):
                    if isinstance(record, Message):
                        end.partial_chunk_messages += 1
                    yield record
            return
        if opcode == Opcode.FOOTER or opcode == Opcode.DATA_END:
            end.offset, end.reason = start, "end"
            return
        if opcode == Opcode.CHUNK:
            try:
                chunk = Chunk.read(_stream(body))
                records = breakup_chunk(chunk)
            except Exception as err:  # noqa: BLE001
                end.offset, end.reason = start, f"corrupt chunk ({type(err).__name__})"
                return
            yield from records
        elif opcode in (
            Opcode.SCHEMA,
            Opcode.CHANNEL,
            Opcode.MESSAGE,
            Opcode.METADATA,
            Opcode.ATTACHMENT,
        ):
            try:
                record = next(StreamReader(io.BytesIO(head + body), skip_magic=True).records)
            except Exception as err:  # noqa: BLE001
                end.offset, end.reason = start, f"corrupt record ({type(err).__name__})"
                return
            if isinstance(record, Schema | Channel | Message | Metadata | Attachment):
                yield record


def _stream(body: bytes) -> Any:
    from mcap.data_stream import ReadDataStream

    return ReadDataStream(io.BytesIO(body))
