"""S-Mirror over a log (dissertation §4.1): nodes mirror foreground views on request, the robot
localizes itself from its LEDs in them and dead-reckons in between.

One library function, :func:`run`, is the whole pipeline; ``trackctl smirror`` and the
``smirror`` processor call it. :func:`localize` does the work and returns every per-sample figure
(the benchmark bins them like the paper's figures); :func:`run` writes the channels and the report.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from enum import StrEnum

import cv2
import numpy as np

from trackctl.errors import InputError, MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.geometry.floorplan import FloorPlan, line_of_sight
from trackctl.geometry.odometry import DiffDrive
from trackctl.logs import topics
from trackctl.logs.foxglove import pose_in_frame
from trackctl.logs.messages import CameraModel, MetricReport, MirrorTransmission, WheelOdometry
from trackctl.logs.reader import LogMessage, LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress
from trackctl.processing.builtin import DeadReckoningProcessor
from trackctl.smirror.node import CastMode, MirrorNode, NodeConfig, beacon_bytes, decide_cast
from trackctl.smirror.robot import (
    FilterConfig,
    LedConfig,
    LedFix,
    PoseFilter,
    detect_leds,
    fix_from_leds,
)

__all__ = [
    "Mode",
    "SmirrorConfig",
    "SmirrorResult",
    "error_by_range",
    "localize",
    "pose_topic",
    "report_metrics",
    "run",
    "run_detailed",
    "sent_topic",
]


def pose_topic(robot: str) -> str:
    """Localized poses of a robot: ``/smirror/NAME/pose`` (foxglove.PoseInFrame)."""
    return f"/smirror/{robot}/pose"


def sent_topic(node: str) -> str:
    """What a node sent: ``/smirror/NODE/sent`` (trackctl.MirrorTransmission)."""
    return f"/smirror/{node}/sent"


class Mode(StrEnum):
    """``mirror+odom``: S-Mirror + motion sensor; ``centralized``: vision-only baseline."""

    MIRROR_ODOM = "mirror+odom"
    CENTRALIZED = "centralized"


@dataclass(frozen=True, slots=True)
class SmirrorConfig:
    """Configuration of an S-Mirror run (defaults follow §4.1.3)."""

    mode: Mode = Mode.MIRROR_ODOM
    broadcast_threshold: int = 15
    """A node broadcasts an image from this many requests on (Table 4.2)."""
    requesters: int | None = None
    """Robots requesting images (ours + others); None: the log's ``smirror/requesters`` metadata."""
    robot: str | None = None
    """The localized robot; None: the log's only ``robot/<NAME>`` metadata or odometry topic."""
    node: NodeConfig = field(default_factory=NodeConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    beacon_period_s: float = 1.0
    sensing_ms: float = 40.0
    """Sensing delay: the sensors' sampling period (25 Hz, §4.1.3 B)."""
    link_kBps: float = 1000.0  # noqa: N815 - kB/s, as the paper writes it
    """Unicast throughput of the wireless link (kB/s)."""
    link_latency_ms: float = 35.0
    broadcast_kBps: float = 250.0  # noqa: N815
    """Broadcast goes at the basic rate (kB/s)."""
    broadcast_wait_ms: float = 200.0
    """Broadcast frames wait for the access point's delivery beacon (DTIM)."""
    broadcast_loss: float = 0.05
    """Broadcast has no link-layer retry: this fraction of images is lost."""
    processing_ms: float = 15.0
    """Processing time used to time a fix's arrival (measured times go into the delay figures;
    a fixed budget keeps the output poses deterministic)."""
    max_range_m: float = 11.0
    """Beyond this ground range a node does not count as covering a point."""
    margin_px: int = 8
    seed: int = 0
    """Seeds the queue positions and broadcast losses."""

    def __post_init__(self) -> None:
        if self.broadcast_threshold < 1:
            raise ValueError(f"broadcast_threshold must be >= 1, got {self.broadcast_threshold}")
        if self.requesters is not None and self.requesters < 1:
            raise ValueError(f"requesters must be >= 1, got {self.requesters}")


@dataclass
class SmirrorResult:
    """Per-sample figures of a run (one row per ground-truth sample of the robot)."""

    t_s: list[float] = field(default_factory=list)
    error_m: list[float] = field(default_factory=list)
    in_coverage: list[bool] = field(default_factory=list)
    range_m: list[float] = field(default_factory=list)
    """Ground distance to the covering node (NaN outside coverage)."""
    delay_ms: list[float] = field(default_factory=list)
    path_m: list[float] = field(default_factory=list)
    """Distance the robot has travelled (ground truth) at the sample."""
    events: list[tuple[float, int, int, int]] = field(default_factory=list)
    """Transmissions: (t_s, bytes sent, bytes if unicast, bytes to our robot)."""
    node_ms: list[float] = field(default_factory=list)
    robot_ms: list[float] = field(default_factory=list)
    full_frame_bytes: int = 0
    foreground_bytes: int = 0
    image_messages: int = 0
    images_new: int = 0
    images_old: int = 0
    beacons: int = 0
    cast_modes: set[str] = field(default_factory=set)
    decode_failures: int = 0
    fix_attempts: int = 0
    fixes: int = 0
    fixes_used: int = 0
    broadcast_lost: int = 0
    requesters: int = 1
    duration_s: float = 0.0
    robot: str = ""


class _Coverage:
    """Which node sees a ground point (calibrated camera, image bounds, range, walls)."""

    def __init__(
        self, cams: dict[str, PinholeCamera], plan: FloorPlan | None, cfg: SmirrorConfig, z: float
    ) -> None:
        self.cams, self.plan, self.cfg, self.z = cams, plan, cfg, z

    def covering(self, xy: Iterable[float], only: str | None = None) -> tuple[str, float] | None:
        """(node, ground range) of the nearest node covering ``xy``, or None."""
        x, y = xy
        best: tuple[str, float] | None = None
        for name, cam in self.cams.items():
            if only is not None and name != only:
                continue
            rng = math.hypot(x - cam.position[0], y - cam.position[1])
            if rng > self.cfg.max_range_m or (best is not None and rng >= best[1]):
                continue
            px, front = cam.project(np.array([[x, y, self.z]]))
            m, (u, v) = self.cfg.margin_px, px[0]
            mod = cam.model
            if not (front[0] and m <= u < mod.width_px - m and m <= v < mod.height_px - m):
                continue
            if self.plan is not None and not line_of_sight(
                cam.position[:2], np.array([x, y]), self.plan.walls
            ):
                continue
            best = (name, rng)
        return best


def _camera_models(reader: LogReader) -> dict[str, CameraModel]:
    present = reader.topics()
    names = sorted(
        t.split("/")[1]
        for t, info in present.items()
        if info.schema_name == CameraModel.SCHEMA and t.endswith("/camera_model")
    )
    out: dict[str, CameraModel] = {}
    for name in names:
        if topics.image(name) not in present:
            continue
        for m in reader.messages([topics.camera_model(name)]):
            if m.message.world_from_camera is not None:
                out[name] = m.message
            break
    if not out:
        raise MissingTopicError(
            f"{reader.path}: no node camera (/<node>/image with a /<node>/camera_model holding "
            "its world pose); smirror needs the nodes' frames and calibrated cameras"
        )
    return out


def _robot_name(reader: LogReader, cfg: SmirrorConfig) -> str:
    if cfg.robot:
        return cfg.robot
    names = sorted(k.split("/", 1)[1] for k in reader.metadata() if k.startswith("robot/"))
    if not names:
        names = sorted(
            t.split("/")[2]
            for t, info in reader.topics().items()
            if info.schema_name == WheelOdometry.SCHEMA and t.startswith("/robot/")
        )
    if not names:
        raise MissingTopicError(
            f"{reader.path}: no robot: neither robot/<NAME> metadata nor a {topics.odom('<NAME>')} "
            "topic; smirror localizes a robot carrying two LEDs"
        )
    if len(names) > 1:
        raise InputError(
            f"{reader.path}: several robots ({', '.join(names)}); choose one with --robot"
        )
    return names[0]


def _floorplan(reader: LogReader) -> FloorPlan | None:
    md = reader.metadata().get("smirror/floorplan")
    if not md or "plan" not in md:
        return None
    try:
        return FloorPlan.from_json(json.loads(md["plan"]))
    except (ValueError, KeyError, TypeError) as err:
        raise InputError(f"{reader.path}: metadata smirror/floorplan is malformed: {err}") from err


def _decode(data: bytes, flags: int = cv2.IMREAD_COLOR) -> np.ndarray | None:
    try:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    except cv2.error:
        return None
    return img


def _stream(
    reader: LogReader, wanted: list[str], images: set[str], res: SmirrorResult
) -> Iterator[LogMessage]:
    """Decoded messages in log order through the reader's one decode path; a message that does
    not decode is skipped with a warning and counted (a camera glitch must not end a run)."""
    start = reader.decode_errors
    try:
        yield from reader.messages(wanted)
    finally:
        res.decode_failures += reader.decode_errors - start


def _metadata_float(values: Mapping[str, str], key: str, default: float, where: str) -> float:
    """A finite number from a metadata record, ``default`` when the key is absent."""
    if key not in values:
        return default
    try:
        value = float(values[key])
    except ValueError:
        raise InputError(f"{where}: {key}={values[key]!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: {key}={values[key]!r} is not finite")
    return value


def localize(
    reader: LogReader,
    cfg: SmirrorConfig,
    writer: LogWriter | None = None,
    progress: Progress | None = None,
) -> SmirrorResult:
    """Run the nodes and the robot over the log; returns the per-sample figures.

    Raises:
        MissingTopicError: no node camera, no robot, or (mirror+odom) no odometry for the robot.
    """
    models = _camera_models(reader)
    robot = _robot_name(reader, cfg)
    present = reader.topics()
    odom_topic = topics.odom(robot)
    use_odom = cfg.mode is Mode.MIRROR_ODOM
    if use_odom and odom_topic not in present:
        raise MissingTopicError(
            f"{reader.path}: {odom_topic} is missing: smirror --mode mirror+odom dead-reckons "
            f"robot {robot!r} with its wheel odometry (use --mode centralized for vision only)"
        )
    metadata = reader.metadata()
    rmd = metadata.get(f"robot/{robot}", {})
    where = f"{reader.path}: metadata robot/{robot}"
    led_default, drive_default = LedConfig(), DiffDrive()
    led = LedConfig(
        led_height_m=_metadata_float(rmd, "led_height_m", led_default.led_height_m, where),
        led_front_m=_metadata_float(rmd, "led_front_m", led_default.led_front_m, where),
        led_back_m=_metadata_float(rmd, "led_back_m", led_default.led_back_m, where),
    )
    drive = DiffDrive(
        _metadata_float(rmd, "ticks_per_m", drive_default.ticks_per_m, where),
        _metadata_float(rmd, "wheel_base_m", drive_default.wheel_base_m, where),
    )
    n_req = cfg.requesters or int(metadata.get("smirror/requesters", {}).get("count", 1))
    plan = _floorplan(reader)
    cams = {n: PinholeCamera(m) for n, m in models.items()}
    nodes = {n: MirrorNode(m, cfg.node) for n, m in models.items()}
    cover = _Coverage(cams, plan, cfg, led.led_height_m)
    has_truth = topics.GROUND_TRUTH in present
    start = DeadReckoningProcessor._start_poses(reader, {robot}).get(robot) if has_truth else None
    rng = np.random.default_rng(cfg.seed)
    res = SmirrorResult(requesters=n_req, robot=robot)
    frame_period_ns: dict[str, int] = {}
    last_frame_ns: dict[str, int] = {}
    beacon_sizes = {n: beacon_bytes(m) for n, m in models.items()}
    next_beacon_ns = 0
    beacon_ns = int(cfg.beacon_period_s * 1e9)

    filt: PoseFilter | None = None
    last_odo: WheelOdometry | None = None
    pending: list[tuple[int, LedFix, float, float]] = []  # (arrival, fix, sigma_pos, sigma_yaw)
    central: list[tuple[int, LedFix]] = []  # centralized fixes by availability time
    central_pose: LedFix | None = None
    last_answer: tuple[int, float] | None = None  # (frame t_ns, delay ms) of our last answer
    central_ms = 0.0
    dr_ms: list[float] = []
    gt_wait: list[tuple[int, float, float]] = []
    last_gt_xy: tuple[float, float] | None = None
    path_m = 0.0
    pose_out = pose_topic(robot)

    def flush_beacons(t_ns: int) -> None:
        nonlocal next_beacon_ns
        while next_beacon_ns <= t_ns:
            for name in sorted(models):
                size = beacon_sizes[name]
                res.beacons += 1
                res.events.append((next_beacon_ns / 1e9, size, size, 0))
                if writer is not None:
                    writer.write(
                        sent_topic(name),
                        MirrorTransmission(
                            next_beacon_ns, name, "beacon", CastMode.BROADCAST.value, 0, size, size
                        ),
                        next_beacon_ns,
                    )
            next_beacon_ns += beacon_ns

    def estimate(t_ns: int) -> tuple[float, float, float] | None:
        nonlocal central_pose
        if use_odom:
            return None if filt is None else filt.pose
        while central and central[0][0] <= t_ns:
            central_pose = central.pop(0)[1]
        if central_pose is None:
            return None
        return central_pose.x_m, central_pose.y_m, central_pose.yaw_rad

    def score(t_ns: int, gx: float, gy: float) -> None:
        est = estimate(t_ns)
        if est is None:
            return
        cov = cover.covering((gx, gy))
        res.t_s.append(t_ns / 1e9)
        res.error_m.append(math.hypot(est[0] - gx, est[1] - gy))
        res.in_coverage.append(cov is not None)
        res.range_m.append(math.nan if cov is None else cov[1])
        res.path_m.append(path_m)
        if use_odom:
            fresh = (
                last_answer is not None
                and t_ns - last_answer[0] <= 1.5 * max(frame_period_ns.values() or [0]) + 3e8
            )
            dr = float(np.median(dr_ms[-50:])) if dr_ms else 0.0
            res.delay_ms.append(last_answer[1] if fresh else cfg.sensing_ms + dr)  # type: ignore[index]
        else:
            res.delay_ms.append(cfg.sensing_ms + central_ms)

    wanted = [topics.image(n) for n in models] + ([odom_topic] if use_odom else [])
    if has_truth:
        wanted.append(topics.GROUND_TRUTH)
    count = 0
    t_first = t_last = None
    for msg in _stream(reader, wanted, set(topics.image(n) for n in models), res):
        t_ns = msg.log_time_ns
        t_first = t_ns if t_first is None else t_first
        t_last = t_ns
        count += 1
        if progress is not None and count % 2000 == 0:
            progress(count, None)
        if cfg.mode is not Mode.CENTRALIZED:
            flush_beacons(t_ns)
        if msg.topic == topics.GROUND_TRUTH:
            for ent in msg.message.entities:
                if ent.entity_id == robot:
                    gx, gy = ent.position_m.x, ent.position_m.y
                    if last_gt_xy is not None:
                        path_m += math.hypot(gx - last_gt_xy[0], gy - last_gt_xy[1])
                    last_gt_xy = (gx, gy)
                    if use_odom and (filt is None or filt.t_ns < t_ns):
                        gt_wait.append((t_ns, gx, gy))  # scored once odometry reaches it
                    else:
                        score(t_ns, gx, gy)
            continue
        if msg.topic == odom_topic:
            odo: WheelOdometry = msg.message
            started = time.perf_counter()
            if filt is None:
                x, y, yaw = start or (0.0, 0.0, 0.0)
                filt = PoseFilter(x, y, yaw, t_ns, cfg.filter)
            else:
                while pending and pending[0][0] <= t_ns:
                    _, ready, sp, sy = pending.pop(0)
                    res.fixes_used += filt.apply_fix(ready, sp, sy)
                assert last_odo is not None
                if odo.left_ticks is not None and last_odo.left_ticks is not None:
                    ds, dyaw = drive.motion_from_ticks(
                        odo.left_ticks - last_odo.left_ticks,
                        odo.right_ticks - last_odo.right_ticks,  # type: ignore[operator]
                    )
                else:  # velocities held over the interval
                    dt = (t_ns - filt.t_ns) / 1e9
                    ds, dyaw = (last_odo.v_mps or 0.0) * dt, (last_odo.omega_rps or 0.0) * dt
                filt.step(t_ns, ds, dyaw)
            dr_ms.append((time.perf_counter() - started) * 1e3)
            last_odo = odo
            if writer is not None:
                x, y, yaw = filt.pose
                writer.write(pose_out, pose_in_frame(t_ns, x, y, yaw), t_ns)
            while gt_wait and gt_wait[0][0] <= t_ns:
                score(*gt_wait.pop(0))
            continue
        # a node frame
        name = msg.topic.split("/")[1]
        if name in last_frame_ns:
            frame_period_ns[name] = t_ns - last_frame_ns[name]
        last_frame_ns[name] = t_ns
        frame = _decode(bytes(msg.message.data))
        if frame is None:
            res.decode_failures += 1
            continue
        node = nodes[name]
        if cfg.mode is Mode.CENTRALIZED:
            started = time.perf_counter()
            front, back = detect_leds([(0, 0, frame)], led)
            fix = (
                None
                if front is None or back is None
                else fix_from_leds(front, back, cams[name], led, t_ns)
            )
            central_ms = (time.perf_counter() - started) * 1e3
            res.robot_ms.append(central_ms)
            res.fix_attempts += 1
            if fix is not None:
                res.fixes += 1
                avail = t_ns + int((cfg.sensing_ms + cfg.processing_ms) * 1e6)
                central.append((avail, fix))
                central.sort(key=lambda c: c[0])
                if writer is not None:
                    writer.write(pose_out, pose_in_frame(t_ns, fix.x_m, fix.y_m, fix.yaw_rad), t_ns)
            continue
        mask = node.sense(frame)
        ours = False
        if filt is not None:
            x, y, _ = filt.pose
            cov = cover.covering((x, y))
            ours = cov is not None and cov[0] == name
        requests = (1 if ours else 0) + (n_req - 1)
        if requests == 0:
            continue
        started = time.perf_counter()
        payload, is_new = node.encode(t_ns, frame, mask)
        node_ms = node.last_sense_ms + (time.perf_counter() - started) * 1e3
        res.node_ms.append(node_ms)
        full = node.full_frame_bytes(frame)
        cast = decide_cast(requests, cfg.broadcast_threshold)
        size = payload.size_bytes
        sent = size if cast is CastMode.BROADCAST else size * requests
        res.cast_modes.add(cast.value)
        res.image_messages += 1
        res.images_new += is_new
        res.images_old += not is_new
        res.foreground_bytes += size
        res.full_frame_bytes += full
        res.events.append((t_ns / 1e9, sent, size * requests, size if ours else 0))
        if writer is not None:
            writer.write(
                sent_topic(name),
                MirrorTransmission(
                    t_ns,
                    name,
                    "image",
                    cast.value,
                    requests,
                    size,
                    sent,
                    "new" if is_new else "old",
                    len(payload.regions),
                    full,
                    round(node_ms, 3),
                ),
                t_ns,
            )
        if not ours or filt is None:
            continue
        # our robot: communication, then LED detection on the received crops
        if cast is CastMode.BROADCAST:
            comm_ms = cfg.broadcast_wait_ms + size / cfg.broadcast_kBps
            lost = bool(rng.random() < cfg.broadcast_loss)
        else:
            position = int(rng.integers(1, requests + 1))
            comm_ms = cfg.link_latency_ms + position * size / cfg.link_kBps
            lost = False
        if lost:
            res.broadcast_lost += 1
            continue
        started = time.perf_counter()
        front, back = detect_leds(payload.crops(), led)
        fix = (
            None
            if front is None or back is None
            else fix_from_leds(front, back, cams[name], led, payload.t_ns)
        )
        robot_ms = (time.perf_counter() - started) * 1e3
        res.robot_ms.append(robot_ms)
        res.fix_attempts += 1
        last_answer = (t_ns, cfg.sensing_ms + node_ms + comm_ms + robot_ms)
        if fix is None:
            continue
        res.fixes += 1
        sp, sy = filt.fix_sigma(fix, cams[name], led.led_height_m)
        arrival = t_ns + int((comm_ms + cfg.processing_ms) * 1e6)
        pending.append((arrival, fix, sp, sy))
        pending.sort(key=lambda p: p[0])
    for t_ns, gx, gy in gt_wait:
        score(t_ns, gx, gy)
    res.duration_s = 0.0 if t_first is None else (t_last - t_first) / 1e9  # type: ignore[operator]
    return res


def _mean(values: Iterable[float]) -> float | None:
    v = [x for x in values if math.isfinite(x)]
    return None if not v else round(float(np.mean(v)), 4)


def report_metrics(
    res: SmirrorResult, cfg: SmirrorConfig
) -> dict[str, float | int | str | bool | None]:
    """The report figures of a run (keys of issue 5 first, then the details)."""
    err = np.asarray(res.error_m)
    cov = np.asarray(res.in_coverage, bool)
    delay = np.asarray(res.delay_ms)
    central = cfg.mode is Mode.CENTRALIZED
    ev = np.asarray(res.events, float).reshape(-1, 4)
    dur = max(res.duration_s, 1e-9)
    kbps = None if central else round(float(ev[:, 1].sum()) / dur / 1e3, 3)
    uni = None if central else round(float(ev[:, 2].sum()) / dur / 1e3, 3)
    # split the link's bytes by where the robot was when they were sent
    kin = kout = None
    if not central and len(res.t_s) > 1 and len(ev):
        ts = np.asarray(res.t_s)
        period = float(np.median(np.diff(ts)))
        idx = np.clip(np.searchsorted(ts, ev[:, 0], side="right") - 1, 0, len(ts) - 1)
        ev_cov = cov[idx]
        t_in, t_out = cov.sum() * period, (~cov).sum() * period
        kin = None if t_in == 0 else round(float(ev[ev_cov, 1].sum()) / t_in / 1e3, 3)
        kout = None if t_out == 0 else round(float(ev[~ev_cov, 1].sum()) / t_out / 1e3, 3)
    if central:
        cast = "none"
    elif len(res.cast_modes) == 1:
        cast = next(iter(res.cast_modes))
    elif res.cast_modes:
        cast = "mixed"
    else:
        cast = "none"
    rng = np.asarray(res.range_m)
    return {
        "system": "smirror",
        "mode": cfg.mode.value,
        "error_m_mean": _mean(err),
        "error_m_mean_in_coverage": _mean(err[cov]),
        "error_m_mean_out_coverage": _mean(err[~cov]),
        "delay_ms_mean": _mean(delay),
        "kbps_mean": kbps,
        "kbps_unicast_equivalent": uni,
        "requesters": res.requesters,
        "cast_mode": cast,
        "kbps_in_coverage": kin,
        "kbps_out_coverage": kout,
        "delay_ms_mean_in_coverage": _mean(delay[cov]),
        "delay_ms_mean_out_coverage": _mean(delay[~cov]),
        "error_m_p95": None if not len(err) else round(float(np.percentile(err, 95)), 4),
        "error_m_max": None if not len(err) else round(float(err.max()), 4),
        "error_m_in_coverage_le_11m_max_bin": _max_bin(err[cov], rng[cov]),
        "error_m_per_m_range": _slope(err[cov], rng[cov]),
        "coverage_fraction": None if not len(cov) else round(float(cov.mean()), 4),
        "samples": len(err),
        "foreground_bytes": res.foreground_bytes,
        "full_frame_bytes": res.full_frame_bytes,
        "full_to_foreground_ratio": None
        if not res.foreground_bytes
        else round(res.full_frame_bytes / res.foreground_bytes, 2),
        "image_messages": res.image_messages,
        "images_new": res.images_new,
        "images_old": res.images_old,
        "beacons": res.beacons,
        "node_ms_median": None if not res.node_ms else round(float(np.median(res.node_ms)), 3),
        "robot_ms_median": None if not res.robot_ms else round(float(np.median(res.robot_ms)), 3),
        "fix_attempts": res.fix_attempts,
        "fixes": res.fixes,
        "fixes_used": res.fixes_used,
        "broadcast_lost": res.broadcast_lost,
        "decode_failures": res.decode_failures,
        "duration_s": round(res.duration_s, 3),
    }


def _max_bin(err: np.ndarray, rng: np.ndarray) -> float | None:
    """Largest mean error over the 1 m range bins from 2 to 11 m (Fig. 4.6's claim: <= 0.5 m)."""
    out = []
    for lo in range(2, 11):
        sel = (rng >= lo) & (rng < lo + 1)
        if sel.sum() >= 3:
            out.append(float(err[sel].mean()))
    return None if not out else round(max(out), 4)


def _slope(err: np.ndarray, rng: np.ndarray) -> float | None:
    """Least-squares growth of the in-coverage error with range (m of error per m of range)."""
    ok = np.isfinite(rng)
    if ok.sum() < 10 or np.ptp(rng[ok]) < 1.0:
        return None
    return round(float(np.polyfit(rng[ok], err[ok], 1)[0]), 5)


def error_by_range(
    res: SmirrorResult, edges: Iterable[float] = range(2, 13)
) -> list[tuple[float, float | None, int]]:
    """(bin start m, mean error m, samples) of in-coverage samples by distance to the node."""
    err, rng = np.asarray(res.error_m), np.asarray(res.range_m)
    e = list(edges)
    out = []
    for lo, hi in zip(e[:-1], e[1:], strict=True):
        sel = (rng >= lo) & (rng < hi)
        out.append((float(lo), None if not sel.any() else float(err[sel].mean()), int(sel.sum())))
    return out


def run(
    reader: LogReader,
    writer: LogWriter,
    config: SmirrorConfig | None = None,
    progress: Progress | None = None,
) -> MetricReport:
    """S-Mirror over ``reader``: writes robot poses and node transmissions, returns the report."""
    return run_detailed(reader, writer, config, progress)[0]


def run_detailed(
    reader: LogReader,
    writer: LogWriter | None,
    config: SmirrorConfig | None = None,
    progress: Progress | None = None,
) -> tuple[MetricReport, SmirrorResult]:
    """:func:`run` that also returns the per-sample figures (plots and benchmarks bin them)."""
    cfg = config or SmirrorConfig()
    res = localize(reader, cfg, writer, progress)
    report = MetricReport(
        t_ns=reader.end_ns or 0,
        processor="smirror",
        metrics=report_metrics(res, cfg),
        params={
            "mode": cfg.mode.value,
            "broadcast_threshold": cfg.broadcast_threshold,
            "requesters": res.requesters,
            "robot": res.robot,
            "link_kBps": cfg.link_kBps,
            "broadcast_kBps": cfg.broadcast_kBps,
            "beacon_period_s": cfg.beacon_period_s,
            "sensing_ms": cfg.sensing_ms,
        },
    )
    return report, res
