"""Atomic MCAP writer with a visible partial file and an exclusive lock.

A log is written to ``OUT.partial`` beside the output and renamed over ``OUT`` only when
:meth:`LogWriter.close` finishes it, so an error never leaves a half-written output and an input
is never overwritten (the writer refuses an output path equal to an input). The partial file is
locked (``flock``) while it is written: a second writer of the same output fails at once instead of
racing the first. After a ``kill -9`` the partial file stays, readable (``trackctl info`` and
``replay`` read it as far as it goes) and finishable with ``trackctl recover``; the next writer of
that output refuses to start rather than throw it away.

Only regular files (or new paths) are written: devices, FIFOs, directories and symlinks to them
are refused, so ``--out /dev/full`` cannot replace a device node with a file.
"""

from __future__ import annotations

import errno
import fcntl
import os
import stat
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from trackctl.errors import OutputError
from trackctl.logs.codecs import Codec, codec_for_type
from trackctl.logs.output import (
    check_output,
    check_output_path,
    forget_unfinished,
    signals_deferred,
    track_unfinished,
    write_text_atomic,
)
from trackctl.logs.reader import RawMessage

__all__ = [
    "LogWriter",
    "ChannelError",
    "COMPRESSIONS",
    "PARTIAL_SUFFIX",
    "check_output_path",
    "check_output",
    "write_text_atomic",
    "partial_path",
]

COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
PROFILE = "trackctl"
MAX_CHANNELS = 65535  # MCAP channel ids are uint16 (id 0 is valid)
PARTIAL_SUFFIX = ".partial"
MAX_LOG_TIME_NS = (1 << 64) - 1


class ChannelError(OutputError):
    """One message cannot go on its topic (another schema holds it, or the log has no channel id
    left); nothing was written and the writer can go on with other messages."""


def partial_path(path: str | os.PathLike[str], suffix: str = PARTIAL_SUFFIX) -> Path:
    """Where the log for ``path`` is written until it is finished."""
    path = Path(path)
    return path.with_name(path.name + suffix)


