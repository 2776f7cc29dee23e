"""``trackctl replay``."""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Iterable
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer
from rich.live import Live
from rich.table import Table

from trackctl.cli.common import check_topics, check_window, console, split_csv, stderr
from trackctl.errors import InputError
from trackctl.logs.jsonl import attachment_line, metadata_line
from trackctl.logs.reader import LogReader, RawMessage
from trackctl.logs.replay import RateMeter, UdpSink, parse_host_port, replay_jsonl


class Format(StrEnum):
    jsonl = "jsonl"
    table = "table"


def _table(meter: RateMeter, title: str) -> Table:
    table = Table(title=title, show_edge=False)
    for col in ("topic", "schema", "count", "rate Hz", "log time s"):
        table.add_column(col, justify="left" if col in ("topic", "schema") else "right")
    for topic, schema, count, rate, last in meter.rows():
        table.add_row(topic, schema, str(count), f"{rate:.1f}", f"{last / 1e9:.3f}")
    return table


def _write_jsonl(
    reader: LogReader,
    stream: Iterable[tuple[RawMessage, str]],
    records: bool,
    sink: UdpSink | None,
    paced: bool,
) -> int:
    """JSON lines on stdout (after the metadata and attachment records with ``records``), each
    also sent to ``sink``; paced lines are flushed one by one. Returns the messages written."""
    write = sys.stdout.write
    if records:
        for name, md in reader.metadata().items():
            write(metadata_line(name, md) + "\n")
        for name, (media_type, data) in reader.attachments().items():
            write(attachment_line(name, media_type, data) + "\n")
    n = 0
    for _, line in stream:
        write(line)
        write("\n")
        if paced:  # each line leaves when its time comes, not a buffer later
            sys.stdout.flush()
        if sink is not None:
            sink.send(line)
        n += 1
    sys.stdout.flush()
    return n


def replay(
    log: Annotated[Path, typer.Argument(help="MCAP log to play back.")],
    topics: Annotated[
        list[str] | None,
        typer.Option("--topics", help="Topics to play (repeat or comma-separate); default all."),
    ] = None,
    start: Annotated[
        float | None, typer.Option(help="Start, seconds after the log's first message.")
    ] = None,
    end: Annotated[
        float | None, typer.Option(help="End, seconds after the log's first message.")
    ] = None,
    speed: Annotated[
        float,
        typer.Option(
            help="Playback speed: 1.0 real time, 2.0 twice as fast, 0 as fast as possible."
        ),
    ] = 1.0,
    fmt: Annotated[
        Format, typer.Option("--format", help="jsonl on stdout, or a live table.")
    ] = Format.jsonl,
    udp: Annotated[
        str | None,
        typer.Option(
            "--udp", metavar="HOST:PORT", help="Also send each JSON line as a UDP datagram."
        ),
    ] = None,
    records: Annotated[
        bool,
        typer.Option(
            "--records",
            help="jsonl: first emit the log's metadata and attachments as "
            '{"type":"metadata"|"attachment",...} lines (record --stdin restores them).',
        ),
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No notes on stderr.")] = False,
) -> None:
    """Play a log back in log-time order, paced or as fast as possible.

    Example: trackctl replay run.mcap --topics /cam0/detections --speed 0 | head
    """
    check_window(start, end)
    if not math.isfinite(speed) or speed < 0:
        raise InputError(f"--speed {speed}: expected a number >= 0 (0 = as fast as possible)")
    sink = UdpSink(*parse_host_port(udp)) if udp else None
    reader = LogReader(log)
    wanted = split_csv(topics)
    check_topics(reader, wanted)
    origin = reader.start_ns or 0
    stream = replay_jsonl(reader, wanted, _log_time(origin, start), _log_time(origin, end), speed)
    try:
        if fmt is Format.jsonl:
            _write_jsonl(reader, stream, records, sink, paced=speed > 0)
        else:
            _show_table(stream, sink, str(log))
    except BrokenPipeError:
        # `replay | head`: the reader went away; stop quietly like other Unix tools.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return
    finally:
        if sink is not None:
            sink.close()
    if sink is not None:
        _warn_sink(sink, udp, quiet)


def _log_time(origin: int, seconds: float | None) -> int | None:
    """``--start``/``--end`` (seconds after the first message) as log time, ns."""
    return None if seconds is None else origin + int(round(seconds * 1e9))


def _show_table(stream: Iterable[tuple[RawMessage, str]], sink: UdpSink | None, title: str) -> int:
    """A live table of the topics' counts and rates, each line also sent to ``sink``.
    Returns the messages played."""
    meter = RateMeter()
    n = 0
    last_draw = 0.0
    with Live(
        _table(meter, title), console=console(), refresh_per_second=4, transient=False
    ) as live:
        for raw, line in stream:
            meter.add(raw)
            if sink is not None:
                sink.send(line)
            n += 1
            now = time.monotonic()
            if now - last_draw > 0.2:
                live.update(_table(meter, title))
                last_draw = now
        live.update(_table(meter, title))
    return n


def _warn_sink(sink: UdpSink, udp: str | None, quiet: bool) -> None:
    """Warnings about datagrams that failed (always) or were too large (not with --quiet)."""
    if sink.failed:
        stderr.print(
            f"[yellow]warning:[/] {sink.failed} datagrams to {udp} failed ({sink.last_error})",
            markup=True,
        )
    if sink.skipped and not quiet:
        stderr.print(
            f"[yellow]warning:[/] {sink.skipped} messages larger than a UDP datagram were not sent",
            markup=True,
        )
