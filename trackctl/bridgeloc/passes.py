"""The two passes of a BridgeLoc run.

1. :func:`map_tags` (infrastructure cameras): every tag seen is placed on the map (Eq. 4.6) and
   the robot's IR light gives I-Cam position fixes (:class:`IcamFixes`);
2. :class:`RobotPass` (robot camera + odometry in time order): tags seen by the robot are bridged
   to the map (Basic mode, Eq. 4.9) and fused with odometry and I-Cam fixes in the EKF (Full
   mode, Eqs. 4.11-4.12); every mode's estimate comes out of the same pass.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation

from trackctl.bridgeloc.bridge import (
    CameraGeometry,
    TagMap,
    bridge_lstsq,
    bridge_pnp,
    tag_corners_in_camera,
)
from trackctl.bridgeloc.config import (
    POSE_TOPIC,
    BridgeLocConfig,
    Mode,
    PoseMethod,
    annotations_topic,
)
from trackctl.bridgeloc.detect import DetectorConfig, TagDetection, detect_tags
from trackctl.bridgeloc.ekf import RobotEkf
from trackctl.errors import InputError, MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.geometry.odometry import DiffDrive, increment
from trackctl.ingest.site import warn_site_defaults
from trackctl.logs import topics
from trackctl.logs.foxglove import pose_in_frame
from trackctl.logs.messages import CameraModel, GroundTruth, WheelOdometry
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress

__all__ = [
    "Setup",
    "load_setup",
    "IcamFixes",
    "map_tags",
    "RobotPass",
    "ir_light",
    "Pose",
    "Estimates",
]

Pose = tuple[float, float, float]
Estimates = list[tuple[int, Pose | None]]


def _imdecode(data: bytes) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise InputError("an image message cannot be decoded (expected JPEG/PNG)")
    return img


def _annotations(t_ns: int, dets: list[TagDetection], labels: list[str]) -> ImageAnnotations:
    msg = ImageAnnotations()
    for d, label in zip(dets, labels, strict=True):
        pa = PointsAnnotation(type=PointsAnnotation.Type.LINE_LOOP, thickness=2.0)
        pa.timestamp.FromNanoseconds(t_ns)
        for x, y in d.corners:
            p = pa.points.add()
            p.x, p.y = float(x), float(y)
        pa.outline_color.r, pa.outline_color.g, pa.outline_color.a = 0.1, 1.0, 1.0
        msg.points.append(pa)
        ta = TextAnnotation(text=label, font_size=12.0)
        ta.timestamp.FromNanoseconds(t_ns)
        ta.position.x, ta.position.y = float(d.corners[0][0]), float(d.corners[0][1]) - 4
        ta.text_color.r = ta.text_color.g = ta.text_color.a = 1.0
        msg.texts.append(ta)
    return msg


def ir_light(gray: np.ndarray, threshold: int, min_area: int) -> np.ndarray | None:
    """Pixel of the brightest saturated blob (the robot's IR light), or None."""
    _, binary = cv2.threshold(gray, threshold, 255, cv2.THRESH_BINARY)
    n, _, stats, cents = cv2.connectedComponentsWithStats(binary)
    if n <= 1:
        return None
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if stats[k, cv2.CC_STAT_AREA] < min_area:
        return None
    return cents[k]


def _models(reader: LogReader) -> dict[str, CameraModel]:
    names = [t for t, info in reader.topics().items() if info.schema_name == CameraModel.SCHEMA]
    out: dict[str, CameraModel] = {}
    for msg in reader.messages(names):
        m: CameraModel = msg.message
        out.setdefault(m.camera, m)
    return out


@dataclass
class Setup:
    """What a run reads from the log before the first frame: robot, cameras, tags."""

    meta: dict[str, str]
    robot: str
    rcam_name: str
    tag_n: int
    tag_size_m: float
    ir_height_m: float
    needs_robot: bool
    infra: dict[str, CameraModel]
    det_cfg: DetectorConfig
    rgeo: CameraGeometry | None
    cam_h: float
    present: set[str] = field(default_factory=set)


def load_setup(reader: LogReader, cfg: BridgeLocConfig) -> Setup:
    """The run's setup (configuration first, then the log's ``bridgeloc`` metadata, then the
    defaults).

    Raises:
        MissingTopicError: the robot camera's images or calibration (``/NAME/camera_model``) are
            missing (basic and full modes), or no infrastructure camera has a world pose.
    """
    meta = {**reader.metadata().get("bridgeloc", {}), **cfg.site.get("bridgeloc", {})}
    rcam_name = cfg.robot_camera or meta.get("robot_camera", "r1cam")
    tops = reader.topics()
    models = _models(reader)
    needs_robot = cfg.mode is not Mode.ICAM
    if needs_robot:
        _require_robot_camera(reader, rcam_name, models, cfg)
    infra = {
        name: m
        for name, m in models.items()
        if name != rcam_name and m.world_from_camera is not None and topics.image(name) in tops
    }
    if not infra:
        raise MissingTopicError(
            f"{reader.path}: no infrastructure camera with images and a /NAME/camera_model world "
            f"pose; bridgeloc needs at least one"
        )
    n = cfg.tag_n or int(meta.get("tag_n", 2))
    rgeo = CameraGeometry.from_model(models[rcam_name]) if needs_robot else None
    _warn_defaults(reader, cfg, meta)
    return Setup(
        meta=meta,
        robot=cfg.robot or meta.get("robot", "r1"),
        rcam_name=rcam_name,
        tag_n=n,
        tag_size_m=cfg.tag_size_m or float(meta.get("tag_size_m", 0.30)),
        ir_height_m=cfg.ir_height_m or float(meta.get("ir_height_m", 0.65)),
        needs_robot=needs_robot,
        infra=infra,
        det_cfg=DetectorConfig(n=n),
        rgeo=rgeo,
        cam_h=float(rgeo.t[2]) if rgeo is not None else 0.5,
        present=set(tops),
    )


_SITE_DEFAULTS = {
    "robot": ("robot", "r1"),
    "robot_camera": ("robot_camera", "r1cam"),
    "tag_n": ("tag_n", 2),
    "tag_size_m": ("tag_size_m", 0.30),
    "ir_height_m": ("ir_height_m", 0.65),
}


def _warn_defaults(reader: LogReader, cfg: BridgeLocConfig, meta: Mapping[str, str]) -> None:
    """One warning naming the setup values neither the command line, the site nor the log gave
    (their defaults are the simulator's, which a real site rarely matches)."""
    robot = cfg.robot or meta.get("robot", "r1")
    records = {**reader.metadata(), **cfg.site}
    missing = [
        f"{key}={default}"
        for attr, (key, default) in _SITE_DEFAULTS.items()
        if getattr(cfg, attr) is None and key not in meta
    ]
    rmd = records.get(f"robot/{robot}", {})
    drive = DiffDrive()
    wheels = (("ticks_per_m", drive.ticks_per_m), ("wheel_base_m", drive.wheel_base_m))
    missing += [f"robot/{robot} {k}={v}" for k, v in wheels if k not in rmd]
    warn_site_defaults(reader.path, [", ".join(missing)] if missing else [])


def _require_robot_camera(
    reader: LogReader, rcam_name: str, models: dict[str, CameraModel], cfg: BridgeLocConfig
) -> None:
    if topics.image(rcam_name) not in reader.topics():
        raise MissingTopicError(
            f"{reader.path}: {topics.image(rcam_name)} is missing; bridgeloc --mode "
            f"{cfg.mode.value} needs the robot camera's images"
        )
    rmodel = models.get(rcam_name)
    if rmodel is None or rmodel.world_from_camera is None:
        raise MissingTopicError(
            f"{reader.path}: {topics.camera_model(rcam_name)} is missing (or has no "
            f"world_from_camera = base <- camera pose); bridgeloc needs the robot camera "
            f"calibration"
        )


class IcamFixes:
    """The robot's IR light seen by the infrastructure cameras: ground positions by time."""

    def __init__(self, fixes: dict[int, list[np.ndarray]], half_period_ns: int) -> None:
        self.fixes = fixes
        self.times = np.array(sorted(fixes), dtype=np.int64)
        self.half_period_ns = half_period_ns

    def at(self, t_ns: int) -> np.ndarray | None:
        """The mean fix of the infrastructure frame nearest ``t_ns`` within half a frame
        period, or None."""
        times = self.times
        if not len(times):
            return None
        i = int(np.searchsorted(times, t_ns))
        best = None
        for j in (i - 1, i):
            if (
                0 <= j < len(times)
                and abs(int(times[j]) - t_ns) <= self.half_period_ns
                and (best is None or abs(int(times[j]) - t_ns) < abs(best - t_ns))
            ):
                best = int(times[j])
        return None if best is None else np.mean(self.fixes[best], axis=0)


def map_tags(
    reader: LogReader,
    setup: Setup,
    cfg: BridgeLocConfig,
    writer: LogWriter,
    progress: Progress | None,
    det_times: list[float],
) -> tuple[TagMap, IcamFixes, int]:
    """Pass 1 over the infrastructure cameras: the tag map (Eq. 4.6) and the I-Cam fixes.

    Returns:
        The finalized tag map, the I-Cam fixes, and the number of messages read.
    """
    infra = setup.infra
    tag_map = TagMap(setup.cam_h)
    fixes: dict[int, list[np.ndarray]] = {}
    geos = {name: CameraGeometry.from_model(m) for name, m in infra.items()}
    pins = {name: PinholeCamera(m) for name, m in infra.items()}
    infra_period: dict[str, int] = {}
    last_t: dict[str, int] = {}
    n_msgs = 0
    for msg in reader.messages([topics.image(c) for c in infra]):
        n_msgs += 1
        if progress is not None and n_msgs % 200 == 0:
            progress(n_msgs, None)
        frame_id = msg.message.frame_id
        cam = frame_id if frame_id in infra else msg.topic.strip("/").split("/")[0]
        gray = _imdecode(msg.message.data)
        t0 = time.perf_counter()
        dets = detect_tags(gray, setup.det_cfg)
        det_times.append(time.perf_counter() - t0)
        for d in dets:
            tag_map.add(d, geos[cam], setup.tag_size_m)
        labels = [d.pattern_id for d in dets]
        writer.write(
            annotations_topic(cam), _annotations(msg.log_time_ns, dets, labels), msg.log_time_ns
        )
        px = ir_light(gray, cfg.ir_threshold, cfg.ir_min_area_px)
        if px is not None:
            g = pins[cam].ground_point(px[None], ground_z=setup.ir_height_m)[0]
            if not np.isnan(g).any():
                fixes.setdefault(msg.log_time_ns, []).append(g[:2])
        if cam in last_t:
            infra_period.setdefault(cam, msg.log_time_ns - last_t[cam])
        last_t[cam] = msg.log_time_ns
    tag_map.finalize()
    half_period = max(infra_period.values(), default=200_000_000) // 2
    return tag_map, IcamFixes(fixes, half_period), n_msgs


def _bridge_fix(
    obs: list[tuple[TagDetection, str, np.ndarray]],
    tag_map: TagMap,
    rgeo: CameraGeometry,
    method: PoseMethod,
) -> tuple[float, float, float] | None:
    """Basic bridging: corners of uniquely identified tags, mapped and seen -> robot pose."""
    world, robot, image = [], [], []
    for d, sig, pb in obs:
        cands = tag_map.candidates(sig)
        if len(cands) != 1:
            continue  # without motion history a shared pattern cannot be told apart
        world.append(cands[0].corners)
        robot.append(pb)
        image.append(d.corners)
    if not world:
        return None
    w = np.concatenate(world)
    if method is PoseMethod.PNP:
        return bridge_pnp(w, np.concatenate(image), rgeo)
    return bridge_lstsq(w[:, :2], np.concatenate(robot)[:, :2])


@dataclass
class RobotPassStats:
    """Counters of the robot pass (reported)."""

    bridge_fixes: int = 0
    icam_fixes: int = 0
    tag_observations: int = 0
    robot_frames: int = 0
    ambiguous_matches: int = 0


class RobotPass:
    """Pass 2: the robot camera and odometry in time order; every mode's estimate at once."""

    def __init__(
        self,
        reader: LogReader,
        setup: Setup,
        cfg: BridgeLocConfig,
        tag_map: TagMap,
        icam: IcamFixes,
        writer: LogWriter,
    ) -> None:
        self.setup, self.cfg, self.tag_map, self.icam, self.writer = (
            setup,
            cfg,
            tag_map,
            icam,
            writer,
        )
        rmeta = {
            **reader.metadata().get(f"robot/{setup.robot}", {}),
            **cfg.site.get(f"robot/{setup.robot}", {}),
        }
        default = DiffDrive()
        self.drive = DiffDrive(
            float(rmeta.get("ticks_per_m", default.ticks_per_m)),
            float(rmeta.get("wheel_base_m", default.wheel_base_m)),
        )
        self.ekf = RobotEkf(cfg.ekf)
        self.truth: dict[int, tuple[float, float]] = {}
        self.est: Estimates = []
        self.other: dict[Mode, Estimates] = {m: [] for m in Mode}
        self.bridge_only: Estimates = []
        self.stats = RobotPassStats()
        self.prev_odom: WheelOdometry | None = None
        self.odom_topic = topics.odom(setup.robot)
        self.frame_topic: str | None = topics.image(setup.rcam_name) if setup.needs_robot else None
        if cfg.mode is Mode.ICAM:
            # I-Cam positions are the infrastructure frames; evaluate at ground-truth instants
            self.frame_topic = topics.GROUND_TRUTH

    def topics(self) -> list[str]:
        """Ground truth (metrics), odometry and the robot camera, those the log has."""
        stream = [topics.GROUND_TRUTH, self.odom_topic]
        if self.setup.needs_robot:
            stream.append(topics.image(self.setup.rcam_name))
        return [t for t in stream if t in self.setup.present]

    def on_message(self, topic: str, t_ns: int, message: object, det_times: list[float]) -> None:
        """Handle one message of the pass, in log-time order."""
        if topic == topics.GROUND_TRUTH:
            self._on_truth(t_ns, message)  # type: ignore[arg-type]
            if self.frame_topic != topics.GROUND_TRUTH:
                return
        if topic == self.odom_topic:
            self._on_odometry(message)  # type: ignore[arg-type]
            return
        fix = self.icam.at(t_ns)
        if self.cfg.mode is Mode.ICAM:
            self.est.append((t_ns, None if fix is None else (float(fix[0]), float(fix[1]), 0.0)))
            return
        self._on_frame(t_ns, message, fix, det_times)

    def _on_truth(self, t_ns: int, gt: GroundTruth) -> None:
        for e in gt.entities:
            if e.entity_id == self.setup.robot:
                self.truth[t_ns] = (e.position_m.x, e.position_m.y)

    def _on_odometry(self, od: WheelOdometry) -> None:
        # encoder ticks, or v/omega (nav_msgs/Odometry twist), or the robot's own poses
        if self.prev_odom is not None and self.setup.needs_robot:
            step = increment(self.prev_odom, od, self.drive)
            if step is not None:
                self.ekf.predict(*step)
        self.prev_odom = od

    def _observe_tags(
        self, t_ns: int, data: bytes, det_times: list[float]
    ) -> list[tuple[TagDetection, str, np.ndarray]]:
        """Tags in a robot frame: (detection, pattern/mount signature, corners in the base
        frame) of those within range; annotations written for all."""
        setup, rgeo = self.setup, self.setup.rgeo
        assert rgeo is not None
        gray = _imdecode(data)
        t0 = time.perf_counter()
        dets = detect_tags(gray, setup.det_cfg)
        det_times.append(time.perf_counter() - t0)
        labels = []
        obs = []
        for d in dets:
            pc = tag_corners_in_camera(d, rgeo, setup.tag_size_m)
            if pc is None:
                labels.append(d.pattern_id)
                continue
            pb = pc @ rgeo.R.T + rgeo.t
            ctr = pb.mean(axis=0)
            mount = "above" if ctr[2] > setup.cam_h else "below"
            sig = f"{d.pattern_id}/{mount}"
            labels.append(sig)
            if math.hypot(ctr[0], ctr[1]) <= self.cfg.max_range_m:
                obs.append((d, sig, pb))
        self.writer.write(
            annotations_topic(setup.rcam_name), _annotations(t_ns, dets, labels), t_ns
        )
        return obs

    def _on_frame(
        self, t_ns: int, message: object, fix: np.ndarray | None, det_times: list[float]
    ) -> None:
        self.stats.robot_frames += 1
        assert self.setup.rgeo is not None
        obs = self._observe_tags(t_ns, message.data, det_times)  # type: ignore[attr-defined]
        bridge = _bridge_fix(obs, self.tag_map, self.setup.rgeo, self.cfg.pose)
        if bridge is not None:
            self.stats.bridge_fixes += 1
        if fix is not None:
            self.stats.icam_fixes += 1
        # every mode's estimate comes out of the same pass (I-Cam and Basic are by-products)
        icam_pose = None if fix is None else (float(fix[0]), float(fix[1]), 0.0)
        basic_pose: Pose | None = None
        if fix is not None:
            basic_pose = (float(fix[0]), float(fix[1]), bridge[2] if bridge else 0.0)
        elif bridge is not None:
            basic_pose = bridge
        self._ekf_update(fix, bridge, obs)
        full_pose: Pose | None = None
        if self.ekf.initialized and self.ekf.sigma_m <= self.cfg.max_sigma_m:
            full_pose = self.ekf.pose
        self.bridge_only.append((t_ns, bridge))
        self.other[Mode.ICAM].append((t_ns, icam_pose))
        self.other[Mode.BASIC].append((t_ns, basic_pose))
        self.other[Mode.FULL].append((t_ns, full_pose))
        pose = {Mode.ICAM: icam_pose, Mode.BASIC: basic_pose, Mode.FULL: full_pose}[self.cfg.mode]
        self.est.append((t_ns, pose))
        if pose is not None:
            self.writer.write(POSE_TOPIC, pose_in_frame(t_ns, pose[0], pose[1], pose[2]), t_ns)

    def _ekf_update(
        self,
        fix: np.ndarray | None,
        bridge: Pose | None,
        obs: list[tuple[TagDetection, str, np.ndarray]],
    ) -> None:
        """Full mode: I-Cam fix, then the bridge pose to initialize, else every tag seen as a
        range-bearing observation of its mapped position (nearest candidate, gated)."""
        ekf, c = self.ekf, self.cfg.ekf
        if fix is not None:
            ekf.update_pose(float(fix[0]), float(fix[1]), None, c.fix_sigma_m, 0.0)
        if not ekf.initialized and bridge is not None:
            ekf.update_pose(*bridge, c.bridge_sigma_m, c.bridge_yaw_sigma_rad)
            return
        if not ekf.initialized:
            return
        for _, sig, pb in obs:
            ctr = pb.mean(axis=0)
            rng_m = math.hypot(ctr[0], ctr[1])
            bearing = math.atan2(ctr[1], ctr[0])
            cands = self.tag_map.candidates(sig)
            if not cands:
                continue
            seen_at = ekf.observed_position(rng_m, bearing)  # Eq. 4.11
            dists = [float(np.linalg.norm(t.center[:2] - seen_at)) for t in cands]
            k = int(np.argmin(dists))
            if len(cands) > 1:
                self.stats.ambiguous_matches += 1
            if dists[k] > c.gate_m + 2 * ekf.sigma_m:
                continue
            ekf.update_range_bearing(rng_m, bearing, cands[k].center[:2])  # Eq. 4.12
            self.stats.tag_observations += 1

    def finish(self) -> None:
        """I-Cam mode writes its poses once the pass is over: one per infrastructure frame that
        saw the IR light, at that frame's time (the ground truth is only where they are scored)."""
        if self.cfg.mode is Mode.ICAM:
            for t in self.icam.times.tolist():
                fix = self.icam.at(int(t))
                if fix is not None:
                    pose = pose_in_frame(int(t), float(fix[0]), float(fix[1]), 0.0)
                    self.writer.write(POSE_TOPIC, pose, int(t))
