"""``trackctl record``: files (CSV, video, calibration) and live JSON lines into one MCAP log."""

from __future__ import annotations

import heapq
import signal
import sys
import threading
import warnings
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from trackctl.errors import InputError
from trackctl.geometry.calib import camera_problems
from trackctl.ingest.calibration import read_calibration, to_foxglove_calibration
from trackctl.ingest.live import (
    LiveStats,
    StopFlag,
    StreamSource,
    UdpSource,
    record_live,
    stop_on_signals,
)
from trackctl.ingest.mot import read_mot_detections
from trackctl.ingest.ros2 import TopicPlan, read_ros2, ros_metadata
from trackctl.ingest.sensors_csv import (
    CsvLayout,
    read_imu,
    read_odometry_csv,
    read_rssi_csv,
    seconds_to_ns,
)
from trackctl.ingest.video import FrameSelection, frame_size, read_frames
from trackctl.logs import topics
from trackctl.logs.foxglove import detection_annotations
from trackctl.logs.messages import Detections
from trackctl.logs.writer import LogWriter
from trackctl.progress import Progress

__all__ = [
    "IngestPlan",
    "IngestSummary",
    "ingest",
    "RecordConfig",
    "record_files",
    "write_site",
    "record_live",
    "LiveStats",
    "UdpSource",
    "StreamSource",
    "parse_named",
]


@dataclass(frozen=True, slots=True)
class RecordConfig:
    """What to ingest. Maps are ``NAME -> path``; topic names follow :mod:`trackctl.logs.topics`."""

    imu: Mapping[str, Path] = field(default_factory=dict)
    rssi: tuple[Path, ...] = ()
    odom: Mapping[str, Path] = field(default_factory=dict)
    video: Mapping[str, Path] = field(default_factory=dict)
    calib: Mapping[str, Path] = field(default_factory=dict)
    detections: Mapping[str, Path] = field(default_factory=dict)
    """MOTChallenge det.txt per camera (:mod:`trackctl.ingest.mot`) -> ``/<CAM>/detections``."""
    min_score: float | None = None
    """Boxes of ``detections`` with a lower raw ``conf`` are dropped (None: keep all)."""
    fps: float | None = None
    video_start_s: float = 0.0
    selection: FrameSelection = field(default_factory=FrameSelection)
    """Which video frames to keep (``--every``, ``--rate``, ``--start``, ``--end``)."""
    frame_times: Path | str | None = None
    """CSV ``file,t`` stamping an image folder's files, or ``"names"`` (numeric file names);
    times in ``time_unit``."""
    calib_units: float | None = None
    """Metres per unit of the calibration files' translation (None: metres; Tsai XML: mm)."""
    jpeg_quality: int = 90
    time_unit: str = "s"
    """Unit of the CSV files' ``t_s`` column: s, ms, us or ns."""
    csv_columns: Mapping[str, Mapping[str, int | str]] = field(default_factory=dict)
    """Column maps of the IMU/RSSI/odometry CSV files (``--columns``) by target: ``""`` for
    every file, an ``imu``/``odom`` NAME, or ``"rssi"`` (see
    :func:`~trackctl.ingest.sensors_csv.parse_column_options`)."""
    csv_header: bool | None = None
    """Whether the CSV files' first row is a header (None: unless it is all numbers)."""
    site: Path | None = None
    """The site file (:mod:`trackctl.ingest.site`), attached to the log as it was written."""
    site_records: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    """Its metadata records (written before any message)."""
    ros2: Path | None = None
    """A ROS bag (ROS 1 .bag, rosbag2 directory or .mcap/.db3) to convert with ``ros2_plan``."""
    ros2_plan: tuple[TopicPlan, ...] = ()
    """What becomes of each of the bag's topics (:func:`~trackctl.ingest.ros2.plan_ros2`)."""

    @property
    def empty(self) -> bool:
        """True when no file source is given."""
        return not (
            self.imu
            or self.rssi
            or self.odom
            or self.video
            or self.calib
            or self.detections
            or self.ros2
        )

    def csv_layout(self, target: str) -> CsvLayout:
        """The layout of the CSV file(s) of ``target`` (an ``imu``/``odom`` NAME or ``rssi``):
        the map for every file, overridden field by field by the target's own.

        Raises:
            InputError: a ``csv_columns`` target names no CSV input.
        """
        known = {*self.imu, *self.odom, *(("rssi",) if self.rssi else ())}
        unknown = sorted(t for t in self.csv_columns if t and t not in known)
        if unknown:
            raise InputError(
                f"--columns {unknown[0]}:...: no --imu/--odom named {unknown[0]} (names: "
                f"{', '.join(sorted(known - {'rssi'})) or 'none'}; rssi: for the --rssi files)"
            )
        columns = {**self.csv_columns.get("", {}), **self.csv_columns.get(target, {})}
        return CsvLayout(columns=columns, header=self.csv_header)

    @property
    def inputs(self) -> tuple[Path, ...]:
        """Every file read (the output may be none of them)."""
        return (
            *self.imu.values(),
            *self.rssi,
            *self.odom.values(),
            *self.video.values(),
            *self.calib.values(),
            *self.detections.values(),
            *((self.ros2,) if self.ros2 is not None else ()),
            *((self.site,) if self.site is not None else ()),
            *((self.frame_times,) if isinstance(self.frame_times, Path) else ()),
        )


