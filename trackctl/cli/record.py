"""``trackctl record`` and ``trackctl recover``."""

from __future__ import annotations

import signal
import sys
from collections import Counter
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from trackctl.cli.common import load_site_file, one_line, print_json, progress, stderr
from trackctl.errors import InputError
from trackctl.logs.writer import COMPRESSIONS, LogWriter


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
    ros2: Annotated[
        Path | None,
        typer.Option(
            "--ros2",
            metavar="BAG",
            help="ROS 2 bag (rosbag2 directory, .mcap or .db3): odometry, IMU, images, "
            "camera_info and tf mapped by message type (table printed).",
        ),
    ] = None,
    ros2_map: Annotated[
        list[str] | None,
        typer.Option(
            "--map",
            metavar="ROS_TOPIC=ROLE:NAME",
            help="Override the ROS 2 mapping of one topic: ROLE is odometry, imu, image, "
            "camera_info, tf or ignore, e.g. --map /odom=odometry:r1.",
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
            help="Frame rate of image folders; for a video, restamps every frame at this rate "
            "(a file with a wrong rate; to keep fewer frames use --rate or --every)."
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
            help="Unit of the CSV files' t_s column: s, ms, us or ns (converted to the log's ns)."
        ),
    ] = "s",
    video_start: Annotated[
        float,
        typer.Option(help="Log time of the first video frame, seconds (align video with CSV t_s)."),
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
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress or notes.")] = False,
) -> None:
    """Ingest video, calibration, IMU/RSSI/odometry CSV or live JSON lines into an MCAP log.

    Example: trackctl record run.mcap --video cam0=walk.avi --calib cam0=cam0.yaml --imu p1=p1.csv
    """
    # Imported here: OpenCV/pandas/SciPy cost ~0.5 s and other commands do not need them.
    from trackctl.geometry.calib import metres_per_unit
    from trackctl.ingest.record import (
        RecordConfig,
        StreamSource,
        UdpSource,
        parse_named,
        record_files,
        record_live,
        write_site,
    )
    from trackctl.ingest.video import FrameSelection

    plan = _ros2_plan(ros2, ros2_map, quiet or json_out)
    cfg = RecordConfig(
        site=site,
        site_records=load_site_file(site),
        ros2=ros2,
        ros2_plan=plan,
        imu=parse_named(imu or [], "--imu"),
        rssi=tuple(rssi or ()),
        odom=parse_named(odom or [], "--odom"),
        video=parse_named(video or [], "--video"),
        calib=parse_named(calib or [], "--calib"),
        fps=fps,
        video_start_s=video_start,
        selection=FrameSelection(every, rate, start, end),
        frame_times=None
        if frame_times is None
        else "names"
        if frame_times == "names"
        else Path(frame_times),
        calib_units=metres_per_unit(calib_units, "--calib-units"),
        time_unit=time_unit,
    )
    if time_unit not in ("s", "ms", "us", "ns"):
        raise InputError(f"--time-unit {time_unit!r}: expected s, ms, us or ns")
    if stdin and udp is not None:
        raise InputError("--stdin and --udp are exclusive; record one live source at a time")
    if cfg.empty and not stdin and udp is None:
        raise InputError(
            "nothing to record: give --imu/--rssi/--odom/--video/--ros2, --stdin or --udp"
        )
    inputs = [
        *cfg.imu.values(),
        *cfg.rssi,
        *cfg.odom.values(),
        *cfg.video.values(),
        *cfg.calib.values(),
        *([ros2] if ros2 is not None else []),
        *([site] if site is not None else []),
    ]
    counts: Counter[str] = Counter()
    rejected = 0
    interrupted = False
    live_stats = None
    source = None
    if udp is not None:
        source = UdpSource(udp)
    # SIGTERM (a supervisor stopping us) ends a live recording like Ctrl-C: with a valid log.
    # SIGINT too, explicitly: a shell starts background jobs with SIGINT ignored, and then
    # `kill -INT` would not stop the recording.
    previous = signal.signal(signal.SIGTERM, signal.default_int_handler)
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        # Live logs are written to OUT.partial, flushed every second and kept if the recorder
        # dies: a recorder killed with SIGKILL loses at most the last second.
        live = stdin or source is not None
        chunk = 256 * 1024 if live else 1 << 20
        with LogWriter(
            out, inputs=inputs, compression=compression, chunk_size=chunk, keep_partial=live
        ) as writer:
            write_site(writer, cfg)
            if not cfg.empty:
                with progress("recording files", quiet) as bar:
                    counts.update(record_files(writer, cfg, lambda n: bar(n, None)))
            if stdin or source is not None:

                def reject(msg: str) -> None:
                    # always shown, --quiet included: a dropped message is a warning
                    stderr.print(
                        f"[yellow]warning:[/] rejected {escape(one_line(msg))}", markup=True
                    )

                # The ready line goes out even with --quiet: with --udp 0 it carries the port.
                if source is not None:
                    stderr.print(f"listening on udp {source.address[0]}:{source.address[1]}")
                    stats = record_live(writer, source, reject, drain=source.drain)
                else:
                    if not quiet:
                        stderr.print("recording JSON lines from stdin until EOF or Ctrl-C")
                    stats = record_live(writer, StreamSource(sys.stdin.fileno()), reject)
                counts.update(stats.counts)
                rejected, interrupted = stats.rejected, stats.interrupted
                live_stats = stats
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
        if source is not None:
            source.close()
    summary = {
        "out": str(out),
        "topics": dict(sorted(counts.items())),
        "messages": sum(counts.values()),
        "rejected": rejected,
        "metadata": live_stats.metadata if live_stats else 0,
        "attachments": live_stats.attachments if live_stats else 0,
        "interrupted": interrupted,
    }
    if json_out:
        print_json(summary)
    elif not quiet:
        stderr.print(
            f"wrote {summary['messages']} messages on {len(counts)} topics to {out}"
            + (f", rejected {rejected}" if stdin or udp is not None else "")
            + (" (stopped by interrupt)" if interrupted else "")
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
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No notes.")] = False,
) -> None:
    """Finish an unfinished recording into a complete, indexed log (every readable message).

    Example: trackctl recover live.mcap.partial --out live.mcap
    """
    from trackctl.logs.copy import recover_log

    result = recover_log(partial, out, keep=keep)
    if json_out:
        print_json(
            {"out": str(result.out), "messages": result.messages, "warnings": len(result.warnings)}
        )
    elif not quiet:
        stderr.print(f"recovered {result.messages} messages from {partial} into {result.out}")


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
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No notes.")] = False,
) -> None:
    """Copy a log without some topics (metadata and attachments kept), e.g. drop the ground
    truth or a camera to see how a processor copes.

    Example: trackctl filter run.mcap --out nogt.mcap --exclude /ground_truth
    """
    from trackctl.logs.copy import filter_log

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


def _ros2_plan(bag: Path | None, maps: list[str] | None, quiet: bool) -> tuple[Any, ...]:
    """The ROS 2 topic plan (printed unless quiet); empty without a bag."""
    if maps and bag is None:
        raise InputError("--map needs --ros2 BAG")
    if bag is None:
        return ()
    from trackctl.ingest.ros2 import parse_maps, plan_ros2

    plan = tuple(plan_ros2(bag, parse_maps(maps or [])))
    if not quiet:
        _print_plan(bag, plan)
    return plan


def _print_plan(bag: Path, plan: tuple[Any, ...]) -> None:
    """The ROS 2 topic mapping as a table on stderr."""
    from rich.table import Table

    table = Table(title=f"{escape(str(bag))}: ROS 2 topics", title_justify="left")
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
