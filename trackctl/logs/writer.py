"""Atomic MCAP writer.

The log is written to a temporary file beside the output and renamed over it only when
:meth:`LogWriter.close` finishes it, so a crash or an error never leaves a half-written output,
and an input is never overwritten (the writer refuses an output path equal to an input).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from trackctl.errors import OutputError
from trackctl.logs.codecs import Codec, codec_for_type
from trackctl.logs.reader import RawMessage

__all__ = ["LogWriter", "COMPRESSIONS"]

COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
PROFILE = "trackctl"


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


class LogWriter:
    """Writes one MCAP log atomically (temp file + rename on :meth:`close`).

    Schemas and channels are registered once, on first use of a topic. Typed messages (trackctl
    dataclasses, Foxglove protobuf messages) go through :meth:`write`; already-encoded messages
    (copies from another log, JSON lines) through :meth:`write_encoded` and :meth:`write_raw`.

    Args:
        path: output file.
        inputs: files the output must not overwrite.
        compression: ``zstd`` (default), ``lz4`` or ``none``.
        chunk_size: target uncompressed chunk size in bytes.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        inputs: Iterable[str | os.PathLike[str]] = (),
        compression: str = "zstd",
        chunk_size: int = 1 << 20,
    ) -> None:
        self.path = Path(path)
        for inp in inputs:
            inp_path = Path(inp)
            if self.path.resolve() == inp_path.resolve() or _same_file(self.path, inp_path):
                raise OutputError(
                    f"{self.path}: output path is the input log; choose another --out "
                    "(trackctl never overwrites its input)"
                )
        if compression not in COMPRESSIONS:
            raise OutputError(
                f"compression {compression!r} unknown; expected one of {sorted(COMPRESSIONS)}"
            )
        if self.path.is_dir():
            raise OutputError(f"{self.path}: is a directory, expected an output file path")
        parent = self.path.parent
        if not parent.exists():
            raise OutputError(f"{self.path}: folder {parent} does not exist")
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp", dir=parent)
        self._tmp_path = Path(tmp)
        self._stream: IO[bytes] = os.fdopen(fd, "wb")
        self._writer = Writer(
            self._stream, chunk_size=chunk_size, compression=COMPRESSIONS[compression]
        )
        self._writer.start(profile=PROFILE, library="trackctl")
        self._schemas: dict[tuple[str, str, bytes], int] = {}
        self._channels: dict[str, tuple[int, str, str]] = {}
        self._closed = False
        self.message_count = 0

    # -- registration -------------------------------------------------------------------------
    def _schema_id(self, name: str, encoding: str, data: bytes) -> int:
        key = (name, encoding, data)
        sid = self._schemas.get(key)
        if sid is None:
            sid = self._writer.register_schema(name=name, encoding=encoding, data=data)
            self._schemas[key] = sid
        return sid

    def channel(
        self,
        topic: str,
        schema_name: str,
        schema_encoding: str,
        schema_data: bytes,
        message_encoding: str,
        metadata: Mapping[str, str] | None = None,
    ) -> int:
        """Channel id for ``topic``, registering schema and channel on first use.

        Raises:
            OutputError: the topic was already registered with another schema or encoding.
        """
        known = self._channels.get(topic)
        if known is not None:
            cid, known_schema, known_enc = known
            if (known_schema, known_enc) != (schema_name, message_encoding):
                raise OutputError(
                    f"{topic}: already written with schema {known_schema} ({known_enc}); "
                    f"cannot also write {schema_name} ({message_encoding}) on it"
                )
            return cid
        sid = 0
        if schema_name or schema_data:
            sid = self._schema_id(schema_name, schema_encoding, schema_data)
        cid = self._writer.register_channel(
            topic=topic,
            message_encoding=message_encoding,
            schema_id=sid,
            metadata=dict(metadata or {}),
        )
        self._channels[topic] = (cid, schema_name, message_encoding)
        return cid

    def _channel_for_codec(self, topic: str, codec: Codec) -> int:
        known = self._channels.get(topic)
        if known is not None and known[1] == codec.schema_name:
            return known[0]
        return self.channel(
            topic,
            codec.schema_name,
            codec.schema_encoding,
            codec.schema_data,
            codec.message_encoding,
        )

    # -- writing ------------------------------------------------------------------------------
    def write(self, topic: str, message: Any, log_time_ns: int | None = None) -> None:
        """Encode and write a typed message; ``log_time_ns`` defaults to the message's ``t_ns``."""
        codec = codec_for_type(type(message))
        if log_time_ns is None:
            log_time_ns = getattr(message, "t_ns", None)
            if log_time_ns is None:
                raise OutputError(f"{topic}: log_time_ns is required for {codec.schema_name}")
        self.write_encoded(topic, codec, codec.encode(message), log_time_ns)

    def write_encoded(
        self,
        topic: str,
        codec: Codec,
        data: bytes,
        log_time_ns: int,
        publish_time_ns: int | None = None,
    ) -> None:
        """Write bytes already encoded by ``codec``."""
        cid = self._channel_for_codec(topic, codec)
        self._add(cid, data, log_time_ns, publish_time_ns)

    def write_raw(self, raw: RawMessage) -> None:
        """Copy a message read from another log unchanged (schema, encoding and bytes)."""
        cid = self.channel(
            raw.topic,
            raw.schema_name,
            raw.schema_encoding,
            raw.schema_data,
            raw.message_encoding,
            raw.channel_metadata,
        )
        self._add(cid, raw.data, raw.log_time_ns, raw.publish_time_ns)

    def _add(self, cid: int, data: bytes, log_time_ns: int, publish_time_ns: int | None) -> None:
        if self._closed:
            raise OutputError(f"{self.path}: writer is closed")
        log_time_ns = int(log_time_ns)
        if log_time_ns < 0:
            raise OutputError(f"{self.path}: negative log time {log_time_ns} ns")
        self._writer.add_message(
            channel_id=cid,
            log_time=log_time_ns,
            publish_time=log_time_ns if publish_time_ns is None else int(publish_time_ns),
            data=data,
        )
        self.message_count += 1

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """Add a metadata record (values are stored as strings, as MCAP requires)."""
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def add_attachment(
        self,
        name: str,
        data: bytes,
        media_type: str = "application/octet-stream",
        log_time_ns: int = 0,
    ) -> None:
        """Attach a file (calibration source, configuration...) to the log."""
        self._writer.add_attachment(
            create_time=log_time_ns,
            log_time=log_time_ns,
            name=name,
            media_type=media_type,
            data=data,
        )

    # -- lifecycle ----------------------------------------------------------------------------
    def close(self) -> Path:
        """Finish the log, flush it to disk and move it to its final path."""
        if self._closed:
            return self.path
        self._writer.finish()
        self._stream.flush()
        os.fsync(self._stream.fileno())
        self._stream.close()
        # mkstemp creates 0600 files; give the log the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(self._tmp_path, 0o666 & ~umask)
        os.replace(self._tmp_path, self.path)
        self._closed = True
        return self.path

    def abort(self) -> None:
        """Drop the unfinished log; the output path is left as it was."""
        if self._closed:
            return
        self._closed = True
        try:
            self._stream.close()
        finally:
            self._tmp_path.unlink(missing_ok=True)

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