def parse_named(values: Iterable[str], option: str) -> dict[str, Path]:
    """Parse ``NAME=PATH`` option values.

    Raises:
        InputError: a value lacks ``=`` or repeats a name.
    """
    out: dict[str, Path] = {}
    for value in values:
        name, sep, path = value.partition("=")
        if not sep or not name or not path:
            raise InputError(
                f"{option} {value!r}: expected NAME=PATH (e.g. {option} cam0=lobby.mp4)"
            )
        if "/" in name or " " in name:
            raise InputError(f"{option} {value!r}: NAME must not contain '/' or spaces")
        if name in out:
            raise InputError(f"{option}: name {name!r} given twice")
        out[name] = Path(path)
    return out


Stamped = tuple[int, int, str, Any]  # (t_ns, tie-break, topic, message)


def _stamped(source: Iterable[Any], topic: str, order: int) -> Iterator[Stamped]:
    for msg in source:
        yield (msg.t_ns, order, topic, msg)


def _with_annotations(source: Iterable[Detections], topic: str, order: int) -> Iterator[Stamped]:
    """Each detections message, then its boxes as a Foxglove image overlay at the same time."""
    overlay = topics.overlay(topic)
    for dets in source:
        yield (dets.t_ns, order, topic, dets)
        yield (dets.t_ns, order, overlay, detection_annotations(dets))


def _frames(path: Path, name: str, cfg: RecordConfig, order: int) -> Iterator[Stamped]:
    for t_ns, img in read_frames(
        path,
        name,
        fps=cfg.fps,
        start_ns=seconds_to_ns(cfg.video_start_s),
        select=cfg.selection,
        frame_times=cfg.frame_times,
        time_unit=cfg.time_unit,
        jpeg_quality=cfg.jpeg_quality,
    ):
        yield (t_ns, order, topics.image(name), img)


def write_site(writer: LogWriter, cfg: RecordConfig) -> None:
    """The site file's metadata records, and the file itself as an attachment."""
    for name, record in cfg.site_records.items():
        writer.add_metadata(name, dict(record))
    for name, record in ros_metadata(cfg.ros2_plan).items():  # e.g. a GPS topic's ENU origin
        writer.add_metadata(name, record)
    if cfg.site is not None:
        data = cfg.site.read_bytes()
        writer.add_attachment(f"site/{cfg.site.name}", data, "application/x-yaml", 0)


def _check_cameras(cfg: RecordConfig) -> None:
    """Every calibration has a camera (video or detections); every detections file its
    calibration and a frame rate."""
    cameras = set(cfg.video) | set(cfg.detections)
    unknown = set(cfg.calib) - cameras
    if unknown:
        raise InputError(
            f"--calib {sorted(unknown)[0]}=...: no --video or --detections with that camera name "
            f"(cameras: {', '.join(sorted(cameras)) or 'none'})"
        )
    uncalibrated = sorted(set(cfg.detections) - set(cfg.calib))
    if uncalibrated:
        cam = uncalibrated[0]
        raise InputError(
            f"--detections {cam}=...: camera {cam} has no --calib {cam}=FILE; vm-track needs its "
            "calibration to place the boxes on the ground"
        )
    if cfg.detections and cfg.fps is None:
        raise InputError("--detections needs --fps F (the sequence's frame rate, e.g. 30)")


