"""Live JSON lines (``record --stdin`` / ``--udp``) into a log: no line ends a recording.

Every line or datagram that cannot be recorded (not JSON, a number out of range, a message that
does not fit its schema, a topic already written with another schema, a channel beyond MCAP's
65535, a line longer than :data:`MAX_LINE_BYTES`) is rejected, counted and reported (the first
:data:`WARN_FIRST` one by one, then at most one line every :data:`WARN_EVERY_S` seconds saying how
many more), and the recording goes on. SIGINT, SIGTERM and SIGHUP end it between two lines, so the
log is finished normally; a second signal interrupts at once (the log is still finished).
"""

from __future__ import annotations

import os
import select
import signal
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from trackctl.errors import InputError, TrackctlError
from trackctl.logs.jsonl import AttachmentLine, JsonlRecord, MetadataLine, parse_line
from trackctl.logs.writer import ChannelError, LogWriter

__all__ = [
    "LiveStats",
    "Line",
    "Oversize",
    "UdpSource",
    "StreamSource",
    "StopFlag",
    "record_live",
    "stop_on_signals",
    "MAX_LINE_BYTES",
    "FLUSH_EVERY_S",
]

MAX_LINE_BYTES = 32 << 20
"""Longest JSON line recorded (an attachment line of a 24 MB file); a longer one is skipped as it
streams in, without being held in memory, and rejected."""
FLUSH_EVERY_S = 1.0  # a live log loses at most this much to kill -9
WARN_FIRST = 20
"""Rejected lines reported one by one; after these, one report every :data:`WARN_EVERY_S`."""
WARN_EVERY_S = 5.0
_TICK_S = 0.25  # how often an idle source wakes the recorder to flush
_READ_BYTES = 1 << 20


@dataclass(frozen=True, slots=True)
class Oversize:
    """Stands for a line longer than the source's limit (its bytes were dropped unread)."""

    limit: int


Line = tuple[bytes | str | Oversize, str, int]  # (line, where it came from, line number)


@dataclass
class LiveStats:
    """What a live recording received."""

    counts: Counter[str] = field(default_factory=Counter)
    rejected: int = 0
    interrupted: bool = False
    metadata: int = 0
    attachments: int = 0


class StopFlag:
    """Set by a signal: the recorder stops between two lines (see :func:`stop_on_signals`)."""

    def __init__(self) -> None:
        self.signal: str | None = None

    def __bool__(self) -> bool:
        return self.signal is not None


@contextmanager
def stop_on_signals(flag: StopFlag) -> Iterator[StopFlag]:
    """SIGINT, SIGTERM and SIGHUP set ``flag`` (the live loop then ends cleanly); a second one
    raises KeyboardInterrupt. Main thread only (elsewhere signals cannot be caught: a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def handler(signum: int, frame: Any) -> None:
        if flag:
            raise KeyboardInterrupt(signal.Signals(signum).name)
        flag.signal = signal.Signals(signum).name

    signums = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous = {s: signal.signal(s, handler) for s in signums}
    try:
        yield flag
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


class UdpSource:
    """JSON lines from UDP datagrams on a local port (one or more lines per datagram).

    Iterating yields lines, and ``None`` about every quarter second while no datagram arrives, so
    the recorder can flush its chunk even when the stream goes quiet.
    """

    def __init__(self, port: int, host: str = "127.0.0.1") -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        # A large receive buffer so bursts are not dropped while a message is being written.
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        try:
            self.sock.bind((host, port))
        except (OSError, OverflowError) as err:
            self.sock.close()
            reason = getattr(err, "strerror", None) or str(err)
            raise InputError(f"--udp {port}: cannot bind {host}:{port} ({reason})") from err
        self.sock.settimeout(_TICK_S)
        self.address = self.sock.getsockname()
        self.where = f"udp:{self.address[1]}"
        self._n = 0

    def _lines(self, datagram: bytes, sender: Any) -> Iterator[Line]:
        origin = f" from {sender[0]}:{sender[1]}" if sender else ""
        for line in datagram.splitlines():
            if line.strip():
                self._n += 1
                # "udp:9870 line 4 from 127.0.0.1:50123": the sender's port is not a line number
                yield line, f"{self.where} line {self._n}{origin}", 0

    def __iter__(self) -> Iterator[Line | None]:
        while True:
            try:
                datagram, sender = self.sock.recvfrom(65535)
            except TimeoutError:
                yield None
                continue
            yield from self._lines(datagram, sender)

    def drain(self) -> Iterator[Line]:
        """Datagrams already received by the kernel but not yet read."""
        self.sock.setblocking(False)
        while True:
            try:
                datagram, sender = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            yield from self._lines(datagram, sender)

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


class _LineBuffer:
    """Splits blocks into lines in linear time (each byte is scanned once; a line is joined once)
    and drops a line longer than ``limit`` as it arrives instead of holding it."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.parts: list[bytes] = []
        self.size = 0
        self.oversize = False

    def _end(self, tail: bytes) -> bytes | Oversize:
        line: bytes | Oversize = (
            Oversize(self.limit)
            if self.oversize or self.size + len(tail) > self.limit
            else b"".join([*self.parts, tail])
        )
        self.parts, self.size, self.oversize = [], 0, False
        return line

    def _keep(self, rest: bytes) -> None:
        if self.oversize or self.size + len(rest) > self.limit:
            self.parts, self.size, self.oversize = [], 0, True
        elif rest:
            self.parts.append(rest)
            self.size += len(rest)

    def feed(self, block: bytes) -> Iterator[bytes | Oversize]:
        start = 0
        while (nl := block.find(b"\n", start)) >= 0:
            yield self._end(block[start:nl])
            start = nl + 1
        self._keep(block[start:])

    def finish(self) -> Iterator[bytes | Oversize]:
        if self.parts or self.oversize:
            yield self._end(b"")


