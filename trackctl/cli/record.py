"""``trackctl record`` and ``trackctl recover``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.markup import escape

from trackctl.cli.common import (
    JsonOption,
    load_site_file,
    one_line,
    print_json,
    progress,
    stderr,
)
from trackctl.errors import InputError
from trackctl.logs.output import check_output
from trackctl.logs.writer import COMPRESSIONS

if TYPE_CHECKING:
    from trackctl.ingest.record import IngestSummary, RecordConfig


def record(
    out: Annotated[Path, typer.Argument(help="MCAP log to write (atomically).")],
    imu: Annotated[
        list[str] | None,
        typer.Option(
            "--imu",
            metavar="NAME=FILE",
            help="IMU CSV (t_s,ax,ay,az[,gx,gy,gz][,qw,qx,qy,qz]) or Sensor Logger export "
            "folder/zip -> /phone/NAME/imu.",
        ),
    ] = None,
    rssi: Annotated[
        list[Path] | None,
        typer.Option(
            "--rssi", metavar="FILE", help="RSSI CSV (t_s,observer,eid,rssi_dbm) -> /rssi."
        ),
    ] = None,
    odom: Annotated[
        list[str] | None,
        typer.Option(
            "--odom",
            metavar="NAME=FILE",
            help="Odometry CSV (t_s,left_ticks,right_ticks or t_s,v_mps,omega_rps) "
            "-> /robot/NAME/odom.",
        ),
    ] = None,
    video: Annotated[
        list[str] | None,
        typer.Option(
            "--video",
            metavar="NAME=FILE",
            help="Video file or image folder -> /NAME/image (foxglove.CompressedImage).",
        ),
    ] = None,
    calib: Annotated[
        list[str] | None,
        typer.Option(
            "--calib",
            metavar="NAME=FILE",
            help="OpenCV or ROS camera_info YAML for camera NAME -> /NAME/calibration, "
            "/NAME/camera_model.",
        ),
    ] = None,
    detections: Annotated[
        list[str] | None,
        typer.Option(
            "--detections",
            metavar="CAM=FILE",
            help="MOTChallenge det.txt (frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z) "
            "-> /CAM/detections; needs --fps and --calib CAM=...",
        ),
    ] = None,
    min_score: Annotated[
        float | None,
        typer.Option(help="Drop --detections boxes whose conf is below this (default: keep all)."),
    ] = None,
    ros2: Annotated[
        Path | None,
        typer.Option(
            "--ros",
            metavar="BAG",
            help="ROS bag: ROS 1 .bag, or ROS 2 rosbag2 directory, .mcap or .db3 (odometry, IMU, "
            "poses, GPS, images, camera_info and tf mapped by message type; table printed).",
        ),
    ] = None,
    ros2_alias: Annotated[
        Path | None, typer.Option("--ros2", metavar="BAG", hidden=True, help="Alias of --ros.")
    ] = None,
    ros2_map: Annotated[
        list[str] | None,
        typer.Option(
            "--map",
            metavar="ROS_TOPIC=ROLE:NAME",
            help="Override the ROS mapping of one topic: ROLE is odometry, imu, pose, gps, "
            "image, camera_info, tf or ignore, e.g. --map /odom=odometry:r1.",
        ),
    ] = None,
    robot: Annotated[
        str | None,
        typer.Option(
            metavar="NAME",
            help="The robot every robot topic of the --ros bag belongs to (default: from its "
            "frames and namespaces).",
        ),
    ] = None,
    site: Annotated[
        Path | None,
        typer.Option(
            help="Site YAML (robot geometry, LEDs, tags, IR light, floor plan; docs/site.md) "
            "stored in the log as metadata records and an attachment."
        ),
    ] = None,
    fps: Annotated[
        float | None,
        typer.Option(
            help="Frame rate of image folders and --detections files; for a video, restamps "
            "every frame at this rate (a file with a wrong rate; to keep fewer frames use "
            "--rate or --every)."
        ),
    ] = None,
    every: Annotated[
        int, typer.Option(help="Keep one video frame in N (timestamps stay true).")
    ] = 1,
    rate: Annotated[
        float | None,
        typer.Option(help="Keep video frames at most this often, Hz (timestamps stay true)."),
    ] = None,
    start: Annotated[
        float | None, typer.Option(help="First second of the video to keep (video time).")
    ] = None,
    end: Annotated[
        float | None, typer.Option(help="Last second of the video to keep (video time).")
    ] = None,
    frame_times: Annotated[
        str | None,
        typer.Option(
            metavar="CSV|names",
            help="Stamp an image folder's files from a CSV file,t or from their numeric names "
            "('names'); t in --time-unit.",
        ),
    ] = None,
    calib_units: Annotated[
        str | None,
        typer.Option(
            help="Unit of the calibration files' translation: m (default), cm or mm (Tsai XML: mm)."
        ),
    ] = None,
    time_unit: Annotated[
        str,
        typer.Option(
            help="Unit of the CSV files' time column (t_s, or --columns t=...): s, ms, us or ns "
            "(converted to the log's ns)."
        ),
    ] = "s",
    columns: Annotated[
        list[str] | None,
        typer.Option(
            "--columns",
            metavar="[NAME:]KEY=COL,...",
            help="Which column of the --imu/--rssi/--odom CSV holds each field: 0-based indexes "
            "(t=0,ax=1,ay=2,az=3) or header names (t=time,ax=accX,...); NAME: (an --imu/--odom "
            "name, or rssi) limits it to that input. Unmapped fields go by their header name.",
        ),
    ] = None,
    header: Annotated[
        bool | None,
        typer.Option(
            "--header/--no-header",
            help="Whether the CSV files' first row is a header (default: yes unless it is all "
            "numbers); header-less files need --columns by index.",
        ),
    ] = None,
    video_start: Annotated[
        float,
        typer.Option(
            help="Log time of the first video frame and of --detections frame 1, seconds "
            "(align video with CSV t_s)."
        ),
    ] = 0.0,
    stdin: Annotated[
        bool, typer.Option("--stdin", help="Record JSON lines from stdin until EOF or Ctrl-C.")
    ] = False,
    udp: Annotated[
        int | None,
        typer.Option(
            "--udp",
            metavar="PORT",
            help="Record JSON lines from UDP datagrams on 127.0.0.1:PORT until Ctrl-C "
            "(0 picks a free port).",
        ),
    ] = None,
    compression: Annotated[
        str, typer.Option(help=f"Chunk compression: {', '.join(COMPRESSIONS)}.")
    ] = "zstd",
    json_out: JsonOption = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress or notes.")] = False,
) -> None:
    """Ingest video, calibration, IMU/RSSI/odometry CSV or live JSON lines into an MCAP log.

    Example: trackctl record run.mcap --video cam0=walk.avi --calib cam0=cam0.yaml --imu p1=p1.csv

    Public detections: trackctl record det.mcap --detections cam0=det.txt --calib cam0=cam0.yaml
    --fps 30
    """
    # Imported here: OpenCV/pandas/SciPy cost ~0.5 s and other commands do not need them.
    from trackctl.ingest.record import IngestPlan, ingest

    named = (imu, odom, video, calib, detections)
    check_output(out, _option_inputs(named, [*(rssi or ()), ros2, site, _frame_times(frame_times)]))
    files = _files_config(
        imu=imu,
        rssi=rssi,
        odom=odom,
        video=video,
        calib=calib,
        detections=detections,
        min_score=min_score,
        ros2=_one_bag(ros2, ros2_alias),
        ros2_map=ros2_map,
        robot=robot,
        site=site,
        fps=fps,
        every=every,
        rate=rate,
        start=start,
        end=end,
        frame_times=frame_times,
        calib_units=calib_units,
        time_unit=time_unit,
        columns=columns,
        header=header,
        video_start=video_start,
        quiet=quiet or json_out,
    )
    plan = IngestPlan(files=files, stdin=stdin, udp=udp, compression=compression)
    summary = ingest(
        plan,
        out,
        progress=lambda: progress("recording files", quiet),
        on_reject=_warn_rejected,
        on_live=lambda address: _announce_live(address, quiet),
    )
    _print_summary(summary, json_out=json_out, quiet=quiet)


def _files_config(
    *,
    imu: list[str] | None,
    rssi: list[Path] | None,
    odom: list[str] | None,
    video: list[str] | None,
    calib: list[str] | None,
    detections: list[str] | None,
    min_score: float | None,
    ros2: Path | None,
    ros2_map: list[str] | None,
    robot: str | None,
    site: Path | None,
    fps: float | None,
    every: int,
    rate: float | None,
    start: float | None,
    end: float | None,
    frame_times: str | None,
    calib_units: str | None,
    time_unit: str,
    columns: list[str] | None,
    header: bool | None,
    video_start: float,
    quiet: bool,
) -> RecordConfig:
    """The file sources of ``record``'s options (the ROS 2 plan printed unless quiet)."""
    from trackctl.geometry.calib import metres_per_unit
    from trackctl.ingest.record import RecordConfig, parse_named
    from trackctl.ingest.sensors_csv import parse_column_options
    from trackctl.ingest.video import FrameSelection

    plan = _ros2_plan(ros2, ros2_map, robot, quiet)
    return RecordConfig(
        site=site,
        site_records=load_site_file(site),
        ros2=ros2,
        ros2_plan=plan,
        imu=parse_named(imu or [], "--imu"),
        rssi=tuple(rssi or ()),
        odom=parse_named(odom or [], "--odom"),
        video=parse_named(video or [], "--video"),
        calib=parse_named(calib or [], "--calib"),
        detections=parse_named(detections or [], "--detections"),
        min_score=min_score,
        fps=fps,
        video_start_s=video_start,
        selection=FrameSelection(every, rate, start, end),
        frame_times=_frame_times(frame_times),
        calib_units=metres_per_unit(calib_units, "--calib-units"),
        time_unit=time_unit,
        csv_columns=parse_column_options(columns or ()),
        csv_header=header,
    )