def _write_calibration(
    writer: LogWriter, cfg: RecordConfig, name: str, path: Path, start_ns: int
) -> None:
    """One camera's calibration, checked against its video's frame size when it has one."""
    model = read_calibration(path, name, cfg.calib_units)
    model = replace(model, t_ns=start_ns)
    size = frame_size(cfg.video[name], name) if name in cfg.video else None
    errors, warns = camera_problems(model, size)
    if errors:
        raise InputError(f"{path} (camera {name}): {errors[0]}")
    for w in warns:
        warnings.warn(f"{path} (camera {name}): {w}", UserWarning, stacklevel=3)
    writer.write(topics.calibration(name), to_foxglove_calibration(model), start_ns)
    writer.write(topics.camera_model(name), model)
    writer.add_attachment(
        f"calibration/{name}{path.suffix}", path.read_bytes(), "application/x-yaml", start_ns
    )


def record_files(
    writer: LogWriter,
    cfg: RecordConfig,
    progress: Callable[[int], None] | None = None,
    skipped: dict[str, int] | None = None,
) -> Counter[str]:
    """Write every file source of ``cfg`` into ``writer``, merged in time order.

    ``skipped`` receives the unusable lines skipped per detections file.

    Returns:
        Message count per topic.
    """
    counts: Counter[str] = Counter()
    _check_cameras(cfg)
    start_ns = seconds_to_ns(cfg.video_start_s)
    cfg.selection.check()
    for name, path in cfg.calib.items():
        _write_calibration(writer, cfg, name, path, start_ns)
        counts[topics.calibration(name)] += 1
        counts[topics.camera_model(name)] += 1
    streams: list[Iterator[Stamped]] = []
    order = 0
    for name, path in cfg.imu.items():
        imu = read_imu(path, name, cfg.time_unit, cfg.csv_layout(name))
        streams.append(_stamped(imu, topics.imu(name), order))
        order += 1
    for path in cfg.rssi:
        rssi = read_rssi_csv(path, cfg.time_unit, cfg.csv_layout("rssi"))
        streams.append(_stamped(rssi, topics.RSSI, order))
        order += 1
    for name, path in cfg.odom.items():
        odom = read_odometry_csv(path, name, cfg.time_unit, cfg.csv_layout(name))
        streams.append(_stamped(odom, topics.odom(name), order))
        order += 1
    for name, path in cfg.video.items():
        streams.append(_frames(path, name, cfg, order))
        order += 1
    for name, path in cfg.detections.items():
        dets = read_mot_detections(path, name, cfg.fps or 0.0, start_ns, cfg.min_score)
        if skipped is not None:
            skipped[str(path)] = dets.skipped
        streams.append(_with_annotations(dets.messages, topics.detections(name), order))
        order += 1
    if cfg.ros2 is not None:
        streams.append(read_ros2(cfg.ros2, cfg.ros2_plan, order))
        order += 1
    n = 0
    # heapq.merge keeps one pending message per source: memory does not grow with the files.
    for t_ns, _, topic, msg in heapq.merge(*streams, key=lambda s: (s[0], s[1])):
        writer.write(topic, msg, t_ns)
        counts[topic] += 1
        n += 1
        if progress is not None and n % 1000 == 0:
            progress(n)
    return counts


TIME_UNITS = ("s", "ms", "us", "ns")


@dataclass(frozen=True, slots=True)
class IngestPlan:
    """One recording: file sources, and at most one live source (stdin or a UDP port)."""

    files: RecordConfig = field(default_factory=RecordConfig)
    stdin: bool = False
    """Record JSON lines from stdin until EOF or Ctrl-C."""
    udp: int | None = None
    """Record JSON lines from UDP datagrams on 127.0.0.1:PORT until Ctrl-C (0: a free port)."""
    compression: str = "zstd"

    @property
    def live(self) -> bool:
        """True with a live source."""
        return self.stdin or self.udp is not None

    def check(self) -> None:
        """Raise InputError for a plan that cannot be recorded."""
        if self.files.time_unit not in TIME_UNITS:
            raise InputError(f"--time-unit {self.files.time_unit!r}: expected s, ms, us or ns")
        csv_inputs = self.files.imu or self.files.rssi or self.files.odom
        if (self.files.csv_columns or self.files.csv_header is not None) and not csv_inputs:
            flag = "--columns" if self.files.csv_columns else "--header/--no-header"
            raise InputError(f"{flag} describes CSV files: give --imu, --rssi or --odom")
        if csv_inputs:
            self.files.csv_layout("")  # a --columns NAME: that names no input
        from trackctl.ingest.video import check_fps, check_log_seconds

        check_log_seconds(self.files.video_start_s, "--video-start")
        if self.files.fps is not None:
            check_fps(self.files.fps)
        if self.stdin and self.udp is not None:
            raise InputError("--stdin and --udp are exclusive; record one live source at a time")
        if self.files.empty and not self.live:
            raise InputError(
                "nothing to record: give --imu/--rssi/--odom/--video/--detections/--ros, "
                "--stdin or --udp"
            )


