"""``trackctl export``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from trackctl.cli.common import JsonOption, QuietOption, parse_choice, print_json, progress, stderr
from trackctl.errors import InputError
from trackctl.export import PERSON_HEIGHT_M, ExportConfig, ExportFormat, export
from trackctl.logs.output import check_output


def export_cmd(
    log: Annotated[Path, typer.Argument(help="MCAP log to read.")],
    topic: Annotated[str, typer.Option("--topic", help="Topic to export.")],
    fmt: Annotated[
        str,
        typer.Option(
            "--format",
            metavar="mot|tum|csv",
            help="mot: MOTChallenge text (tracks, ground truth); tum: TUM trajectory "
            "(poses); csv: flat columns (any topic).",
        ),
    ],
    out: Annotated[Path, typer.Option("--out", help="File to write (atomically).")],
    camera: Annotated[
        str | None,
        typer.Option(
            "--camera",
            metavar="CAM",
            help="mot: project boxes through /CAM/camera_model (without: -1 box columns).",
        ),
    ] = None,
    person_height_m: Annotated[
        float,
        typer.Option(
            "--person-height-m",
            help="mot with --camera: a person's box height in metres (width 0.41 of it).",
        ),
    ] = PERSON_HEIGHT_M,
    robot: Annotated[
        str | None,
        typer.Option(
            "--robot",
            metavar="NAME",
            help="tum: the entity to export from a topic holding several (/ground_truth).",
        ),
    ] = None,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Export one topic to another tool's format: MOTChallenge (py-motmetrics, TrackEval),
    TUM (evo) or CSV (pandas).

    Example: trackctl export out.mcap --topic /vmtrack/tracks --format mot --out tracks.txt
    """
    try:
        config = ExportConfig(
            topic,
            parse_choice(ExportFormat, fmt, "--format"),
            camera=camera,
            person_height_m=person_height_m,
            robot=robot,
        )
    except ValueError as err:
        raise InputError(f"--person-height-m {person_height_m}: expected metres > 0") from err
    check_output(out, [log])
    with progress(f"export {topic}", quiet) as update:
        result = export(log, out, config, update)
    if json_out:
        print_json(
            {
                "out": str(result.out),
                "messages": result.messages,
                "rows": result.rows,
                "extra": [str(p) for p in result.extra],
            }
        )
    elif not quiet:
        beside = "".join(f" (+ {p})" for p in result.extra)
        stderr.print(
            f"wrote {result.rows} rows from {result.messages} messages of {topic} to "
            f"{result.out}{beside}"
        )