def _option_inputs(
    named: tuple[list[str] | None, ...], paths: list[Path | str | None]
) -> list[Path]:
    """Every file the options name (``NAME=FILE`` values and plain paths), for the output rule."""
    files = [Path(v.partition("=")[2]) for values in named for v in values or () if "=" in v]
    return files + [p for p in paths if isinstance(p, Path)]


def _frame_times(value: str | None) -> Path | str | None:
    """``--frame-times``: a CSV file, ``"names"`` or nothing."""
    if value is None or value == "names":
        return value
    return Path(value)


def _warn_rejected(msg: str) -> None:
    """A rejected live line: always shown, --quiet included (a dropped message is a warning)."""
    stderr.print(f"[yellow]warning:[/] rejected {escape(one_line(msg))}", markup=True)


def _announce_live(address: tuple[str, int] | None, quiet: bool) -> None:
    """The ready line; with --udp even with --quiet, as it carries the port (--udp 0)."""
    if address is not None:
        stderr.print(f"listening on udp {address[0]}:{address[1]}")
    elif not quiet:
        stderr.print("recording JSON lines from stdin until EOF or Ctrl-C")


def _print_summary(summary: IngestSummary, *, json_out: bool, quiet: bool) -> None:
    """One JSON object, or one line on stderr (nothing with --quiet)."""
    if json_out:
        print_json(
            {
                "out": str(summary.out),
                "topics": dict(summary.topics),
                "messages": summary.messages,
                "rejected": summary.rejected,
                "metadata": summary.metadata,
                "attachments": summary.attachments,
                "interrupted": summary.interrupted,
                "skipped_lines": dict(summary.skipped),
            }
        )
    elif not quiet:
        stderr.print(
            f"wrote {summary.messages} messages on {len(summary.topics)} topics to {summary.out}"
            + (f", rejected {summary.rejected}" if summary.live else "")
            + (f", skipped {bad} bad lines" if (bad := sum(summary.skipped.values())) else "")
            + (" (stopped by interrupt)" if summary.interrupted else "")
        )


