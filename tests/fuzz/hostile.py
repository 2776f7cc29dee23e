"""Builders of hostile inputs, shared by the fuzz tests and ``benchmarks/hostile_inputs.py``:
MCAP logs whose content lies (a channel's schema name swapped, garbage metadata values, huge
numbers in JSON payloads) and a small log whose chunk header claims 3 GB uncompressed.

Each builder writes a new file from a sample log with the plain ``mcap`` writer (trackctl's own
writer refuses what these files hold) and never touches the sample.
"""

from __future__ import annotations

import json
import random
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

__all__ = [
    "LogParts",
    "read_parts",
    "write_parts",
    "swap_schema",
    "garbage_metadata",
    "hostile_numbers",
    "claimed_chunk_log",
    "GARBAGE_VALUES",
]


@dataclass
class LogParts:
    """Everything a log holds, as plain values (editable, then written back)."""

    schemas: dict[int, tuple[str, str, bytes]]
    """id -> (name, encoding, data)"""
    channels: dict[int, tuple[str, str, int]]
    """id -> (topic, message encoding, schema id)"""
    messages: list[tuple[int, int, int, bytes]]
    """(channel id, log time, publish time, data)"""
    metadata: dict[str, dict[str, str]]
    attachments: list[tuple[str, str, int, bytes]]
    """(name, media type, log time, data)"""


def read_parts(path: Path) -> LogParts:
    """The parts of a (well-formed) log."""
    with path.open("rb") as f:
        reader = make_reader(f)
        schemas: dict[int, tuple[str, str, bytes]] = {}
        channels: dict[int, tuple[str, str, int]] = {}
        messages = []
        for schema, channel, msg in reader.iter_messages(log_time_order=True):
            if schema is not None:
                schemas[schema.id] = (schema.name, schema.encoding, schema.data)
            channels[channel.id] = (channel.topic, channel.message_encoding, channel.schema_id)
            messages.append((channel.id, msg.log_time, msg.publish_time, msg.data))
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        attachments = [
            (a.name, a.media_type, a.log_time, a.data) for a in reader.iter_attachments()
        ]
    return LogParts(schemas, channels, messages, metadata, attachments)


def write_parts(
    parts: LogParts, path: Path, compression: CompressionType = CompressionType.ZSTD
) -> Path:
    """Write ``parts`` as a log at ``path`` (chunked, indexed)."""
    with path.open("wb") as f:
        w = McapWriter(f, compression=compression, chunk_size=64 * 1024)
        w.start(profile="", library="tests.fuzz.hostile")
        sids = {sid: w.register_schema(n, e, d) for sid, (n, e, d) in parts.schemas.items()}
        cids = {
            cid: w.register_channel(topic, enc, sids.get(sid, 0))
            for cid, (topic, enc, sid) in parts.channels.items()
        }
        for cid, log_time, publish, data in parts.messages:
            w.add_message(cids[cid], log_time=log_time, data=data, publish_time=publish)
        for name, record in parts.metadata.items():
            w.add_metadata(name, record)
        for name, media, log_time, data in parts.attachments:
            w.add_attachment(log_time, log_time, name, media, data)
        w.finish()
    return path


def swap_schema(src: Path, dst: Path, topic: str, schema_name: str) -> Path:
    """``src`` with ``topic``'s channel claiming the schema ``schema_name`` (taken from another
    channel of the log when one has it, else a JSON schema of that name): the payloads stay
    what they were, the schema lies."""
    parts = read_parts(src)
    by_name = {name: sid for sid, (name, _, _) in parts.schemas.items()}
    sid = by_name.get(schema_name)
    if sid is None:
        sid = max(parts.schemas, default=0) + 1
        parts.schemas[sid] = (schema_name, "jsonschema", b"{}")
    for cid, (t, enc, _) in list(parts.channels.items()):
        if t == topic:
            parts.channels[cid] = (t, enc, sid)
    return write_parts(parts, dst)


GARBAGE_VALUES = (
    "nan",
    "inf",
    "-1",
    "0",
    "1e400",
    "9" * 5000,
    "",
    "{",
    "[]",
    '{"size_m": [1], "walls": 3}',
    "null",
    "x-y",
    "1-2-3",
    "\x00\xff",
    "2001-01-01",
)
"""Metadata values no real record holds."""


def garbage_metadata(src: Path, dst: Path, rng: random.Random, n: int = 3) -> Path:
    """``src`` with ``n`` metadata values (existing keys, or site keys processors read)
    replaced by :data:`GARBAGE_VALUES`."""
    parts = read_parts(src)
    targets = [(name, key) for name, rec in parts.metadata.items() for key in rec]
    targets += [
        ("robot/r1", "ticks_per_m"),
        ("robot/r1", "wheel_base_m"),
        ("robot/r1", "front_hue"),
        ("smirror/floorplan", "plan"),
        ("smirror/requesters", "count"),
        ("bridgeloc", "tag_n"),
        ("bridgeloc", "tag_size_m"),
        ("bridgeloc", "max_range_m"),
    ]
    for _ in range(n):
        name, key = rng.choice(targets)
        parts.metadata.setdefault(name, {})[key] = rng.choice(GARBAGE_VALUES)
    return write_parts(parts, dst)


