"""Playback of a log: paced iteration, JSON lines, per-topic rates, UDP datagrams."""

from __future__ import annotations

import socket
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

from trackctl.errors import InputError
from trackctl.logs.codecs import Codec
from trackctl.logs.jsonl import to_jsonl
from trackctl.logs.reader import LogReader, RawMessage

__all__ = ["paced", "replay_jsonl", "RateMeter", "UdpSink", "parse_host_port"]


def paced(
    messages: Iterable[RawMessage],
    speed: float,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> Iterator[RawMessage]:
    """Yield each message when its log time comes, ``speed`` times real time (0 = no waiting)."""
    if speed < 0:
        raise InputError(f"--speed must be >= 0 (0 = as fast as possible), got {speed}")
    if speed == 0:
        yield from messages
        return
    wall0 = log0 = None
    for msg in messages:
        if wall0 is None:
            wall0, log0 = clock(), msg.log_time_ns
        else:
            due = wall0 + (msg.log_time_ns - log0) / 1e9 / speed  # type: ignore[operator]
            delay = due - clock()
            if delay > 0:
                sleep(delay)
        yield msg


def replay_jsonl(
    reader: LogReader,
    topics: Iterable[str] | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
    speed: float = 0.0,
) -> Iterator[tuple[RawMessage, str]]:
    """``(message, JSON line)`` pairs in log-time order, paced by ``speed``.

    A message that cannot be turned into JSON (a foreign log's non-UTF-8 "JSON", a protobuf that
    does not parse) is skipped with a warning on the reader, counted in ``reader.decode_errors``.
    """
    codecs: dict[tuple[str, str, bytes], Codec] = {}
    for raw in paced(reader.raw(topics, start_ns, end_ns), speed):
        key = (raw.schema_name, raw.message_encoding, raw.schema_data)
        codec = codecs.get(key)
        if codec is None:
            codec = codecs[key] = reader.codec(raw)
        try:
            line = to_jsonl(raw, codec)
        except Exception as err:  # noqa: BLE001 - foreign bytes may break any decoder
            reader.skip_undecodable(raw, err)
            continue
        yield raw, line


@dataclass
class _TopicRate:
    count: int = 0
    recent: deque[float] = field(default_factory=deque)
    schema: str = ""
    last_log_ns: int = 0
    bytes: int = 0


class RateMeter:
    """Per-topic counts and message rates over a sliding wall-clock window (live table)."""

    def __init__(self, window_s: float = 1.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.window_s = window_s
        self.clock = clock
        self.topics: dict[str, _TopicRate] = {}

    def add(self, raw: RawMessage) -> None:
        st = self.topics.get(raw.topic)
        if st is None:
            st = self.topics[raw.topic] = _TopicRate(schema=raw.schema_name)
        now = self.clock()
        st.count += 1
        st.bytes += len(raw.data)
        st.last_log_ns = raw.log_time_ns
        st.recent.append(now)
        while st.recent and st.recent[0] < now - self.window_s:
            st.recent.popleft()

    def rows(self) -> list[tuple[str, str, int, float, int]]:
        """``(topic, schema, count, rate_hz, last_log_time_ns)`` per topic, sorted by topic."""
        now = self.clock()
        out = []
        for topic in sorted(self.topics):
            st = self.topics[topic]
            while st.recent and st.recent[0] < now - self.window_s:
                st.recent.popleft()
            out.append((topic, st.schema, st.count, len(st.recent) / self.window_s, st.last_log_ns))
        return out


def parse_host_port(value: str) -> tuple[str, int]:
    """``HOST:PORT`` -> (host, port)."""
    host, sep, port = value.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"--udp {value!r}: expected HOST:PORT, e.g. 127.0.0.1:9870")
    return host, int(port)


class UdpSink:
    """Sends JSON lines as UDP datagrams; lines over the datagram limit are skipped and counted."""

    MAX_DATAGRAM = 65_507

    def __init__(self, host: str, port: int) -> None:
        try:
            info = socket.getaddrinfo(host, port, socket.AF_UNSPEC, socket.SOCK_DGRAM)
        except (socket.gaierror, UnicodeError, OverflowError) as err:
            reason = getattr(err, "strerror", None) or str(err)
            raise InputError(f"--udp {host}:{port}: cannot resolve the host ({reason})") from None
        family, _, _, _, address = info[0]
        self.address = address
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        self.sent = 0
        self.skipped = 0
        self.failed = 0
        self.last_error = ""

    def send(self, line: str) -> bool:
        """Send one line; False when it is too large or the network refuses it (counted)."""
        data = line.encode() + b"\n"
        if len(data) > self.MAX_DATAGRAM:
            self.skipped += 1
            return False
        try:
            self.sock.sendto(data, self.address)
        except OSError as err:  # unreachable network, no route: the replay itself goes on
            self.failed += 1
            self.last_error = err.strerror or str(err)
            return False
        self.sent += 1
        return True

    def close(self) -> None:
        self.sock.close()