@dataclass(frozen=True, slots=True)
class IngestSummary:
    """What :func:`ingest` wrote."""

    out: Path
    topics: Mapping[str, int]
    """Messages per topic, sorted by topic."""
    live: bool = False
    rejected: int = 0
    """Live lines rejected (bad JSON, bad message...)."""
    metadata: int = 0
    attachments: int = 0
    interrupted: bool = False
    """The live recording was ended by Ctrl-C, SIGINT, SIGTERM or SIGHUP (the log is valid)."""
    skipped: Mapping[str, int] = field(default_factory=dict)
    """Unusable lines skipped per detections file (``--detections``)."""

    @property
    def messages(self) -> int:
        """Messages written."""
        return sum(self.topics.values())


ProgressScope = Callable[[], AbstractContextManager[Progress]]
"""Opens the progress display of the file pass and yields the callback it reports to."""


@contextmanager
def _no_progress() -> Iterator[Progress]:
    yield lambda done, total, stage=None: None


_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def _interrupt_on_signals() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP raise KeyboardInterrupt during the file pass (main thread
    only): the unfinished output is removed. SIGINT explicitly: a shell starts background jobs
    with SIGINT ignored, and then ``kill -INT`` would not stop the recording. The live pass
    replaces these by :func:`~trackctl.ingest.live.stop_on_signals` (it ends with a valid log).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, signal.default_int_handler) for s in _SIGNALS}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def ingest(
    plan: IngestPlan,
    out: Path,
    progress: ProgressScope | None = None,
    on_reject: Callable[[str], None] | None = None,
    on_live: Callable[[tuple[str, int] | None], None] | None = None,
) -> IngestSummary:
    """Record ``plan`` into the MCAP log ``out``: the site, then the files merged in time order,
    then the live source until it ends or Ctrl-C / SIGINT / SIGTERM / SIGHUP.

    ``out`` is written atomically and is never one of the inputs. A live recording goes to
    ``OUT.partial``, flushed every second and kept if the recorder dies (SIGKILL loses at most
    the last second); an interrupt ends it normally with a valid log (``interrupted``). Bad live
    lines are rejected through ``on_reject`` and recording goes on. ``progress`` is opened around
    the file pass only; ``on_live`` is called as the live source starts, with the UDP address
    (``None``: stdin).

    Raises:
        InputError: the plan cannot be recorded (see :meth:`IngestPlan.check`), a bad file.
        KeyboardInterrupt: an interrupt during the file pass (the output is removed).
    """
    plan.check()
    cfg = plan.files
    counts: Counter[str] = Counter()
    skipped: dict[str, int] = {}
    stats: LiveStats | None = None
    source = UdpSource(plan.udp) if plan.udp is not None else None
    try:
        with _interrupt_on_signals():
            chunk = 256 * 1024 if plan.live else 1 << 20
            with LogWriter(
                out,
                inputs=cfg.inputs,
                compression=plan.compression,
                chunk_size=chunk,
                keep_partial=plan.live,
            ) as writer:
                write_site(writer, cfg)
                if not cfg.empty:
                    with (progress or _no_progress)() as bar:
                        counts.update(record_files(writer, cfg, lambda n: bar(n, None), skipped))
                if plan.live:
                    stats = _record_source(writer, source, on_reject, on_live)
                    counts.update(stats.counts)
    finally:
        if source is not None:
            source.close()
    return IngestSummary(
        out=out,
        topics=dict(sorted(counts.items())),
        live=plan.live,
        rejected=stats.rejected if stats else 0,
        metadata=stats.metadata if stats else 0,
        attachments=stats.attachments if stats else 0,
        interrupted=stats.interrupted if stats else False,
        skipped=skipped,
    )


def _record_source(
    writer: LogWriter,
    source: UdpSource | None,
    on_reject: Callable[[str], None] | None,
    on_live: Callable[[tuple[str, int] | None], None] | None,
) -> LiveStats:
    """The live part of :func:`ingest`: ``source``, or stdin without one, until its end or a
    signal (SIGINT, SIGTERM, SIGHUP end it between two lines, with a valid log)."""
    with stop_on_signals(StopFlag()) as stop:
        if source is not None:
            if on_live is not None:
                on_live((source.address[0], source.address[1]))
            return record_live(writer, source, on_reject, drain=source.drain, stop=stop)
        if on_live is not None:
            on_live(None)
        return record_live(writer, StreamSource(sys.stdin.fileno()), on_reject, stop=stop)