def _open_locked(partial: Path, final: Path) -> int:
    """Create and exclusively lock ``partial``; the fd of an empty, locked regular file."""
    while True:
        try:
            fd = os.open(partial, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        except OSError as err:
            raise OutputError(f"{final}: cannot create {partial.name} ({err.strerror})") from err
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise OutputError(f"{partial}: is not a regular file; remove it and try again")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise OutputError(
                    f"{final}: another process is writing it ({partial.name} is locked); "
                    "wait for it or choose another output"
                ) from None
            try:
                same = os.stat(partial).st_ino == st.st_ino
            except FileNotFoundError:
                same = False
            if not same:  # the previous writer renamed it away between our open and lock
                os.close(fd)
                continue
            if os.fstat(fd).st_size > 0:
                raise OutputError(
                    f"{partial}: holds an unfinished log from an earlier run that was stopped "
                    f"(killed or out of disk); finish it with `trackctl recover {partial}` "
                    "or delete it"
                )
            return fd
        except BaseException:
            os.close(fd)
            raise


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
        keep_partial: on failure keep ``OUT.partial`` (a live recording: it holds data) instead
            of deleting it.
        partial_suffix: suffix of the file written until :meth:`close`.

    Raises:
        OutputError: the output is an input, not a regular file or new path, its folder is
            missing or unwritable, another process writes it, or an unfinished ``OUT.partial``
            from an earlier run is in the way.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        inputs: Iterable[str | os.PathLike[str]] = (),
        compression: str = "zstd",
        chunk_size: int = 1 << 20,
        keep_partial: bool = False,
        partial_suffix: str = PARTIAL_SUFFIX,
    ) -> None:
        self.path = Path(path)
        self._target = check_output(self.path, inputs)  # the output rule: logs/output.py
        if compression not in COMPRESSIONS:
            raise OutputError(
                f"compression {compression!r} unknown; expected one of {sorted(COMPRESSIONS)}"
            )
        self.partial_path = partial_path(self._target, partial_suffix)
        self.keep_partial = keep_partial
        with signals_deferred():  # created and registered as one step (see logs/output.py)
            fd = _open_locked(self.partial_path, self.path)
            if not keep_partial:
                track_unfinished(self.partial_path)
        self._stream: IO[bytes] = os.fdopen(fd, "wb")
        self._writer = Writer(
            self._stream,
            chunk_size=chunk_size,
            compression=COMPRESSIONS[compression],
            enable_data_crcs=True,  # so readers can verify the whole data section
        )
        try:
            self._writer.start(profile=PROFILE, library="trackctl")
        except OSError as err:
            self._fail(err, "start")
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
            ChannelError: the topic was already registered with another schema or encoding, or
                the log holds :data:`MAX_CHANNELS` channels already.
        """
        known = self._channels.get(topic)
        if known is not None:
            cid, known_schema, known_enc = known
            if (known_schema, known_enc) != (schema_name, message_encoding):
                raise ChannelError(
                    f"{topic}: already written with schema {known_schema} ({known_enc}); "
                    f"cannot also write {schema_name} ({message_encoding}) on it"
                )
            return cid
        if len(self._channels) >= MAX_CHANNELS:
            raise ChannelError(
                f"{self.path}: topic {topic} would be channel {len(self._channels) + 1}; an MCAP "
                f"log holds at most {MAX_CHANNELS} channels (16-bit channel ids)"
            )
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

    def check_log_time(self, log_time_ns: int) -> None:
        """Raise :class:`OutputError` unless ``log_time_ns`` fits MCAP's uint64."""
        if not 0 <= log_time_ns <= MAX_LOG_TIME_NS:
            raise OutputError(
                f"{self.path}: log time {log_time_ns} ns is outside 0..2^64-1 (MCAP's uint64)"
            )

    def _add(self, cid: int, data: bytes, log_time_ns: int, publish_time_ns: int | None) -> None:
        if self._closed:
            raise OutputError(f"{self.path}: writer is closed")
        log_time_ns = int(log_time_ns)
        publish = log_time_ns if publish_time_ns is None else int(publish_time_ns)
        if not (0 <= log_time_ns <= MAX_LOG_TIME_NS and 0 <= publish <= MAX_LOG_TIME_NS):
            raise OutputError(
                f"{self.path}: log time {log_time_ns} ns is outside 0..2^64-1 (MCAP's uint64)"
            )
        try:
            self._writer.add_message(
                channel_id=cid, log_time=log_time_ns, publish_time=publish, data=data
            )
        except OSError as err:
            self._fail(err, "write")
        self.message_count += 1

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """Add a metadata record (values are stored as strings, as MCAP requires)."""
        try:
            self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
        except OSError as err:
            self._fail(err, "write")

    def add_attachment(
        self,
        name: str,
        data: bytes,
        media_type: str = "application/octet-stream",
        log_time_ns: int = 0,
    ) -> None:
        """Attach a file (calibration source, configuration...) to the log."""
        try:
            self._writer.add_attachment(
                create_time=log_time_ns,
                log_time=log_time_ns,
                name=name,
                media_type=media_type,
                data=data,
            )
        except OSError as err:
            self._fail(err, "write")

    # -- lifecycle ----------------------------------------------------------------------------
    def flush(self) -> None:
        """Close the chunk in progress and hand everything written so far to the OS.

        A live recorder calls this about once a second: after a ``kill -9`` the partial file then
        holds every message up to the last flush, readable by ``info``/``replay``/``recover``.
        """
        if self._closed:
            return
        try:
            self._writer.flush()  # type: ignore[no-untyped-call]
        except OSError as err:
            self._fail(err, "write")

    def _fail(self, err: OSError, doing: str) -> None:
        """Drop (or keep, for a live recording) the partial file; raise a one-line OutputError."""
        self.abort()
        kept = (
            f"; what was written so far is in {self.partial_path} (`trackctl recover` finishes it)"
            if self.keep_partial and self.partial_path.exists()
            else ""
        )
        reason = err.strerror or str(err)
        raise OutputError(f"{self.path}: cannot {doing} the log ({reason}){kept}") from err

    def close(self) -> Path:
        """Finish the log, flush it to disk and move it to its final path."""
        if self._closed:
            return self.path
        try:
            self._writer.finish()  # type: ignore[no-untyped-call]
            self._stream.flush()
            os.fsync(self._stream.fileno())
            with signals_deferred():
                os.replace(self.partial_path, self._target)  # still locked while renamed
                forget_unfinished(self.partial_path)
        except OSError as err:
            self._fail(err, "finish")
        self._closed = True
        try:
            self._stream.close()  # releases the lock
        except OSError as err:
            if err.errno != errno.EBADF:
                raise OutputError(f"{self.path}: cannot close the log ({err.strerror})") from err
        return self.path

    def abort(self) -> None:
        """Drop the unfinished log (kept as ``OUT.partial`` with ``keep_partial``); the output
        path is left as it was."""
        if self._closed:
            return
        self._closed = True
        keep = self.keep_partial and self.message_count > 0
        with signals_deferred():
            try:
                if keep:
                    self._stream.flush()
                else:
                    self.partial_path.unlink(missing_ok=True)
                    forget_unfinished(self.partial_path)
            except OSError:
                pass
            finally:
                try:
                    self._stream.close()
                except OSError:
                    pass

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