class StreamSource:
    """JSON lines from a file descriptor (stdin), with ``None`` ticks while it is idle or while
    a long line streams in."""

    def __init__(
        self, fd: int, where: str = "<stdin>", max_line_bytes: int = MAX_LINE_BYTES
    ) -> None:
        self.fd = fd
        self.where = where
        self.max_line_bytes = max_line_bytes

    def __iter__(self) -> Iterator[Line | None]:
        buf = _LineBuffer(self.max_line_bytes)
        lineno = 0
        while True:
            try:
                ready, _, _ = select.select([self.fd], [], [], _TICK_S)
            except (OSError, ValueError):  # not selectable (some Windows-like fds): block
                ready = [self.fd]
            if not ready:
                yield None
                continue
            block = os.read(self.fd, _READ_BYTES)
            if not block:
                break
            for line in buf.feed(block):
                lineno += 1
                yield line, self.where, lineno
            yield None  # lets a signal stop the recording inside a long line
        for line in buf.finish():
            yield line, self.where, lineno + 1


class _Rejects:
    """Counts rejected lines and reports them, rate-limited."""

    def __init__(self, on_reject: Callable[[str], None] | None) -> None:
        self.on_reject = on_reject
        self.count = 0
        self.unreported = 0
        self.last_report = 0.0

    def __call__(self, msg: str) -> None:
        self.count += 1
        if self.on_reject is None:
            return
        now = time.monotonic()
        if self.count > WARN_FIRST and now - self.last_report < WARN_EVERY_S:
            self.unreported += 1
            return
        more = f" (and {self.unreported} more rejected lines not shown)" if self.unreported else ""
        self.on_reject(msg + more)
        self.unreported = 0
        self.last_report = now

    def finish(self) -> None:
        if self.unreported and self.on_reject is not None:
            self.on_reject(f"{self.unreported} more lines (not shown one by one)")
            self.unreported = 0


def _at(where: str, lineno: int) -> str:
    return f"{where}:{lineno}" if lineno else where


class _Recorder:
    """Writes one parsed line at a time; any line that cannot be written is rejected."""

    def __init__(self, writer: LogWriter, rejects: _Rejects) -> None:
        self.writer = writer
        self.rejects = rejects
        self.stats = LiveStats()

    def _parse(
        self, line: bytes | str, where: str, lineno: int
    ) -> JsonlRecord | MetadataLine | AttachmentLine | None:
        try:
            rec = parse_line(line, where, lineno)
            if isinstance(rec, JsonlRecord):
                self.writer.check_log_time(rec.log_time_ns)
            return rec
        except TrackctlError as err:
            self.rejects(str(err))
        except Exception as err:  # noqa: BLE001 - parsing writes nothing: any failure is the line's
            self.rejects(f"{_at(where, lineno)}: cannot parse ({type(err).__name__}: {err})"[:500])
        return None

    def take(self, line: bytes | str | Oversize, where: str, lineno: int) -> None:
        if isinstance(line, Oversize):
            self.rejects(f"{_at(where, lineno)}: line longer than {line.limit} bytes (skipped)")
            return
        if not line.strip():
            return
        rec = self._parse(line, where, lineno)
        if rec is None:
            return
        stats = self.stats
        if isinstance(rec, MetadataLine):
            self.writer.add_metadata(rec.name, rec.metadata)
            stats.metadata += 1
        elif isinstance(rec, AttachmentLine):
            self.writer.add_attachment(rec.name, rec.data, rec.media_type, rec.log_time_ns)
            stats.attachments += 1
        else:
            try:
                self.writer.write_encoded(rec.topic, rec.codec, rec.data, rec.log_time_ns)
            except ChannelError as err:  # checked before anything is written: the log goes on
                self.rejects(f"{_at(where, lineno)}: {err}")
                return
            stats.counts[rec.topic] += 1


def record_live(
    writer: LogWriter,
    lines: Iterable[Line | None],
    on_reject: Callable[[str], None] | None = None,
    drain: Callable[[], Iterable[Line]] | None = None,
    flush_every_s: float = FLUSH_EVERY_S,
    stop: StopFlag | None = None,
) -> LiveStats:
    """Write JSON lines as they arrive until the source ends, ``stop`` is set (a signal, see
    :func:`stop_on_signals`) or Ctrl-C (KeyboardInterrupt).

    A line that cannot be recorded is rejected, reported through ``on_reject`` (rate-limited)
    with its line number or sender, topic and field where known, counted, and recording goes on:
    a live sensor stream must not be lost to one malformed message. The writer is flushed at
    least every ``flush_every_s`` (``None`` items are idle ticks from the source), so a killed
    recorder loses at most that much. When stopped, lines already received (``drain``) are still
    written, and the caller closes ``writer`` into a valid log.
    """
    rejects = _Rejects(on_reject)
    rec = _Recorder(writer, rejects)
    last_flush = time.monotonic()
    try:
        for item in lines:
            if item is not None:
                rec.take(*item)
            if stop:
                rec.stats.interrupted = True
                break
            now = time.monotonic()
            if now - last_flush >= flush_every_s:
                writer.flush()
                last_flush = now
    except KeyboardInterrupt:
        rec.stats.interrupted = True
    if rec.stats.interrupted and drain is not None:
        try:
            for line, where, lineno in drain():
                rec.take(line, where, lineno)
        except KeyboardInterrupt:
            pass
    rejects.finish()
    rec.stats.rejected = rejects.count
    return rec.stats
