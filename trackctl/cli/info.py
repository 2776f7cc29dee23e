"""``trackctl info``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from trackctl.cli.common import JsonOption, console, print_json
from trackctl.logs.info import log_info
from trackctl.logs.reader import LogReader


def info(
    log: Annotated[Path, typer.Argument(help="MCAP log to describe.")],
    json_out: JsonOption = False,
) -> None:
    """Topics, schemas, message counts, rates, time span and metadata of a log.

    Example: trackctl info sample_logs/demo.mcap
    """
    data = log_info(LogReader(log))
    if json_out:
        print_json(data)
        return
    screen = console()
    screen.print(
        f"[bold]{data['path']}[/]  {data['message_count']} messages, "
        f"{data['duration_s']:.3f} s  ({data['start_ns']} .. {data['end_ns']} ns)"
    )
    table = Table(show_edge=False)
    for col in ("topic", "schema", "encoding", "count", "rate Hz"):
        table.add_column(col, justify="right" if col in ("count", "rate Hz") else "left")
    for topic, t in data["topics"].items():
        table.add_row(topic, t["schema"], t["encoding"], str(t["count"]), f"{t['rate_hz']:.2f}")
    screen.print(table)
    for name, md in data["metadata"].items():
        shown = ", ".join(f"{k}={v}" for k, v in md.items() if k != "report")
        screen.print(f"metadata [bold]{name}[/]: {shown}", soft_wrap=True)
    for name, att in data["attachments"].items():
        screen.print(f"attachment [bold]{name}[/]: {att['media_type']}, {att['bytes']} bytes")