def recover(
    partial: Annotated[
        Path, typer.Argument(help="Unfinished log: OUT.partial of a killed recording, a cut copy.")
    ],
    out: Annotated[
        Path | None,
        typer.Option(help="Finished log to write (default: PARTIAL without .partial)."),
    ] = None,
    keep: Annotated[bool, typer.Option("--keep", help="Keep PARTIAL after recovering.")] = False,
    json_out: JsonOption = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No notes.")] = False,
) -> None:
    """Finish an unfinished recording into a complete, indexed log (every readable message).

    Example: trackctl recover live.mcap.partial --out live.mcap
    """
    from trackctl.logs.copy import recover_log

    if out is not None:
        check_output(out, [partial])
    result = recover_log(partial, out, keep=keep)
    if json_out:
        print_json(
            {
                "out": str(result.out),
                "messages": result.messages,
                "warnings": len(result.warnings),
                "removed_input": result.removed_input,
            }
        )
    elif not quiet:
        kept = "" if result.removed_input else f" ({partial} kept)"
        stderr.print(f"recovered {result.messages} messages from {partial} into {result.out}{kept}")


def filter_cmd(
    log: Annotated[Path, typer.Argument(help="MCAP log to read (never changed).")],
    out: Annotated[Path, typer.Option(help="Filtered MCAP log to write.")],
    include: Annotated[
        list[str] | None,
        typer.Option("--include", help="Keep only topics matching this glob (repeatable)."),
    ] = None,
    exclude: Annotated[
        list[str] | None,
        typer.Option("--exclude", help="Drop topics matching this glob (repeatable)."),
    ] = None,
    json_out: JsonOption = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No notes.")] = False,
) -> None:
    """Copy a log without some topics (metadata and attachments kept), e.g. drop the ground
    truth or a camera to see how a processor copes.

    Example: trackctl filter run.mcap --out nogt.mcap --exclude /ground_truth
    """
    from trackctl.logs.copy import filter_log

    check_output(out, [log])
    result = filter_log(log, out, include=tuple(include or ()), exclude=tuple(exclude or ()))
    if json_out:
        print_json(
            {
                "out": str(result.out),
                "messages": result.messages,
                "kept_topics": len(result.kept_topics),
                "dropped_topics": list(result.dropped_topics),
            }
        )
    elif not quiet:
        stderr.print(
            f"wrote {result.messages} messages on {len(result.kept_topics)} topics to "
            f"{result.out}; dropped {', '.join(result.dropped_topics) or 'nothing'}"
        )