_HOSTILE_NUMBERS: tuple[Callable[[random.Random], Any], ...] = (
    lambda r: 10**30,
    lambda r: -(10**25),
    lambda r: int("9" * 400),
    lambda r: 1e308,
    lambda r: 1e14,
    lambda r: -1,
    lambda r: 0,
    lambda r: r.choice(["1", "x", None, [], {}]),
)


def _walk(obj: Any) -> Iterator[tuple[Any, Any]]:
    """(container, key) of every number in a JSON value."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            if isinstance(v, int | float) and not isinstance(v, bool):
                yield obj, k
            else:
                yield from _walk(v)
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            if isinstance(v, int | float) and not isinstance(v, bool):
                yield obj, i
            else:
                yield from _walk(v)


def hostile_numbers(src: Path, dst: Path, rng: random.Random, share: float = 0.05) -> Path:
    """``src`` with a ``share`` of its JSON messages holding one number replaced by a huge,
    negative or wrongly typed value (NaN and inf are not JSON: written as ``NaN``/``Infinity``,
    which Python's reader accepts and others refuse)."""
    parts = read_parts(src)
    json_channels = {cid for cid, (_, enc, _) in parts.channels.items() if enc == "json"}
    out = []
    for cid, log_time, publish, data in parts.messages:
        if cid in json_channels and rng.random() < share:
            obj = json.loads(data)
            spots = list(_walk(obj))
            if spots:
                holder, key = rng.choice(spots)
                if rng.random() < 0.2:
                    holder[key] = float(rng.choice(["nan", "inf", "-inf"]))
                else:
                    holder[key] = rng.choice(_HOSTILE_NUMBERS)(rng)
                data = json.dumps(obj).encode()
        out.append((cid, log_time, publish, data))
    parts.messages = out
    return write_parts(parts, dst)


def claimed_chunk_log(dst: Path, claim: int = 3 << 30, target_bytes: int = 200_000) -> Path:
    """A ~200 kB log of incompressible messages in lz4 chunks, the first chunk's header claiming
    ``claim`` bytes uncompressed (3 GB: what a reader that trusts it would allocate)."""
    rng = random.Random(45)
    with dst.open("wb") as f:
        w = McapWriter(f, compression=CompressionType.LZ4, chunk_size=target_bytes // 2)
        w.start(profile="", library="tests.fuzz.hostile")
        sid = w.register_schema("blob", "jsonschema", b"{}")
        cid = w.register_channel("/blob", "json", sid)
        payload_size, t = 1000, 0
        while f.tell() < target_bytes - 2 * payload_size:
            t += 1_000_000
            text = json.dumps({"x": rng.randbytes(payload_size // 2).hex()}).encode()
            w.add_message(cid, log_time=t, data=text, publish_time=t)
        w.finish()
    data = bytearray(dst.read_bytes())
    pos = 8
    while pos + 9 <= len(data):
        op, length = data[pos], int.from_bytes(data[pos + 1 : pos + 9], "little")
        if op == 0x06:  # Chunk: start, end, then the uncompressed size
            data[pos + 9 + 16 : pos + 9 + 24] = struct.pack("<Q", claim)
            break
        pos += 9 + length
    dst.write_bytes(bytes(data))
    return dst


@dataclass(frozen=True)
class Run:
    """One trackctl run in a child process."""

    code: int
    stdout: str
    stderr: str
    peak_rss_mb: float
    """The child's own peak resident memory (``wait4``'s rusage: this child only)."""


_MEASURE = """
import os, resource, subprocess, sys
code = subprocess.call([sys.executable, "-m", "trackctl", *sys.argv[2:]])
with open(sys.argv[1], "w") as f:
    f.write(str(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss))
sys.exit(code)
"""
"""A small process between the caller and trackctl: Linux carries the high-water RSS of the
process that forks into the child it execs, so a child of a large process (pytest) would report
the parent's peak; this one is small, and its RUSAGE_CHILDREN is trackctl's own peak."""


def run_measured(
    args: list[str], cwd: Path | None = None, timeout_s: float = 300.0, stdin: Path | None = None
) -> Run:
    """``python -m trackctl ARGS`` in a child process (``stdin``: a file to read from), with its
    exit code, output and peak RSS (``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss`` taken by
    a small intermediate process: KiB on Linux)."""
    import os
    import subprocess
    import sys
    import tempfile

    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root), "COLUMNS": "200"}
    with (
        tempfile.TemporaryDirectory() as tmp,
        tempfile.TemporaryFile() as out,
        tempfile.TemporaryFile() as err,
        stdin.open("rb") if stdin is not None else open(os.devnull, "rb") as inp,
    ):
        rss = Path(tmp) / "rss"
        try:
            code = subprocess.run(
                [sys.executable, "-c", _MEASURE, str(rss), *args],
                stdout=out,
                stderr=err,
                stdin=inp,
                cwd=cwd or root,
                env=env,
                timeout=timeout_s,
                check=False,
            ).returncode
        except subprocess.TimeoutExpired:
            code = -9
        out.seek(0)
        err.seek(0)
        peak_kib = float(rss.read_text()) if rss.is_file() else 0.0
        return Run(
            code,
            out.read().decode(errors="replace"),
            err.read().decode(errors="replace"),
            peak_kib / 1024,
        )