def _one_bag(ros: Path | None, alias: Path | None) -> Path | None:
    """``--ros`` or its old name ``--ros2`` (not both)."""
    if ros is not None and alias is not None:
        raise InputError("--ros and --ros2 are one option (--ros2 is its old name): give one")
    return ros if ros is not None else alias


def _ros2_plan(
    bag: Path | None, maps: list[str] | None, robot: str | None, quiet: bool
) -> tuple[Any, ...]:
    """The ROS topic plan (printed unless quiet); empty without a bag."""
    if (maps or robot) and bag is None:
        raise InputError(f"{'--map' if maps else '--robot'} needs --ros BAG")
    if bag is None:
        return ()
    from trackctl.ingest.ros2 import parse_maps, plan_ros2

    plan = tuple(plan_ros2(bag, parse_maps(maps or []), robot))
    if not quiet:
        _print_plan(bag, plan)
    return plan


def _print_plan(bag: Path, plan: tuple[Any, ...]) -> None:
    """The ROS topic mapping as a table on stderr."""
    from rich.table import Table

    table = Table(title=f"{escape(str(bag))}: ROS topics", title_justify="left")
    for col in ("ROS topic", "type", "count", "role", "trackctl topic(s)", "by"):
        table.add_column(col)
    for p in plan:
        table.add_row(
            escape(p.ros_topic),
            escape(p.ros_type),
            str(p.count),
            p.role,
            escape(", ".join(p.targets)) or "-",
            escape(p.why),
        )
    stderr.print(table)
