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
from functools import partial

import cv2
import numpy as np
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation

from trackctl.bridgeloc.bridge import (
    BridgeObservation,
    CameraGeometry,
    MapTag,
    TagMap,
    bridge_branches,
    bridge_pnp,
    bridge_pose,
    corner_jacobian,
    map_jacobian,
    project_corners,
    tag_corners_in_camera,
)
from trackctl.bridgeloc.config import (
    POSE_TOPIC,
    BridgeLocConfig,
    Mode,
    PoseMethod,
    annotations_topic,
)
from trackctl.bridgeloc.detect import DetectorConfig, TagDetection, detect_tags, read_oriented
from trackctl.bridgeloc.ekf import RobotEkf, corner_covariance, pose_cov
from trackctl.bridgeloc.smooth import RtsSmoother, position_sigma
from trackctl.bridgeloc.tags import check_family
from trackctl.errors import InputError, MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.geometry.odometry import DiffDrive, increment, integrate_step
from trackctl.ingest.site import record_number, warn_site_defaults
from trackctl.logs import topics
from trackctl.logs.foxglove import (
    map_base_transform,
    map_odom_transform,
    odom_base_transform,
    pose_in_frame,
)
from trackctl.logs.messages import CameraModel, GroundTruth, WheelOdometry
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress

__all__ = [
    "Setup",
    "load_setup",
    "IcamFix",
    "IcamFixes",
    "ir_blobs",
    "moved_together",
    "map_tags",
    "RobotPass",
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


def ir_blobs(
    gray: np.ndarray,
    threshold: int,
    min_area: int,
    isolation: float = 0.75,
    rejected: list[np.ndarray] | None = None,
) -> list[tuple[np.ndarray, int]]:
    """Every saturated blob that stands alone (centroid px, area px): the robot's IR light and
    whatever else glows as it does (lamps, reflections; the caller tells them apart).

    A light source is far brighter than full scale: its core is clipped (>= 250), where a
    bright surface (white paper under strong light) only crosses the threshold in noisy
    fragments. And it is a compact spot whose surroundings are dark: the median grey of an
    annulus at 2.5-4 blob radii must stay below ``isolation`` x ``threshold`` (a window or a
    large bright patch is not a light). Blobs of 12 px or more must be round (a disk's aspect
    and fill). Centroids of the blobs turned down are appended to
    ``rejected`` (the static-fixture test counts every bright spot, kept or not)."""
    _, binary = cv2.threshold(gray, threshold, 255, cv2.THRESH_BINARY)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(binary)
    h, w = gray.shape
    # a light source is far beyond full scale: its core is clipped, not just over threshold
    clipped = np.bincount(labels[gray >= 250], minlength=n)
    out = []
    for k in range(1, n):
        area = int(stats[k, cv2.CC_STAT_AREA])
        if area < min_area or clipped[k] < 1:
            if rejected is not None and area >= min_area:
                rejected.append(cents[k])
            continue
        bw, bh = int(stats[k, cv2.CC_STAT_WIDTH]), int(stats[k, cv2.CC_STAT_HEIGHT])
        if area >= 12 and not _round(area, bw, bh):
            if rejected is not None:
                rejected.append(cents[k])
            continue
        cx, cy = cents[k]
        r = math.sqrt(area / math.pi) + 1.5
        r_in, r_out = 2.5 * r, 4.0 * r
        x0, x1 = max(0, int(cx - r_out)), min(w, int(cx + r_out) + 1)
        y0, y1 = max(0, int(cy - r_out)), min(h, int(cy + r_out) + 1)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        d2 = (xx - cx) ** 2 + (yy - cy) ** 2
        ring = gray[y0:y1, x0:x1][(d2 >= r_in * r_in) & (d2 <= r_out * r_out)]
        if ring.size and float(np.median(ring)) >= isolation * threshold:
            if rejected is not None:
                rejected.append(cents[k])
            continue
        out.append((cents[k], area))
    return out


def _round(area: int, width: int, height: int) -> bool:
    """A light's glow is a disk: about as wide as high, filling ~pi/4 of its bounding box (a
    clipped patch of paper is a rectangle or a fragment cut by print)."""
    fill = area / max(width * height, 1)
    return max(width, height) <= 1.6 * min(width, height) and 0.55 <= fill <= 0.92


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
    where = f"{reader.path}: metadata bridgeloc"
    n = cfg.tag_n or int(record_number(meta, "tag_n", 2, where))
    family = cfg.tag_family or meta.get("tag_family", "plain")
    check_family(family, n)
    rgeo = CameraGeometry.from_model(models[rcam_name]) if needs_robot else None
    _warn_defaults(reader, cfg, meta)
    return Setup(
        meta=meta,
        robot=cfg.robot or meta.get("robot", "r1"),
        rcam_name=rcam_name,
        tag_n=n,
        tag_size_m=cfg.tag_size_m or record_number(meta, "tag_size_m", 0.30, where),
        ir_height_m=cfg.ir_height_m or record_number(meta, "ir_height_m", 0.65, where),
        needs_robot=needs_robot,
        infra=infra,
        det_cfg=DetectorConfig(n=n, family=family),
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


@dataclass(frozen=True, slots=True)
class IcamFix:
    """One IR-light candidate on the ground plane, with its 2x2 covariance."""

    xy: np.ndarray
    cov: np.ndarray
    camera: str
    systematic_m: float = 0.0
    """The part of the std that is the same for every fix of this camera there (calibration,
    the light's offset): repeated fixes do not average it out."""


def moved_together(
    first: tuple[np.ndarray, np.ndarray],
    last: tuple[np.ndarray, np.ndarray],
    min_move_m: float = 0.5,
    tol_m: float = 0.3,
    tol_frac: float = 0.2,
) -> bool:
    """Whether a light that keeps disagreeing with the filter is the robot's: between the first
    and the last of its rejected fixes ((fix, state) positions) the filter's state moved at
    least ``min_move_m`` and the light moved by the same displacement (within ``tol_m`` +
    ``tol_frac`` of it). A lamp or a reflection stays put while the wheels turn; a robot that
    stands still gives no evidence either way, and the state is kept."""
    moved = last[1] - first[1]
    seen = last[0] - first[0]
    dist = float(np.hypot(*moved))
    return dist >= min_move_m and float(np.hypot(*(seen - moved))) <= tol_m + tol_frac * dist


class IcamFixes:
    """The robot's IR light seen by the infrastructure cameras: candidates by frame time.

    Blobs lit at the same pixel in at least ``static_share`` of a camera's frames are fixtures
    (lamps, reflections), not a robot that drives, and are dropped."""

    def __init__(self, half_period_ns: int) -> None:
        self.fixes: dict[int, list[IcamFix]] = {}
        self.half_period_ns = half_period_ns
        self.times = np.zeros(0, np.int64)
        self.static_dropped = 0
        self._cells: dict[str, dict[tuple[int, int], int]] = {}
        self._frames: dict[str, int] = {}
        self._pending: list[tuple[int, tuple[int, int], IcamFix]] = []

    CELL_PX = 6

    @property
    def frames_per_camera(self) -> dict[str, int]:
        return dict(self._frames)

    def frame(self, camera: str) -> None:
        self._frames[camera] = self._frames.get(camera, 0) + 1

    def lit(self, camera: str, px: np.ndarray) -> tuple[int, int]:
        """Count a bright spot at pixel ``px`` of one of ``camera``'s frames."""
        cell = (int(px[0]) // self.CELL_PX, int(px[1]) // self.CELL_PX)
        counts = self._cells.setdefault(camera, {})
        counts[cell] = counts.get(cell, 0) + 1
        return cell

    def add(self, t_ns: int, px: np.ndarray, fix: IcamFix) -> None:
        self._pending.append((t_ns, self.lit(fix.camera, px), fix))

    def finalize(self, static_share: float = 0.5, min_frames: int = 20) -> None:
        for t_ns, (cx, cy), fix in self._pending:
            counts = self._cells[fix.camera]
            lit = sum(counts.get((cx + i, cy + j), 0) for i in (-1, 0, 1) for j in (-1, 0, 1))
            frames = self._frames.get(fix.camera, 0)
            if frames >= min_frames and lit >= static_share * frames:
                self.static_dropped += 1
                continue
            self.fixes.setdefault(t_ns, []).append(fix)
        self._pending.clear()
        self._cells.clear()
        self.times = np.array(sorted(self.fixes), dtype=np.int64)

    def candidates(self, t_ns: int) -> list[IcamFix]:
        """The candidates of the infrastructure frame nearest ``t_ns`` within half a frame
        period (empty if none)."""
        times = self.times
        if not len(times):
            return []
        i = int(np.searchsorted(times, t_ns))
        best = None
        for j in (i - 1, i):
            if (
                0 <= j < len(times)
                and abs(int(times[j]) - t_ns) <= self.half_period_ns
                and (best is None or abs(int(times[j]) - t_ns) < abs(best - t_ns))
            ):
                best = int(times[j])
        return [] if best is None else self.fixes[best]

    def at(self, t_ns: int, agree_m: float = 0.5) -> np.ndarray | None:
        """The fix at ``t_ns`` without a motion model: the covariance-weighted mean of the
        candidates when they agree (several cameras seeing the light), None when there are none
        or they disagree (a lamp the static test missed: ambiguous)."""
        cands = self.candidates(t_ns)
        if not cands:
            return None
        w = [np.linalg.inv(c.cov) for c in cands]
        mean = np.linalg.solve(sum(w), sum(wi @ c.xy for wi, c in zip(w, cands, strict=True)))
        if any(np.linalg.norm(c.xy - mean) > agree_m for c in cands):
            return None
        return mean


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
    e = cfg.ekf
    tag_map = TagMap(setup.cam_h, systematic_per_m=math.hypot(e.calib_rad, e.map_scale_frac))
    icam = IcamFixes(0)
    max_ir_m = 0.25  # the light's glow is never wider than this on the ground plane
    geos = {name: CameraGeometry.from_model(m) for name, m in infra.items()}
    pins = {name: PinholeCamera(m) for name, m in infra.items()}
    infra_period: dict[str, int] = {}
    last_t: dict[str, int] = {}
    n_msgs = 0
    wanted = [topics.image(c) for c in infra]
    total = reader.count(wanted)
    for msg in reader.messages(wanted):
        n_msgs += 1
        if progress is not None and n_msgs % 10 == 0:
            progress(n_msgs, total, "mapping tags in the infrastructure frames")
        frame_id = msg.message.frame_id
        cam = frame_id if frame_id in infra else msg.topic.strip("/").split("/")[0]
        gray = _imdecode(msg.message.data)
        t0 = time.perf_counter()
        dets = _oriented(gray, detect_tags(gray, setup.det_cfg), geos[cam], setup)
        det_times.append(time.perf_counter() - t0)
        for d in dets:
            tag_map.add(d, geos[cam], setup.tag_size_m)
        labels = [d.pattern_id for d in dets]
        writer.write(
            annotations_topic(cam), _annotations(msg.log_time_ns, dets, labels), msg.log_time_ns
        )
        icam.frame(cam)
        others: list[np.ndarray] = []
        for px, area in ir_blobs(gray, cfg.ir_threshold, cfg.ir_min_area_px, rejected=others):
            fix = _icam_fix(pins[cam], px, area, setup.ir_height_m, cfg, max_ir_m)
            if fix is not None:
                icam.add(msg.log_time_ns, px, fix)
            else:
                others.append(px)
        for px in others:  # bright spots that are no fix still show where the fixtures are
            icam.lit(cam, px)
        if cam in last_t:
            infra_period.setdefault(cam, msg.log_time_ns - last_t[cam])
        last_t[cam] = msg.log_time_ns
    tag_map.finalize(icam.frames_per_camera)
    icam.half_period_ns = max(infra_period.values(), default=200_000_000) // 2
    icam.finalize()
    return tag_map, icam, n_msgs


def _oriented(
    gray: np.ndarray, dets: list[TagDetection], geo: CameraGeometry, setup: Setup
) -> list[TagDetection]:
    """Detections re-read with their mount (square or diamond) from their 3-D pose against the
    world's up direction (``geo.R`` maps the camera to a frame with z up: world or robot base)."""
    up = geo.R.T @ np.array([0.0, 0.0, 1.0])
    out = []
    for d in dets:
        pc = tag_corners_in_camera(d, geo, setup.tag_size_m)
        got = d if pc is None else read_oriented(gray, d, pc, up, setup.det_cfg)
        if got is not None:
            out.append(got)
    return out


def _icam_fix(
    pin: PinholeCamera,
    px: np.ndarray,
    area: int,
    ir_height_m: float,
    cfg: BridgeLocConfig,
    max_size_m: float,
) -> IcamFix | None:
    """Eq. 4.2: the blob's pixel on the plane z = IR height, with its covariance (the ground
    distance per pixel grows as d^2 / (f * drop)); None when the ray misses the plane or the
    blob is too big to be the light at that distance."""
    g = pin.ground_point(px[None], ground_z=ir_height_m)[0]
    if np.isnan(g).any():
        return None
    f = float(pin.model.fx_px)
    d = float(np.linalg.norm(pin.position - g))
    if math.sqrt(area) * d / f > max_size_m:
        return None
    drop = max(0.3, abs(float(pin.position[2]) - ir_height_m))
    per_px = d * d / (f * drop)
    e = cfg.ekf
    # pixel noise and the camera's calibration error, both magnified by the grazing ray
    systematic = math.hypot(e.icam_floor_m, e.calib_rad * f * per_px)
    sigma = math.hypot(systematic, e.icam_sigma_px * per_px)
    return IcamFix(g[:2].copy(), np.eye(2) * sigma**2, pin.model.camera, systematic)


def _in_front(pose: Pose, world: np.ndarray, cam: CameraGeometry, min_depth_m: float = 0.2) -> bool:
    """Whether mapped corners lie in front of the robot camera at ``pose`` (projection is
    meaningless behind it)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    r_wb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    p_c = r_wb @ cam.t + [pose[0], pose[1], 0.0]
    depth = (np.asarray(world) - p_c) @ (r_wb @ cam.R)[:, 2]
    return bool((depth > min_depth_m).all())


def _usable_start(cov: np.ndarray, max_sigma_m: float) -> bool:
    """A bridged pose good enough to start (or restart) the filter: position std within
    ``max_sigma_m`` (a far tag seen near head-on is two-fold ambiguous and is not)."""
    return float(np.sqrt(np.linalg.eigvalsh(cov[:2, :2]).max())) <= max_sigma_m


def _reproject(pose: np.ndarray, world: np.ndarray, cam: CameraGeometry) -> np.ndarray:
    return project_corners(pose, world, cam).reshape(-1)


def _bridge_fix(
    obs: list[tuple[TagDetection, str, np.ndarray]],
    tag_map: TagMap,
    rgeo: CameraGeometry,
    setup: Setup,
    cfg: BridgeLocConfig,
) -> tuple[Pose, np.ndarray] | None:
    """Basic bridging: the tags whose signature is unique in the map -> robot pose (Eq. 4.9)
    and its covariance."""
    unique = []
    for d, sig, _ in obs:
        cands = tag_map.candidates(sig)
        if len(cands) == 1:  # without motion history a shared pattern cannot be told apart
            unique.append(BridgeObservation(d, cands[0].corners))
    if not unique:
        return None
    return _bridged(unique, rgeo, setup, cfg)


def _bridged(
    observations: list[BridgeObservation],
    rgeo: CameraGeometry,
    setup: Setup,
    cfg: BridgeLocConfig,
) -> tuple[Pose, np.ndarray] | None:
    e = cfg.ekf
    out = bridge_pose(
        observations,
        rgeo,
        setup.tag_size_m,
        e.corner_sigma_px,
        e.bridge_floor_m,
        e.bridge_floor_rad,
    )
    if out is None or cfg.pose is PoseMethod.LSTSQ:
        return out
    # --pose pnp: the pose from one solvePnP, the covariance from the same propagation
    w = np.concatenate([o.world for o in observations])
    img = np.concatenate([o.detection.corners for o in observations])
    pnp = bridge_pnp(w, img, rgeo)
    return None if pnp is None else (pnp, out[1])


def _by_product_poses(
    bridge: tuple[Pose, np.ndarray] | None, fix: np.ndarray | None
) -> tuple[Pose | None, Pose | None]:
    """The I-Cam and Basic modes' poses at a robot frame: the I-Cam fix (heading 0), and the
    fix with the bridged heading, else the bridged pose."""
    icam_pose = None if fix is None else (float(fix[0]), float(fix[1]), 0.0)
    basic_pose: Pose | None = None
    if fix is not None:
        basic_pose = (float(fix[0]), float(fix[1]), bridge[0][2] if bridge else 0.0)
    elif bridge is not None:
        basic_pose = bridge[0]
    return icam_pose, basic_pose


@dataclass
class RobotPassStats:
    """Counters of the robot pass (reported)."""

    bridge_fixes: int = 0
    icam_fixes: int = 0
    tag_observations: int = 0
    robot_frames: int = 0
    ambiguous_matches: int = 0
    rejected_updates: int = 0
    frames_with_pose: int = 0
    frames_with_fix: int = 0
    icam_fused: int = 0
    restarts: int = 0
    ambiguous_skipped: int = 0


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
        where = f"{reader.path}: metadata robot/{setup.robot}"
        self.drive = DiffDrive(
            record_number(rmeta, "ticks_per_m", default.ticks_per_m, where),
            record_number(rmeta, "wheel_base_m", default.wheel_base_m, where),
        )
        self.ekf = RobotEkf(
            cfg.ekf, RtsSmoother(self._emit_full, cfg.smooth_lag_s) if cfg.smooth else None
        )
        self.truth: dict[int, tuple[float, float]] = {}
        self.est: Estimates = []
        self.sigmas: dict[int, float] = {}
        """Full mode: the EKF's largest position std at every output pose."""
        self.other: dict[Mode, Estimates] = {m: [] for m in Mode}
        self.bridge_only: Estimates = []
        self._causal_sigma: dict[int, float] = {}
        self.robot_sightings: dict[int, int] = {}
        """Map tag (index in the map) -> robot frames that used it."""
        self.stats = RobotPassStats()
        self._icam_next = 0
        self.max_range_m = (
            cfg.max_range_m
            if cfg.max_range_m is not None
            else record_number(setup.meta, "max_range_m", 4.5, f"{reader.path}: metadata bridgeloc")
        )
        self._bad_frames = 0
        self._icam_rejects = 0
        self._icam_run: tuple[np.ndarray, np.ndarray] | None = None
        """(fix, state) positions at the first of the current run of rejected lone I-Cam fixes."""
        self.prev_odom: WheelOdometry | None = None
        self.odom_topic = topics.odom(setup.robot)
        self.tf_topic = topics.transforms("/bridgeloc")
        self.odom_pose: Pose = (0.0, 0.0, 0.0)
        """The wheels alone, from the first odometry sample (the ``NAME/odom`` frame)."""
        self._odom_at: dict[int, Pose] = {}
        """Full mode with odometry: the wheels' pose at each robot frame waiting for its
        (smoothed) estimate."""
        self._odom_tree = cfg.mode is Mode.FULL and self.odom_topic in setup.present
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
        if self.setup.needs_robot:
            self._fuse_icam_until(t_ns)
        if topic == self.odom_topic:
            self._on_odometry(message)  # type: ignore[arg-type]
            self._write_odom_frame(t_ns)
            return
        if self.cfg.mode is Mode.ICAM:
            fix = self.icam.at(t_ns)
            self.est.append((t_ns, None if fix is None else (float(fix[0]), float(fix[1]), 0.0)))
            return
        self._on_frame(t_ns, message, det_times)

    def _fuse_icam_until(self, t_ns: int) -> None:
        """Full mode: I-Cam fixes enter the EKF at their own frame times (the infrastructure
        and robot cameras are not synchronised): the candidate that fits the state best
        (least NIS; a lamp the static test missed fits worse than the robot's light), gated."""
        times = self.icam.times
        while self._icam_next < len(times) and int(times[self._icam_next]) <= t_ns:
            t = int(times[self._icam_next])
            self._icam_next += 1
            cands = self.icam.fixes[t]
            ekf = self.ekf
            ekf.t_ns = t
            if not ekf.initialized:
                fix = self.icam.at(t)
                if fix is not None:  # position only; a tag then gives the heading
                    ekf.update_position(fix, np.mean([c.cov for c in cands], axis=0))
                continue
            best = min(cands, key=lambda c: ekf.position_nis(c.xy, c.cov))
            ok = ekf.update_position(best.xy, best.cov)
            if ok:
                # like a mapped tag's error, the camera's does not average out over its fixes
                ekf.floor_position(best.systematic_m)
            self.stats.icam_fused += ok
            self.stats.rejected_updates += not ok
            self._icam_rejects = 0 if ok else self._icam_rejects + 1
            if ok or len(cands) != 1:
                self._icam_run = None
                continue
            state = np.asarray(ekf.pose[:2], float)
            if self._icam_run is None:
                self._icam_run = (np.asarray(best.xy, float), state)
            if self._icam_rejects >= self.cfg.ekf.max_rejects and moved_together(
                self._icam_run, (np.asarray(best.xy, float), state)
            ):
                # the one light the cameras see keeps disagreeing (a wrong start, slip), and it
                # moved as the wheels say the robot did: the position is the fix's, the heading
                # kept but no longer trusted
                ekf.init((*best.xy, ekf.pose[2]), pose_cov(best.cov, 0.5**2))
                self._icam_rejects = 0
                self._icam_run = None
                self.stats.restarts += 1

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
                self.odom_pose = integrate_step(*self.odom_pose, *step)
        self.prev_odom = od

    def _write_odom_frame(self, t_ns: int) -> None:
        """Full mode: ``NAME/odom -> NAME/base_link`` at each odometry sample (the wheels)."""
        if self._odom_tree:
            tf = odom_base_transform(t_ns, self.setup.robot, *self.odom_pose)
            self.writer.write(self.tf_topic, tf, t_ns)

    def _write_map_frame(self, t_ns: int, pose: Pose) -> None:
        """The estimate as a frame: ``map -> NAME/odom`` (full mode with odometry: the
        correction of the wheels' pose at that frame), else ``map -> NAME/base_link``."""
        robot = self.setup.robot
        if self._odom_tree:
            odom = self._odom_at.pop(t_ns, self.odom_pose)
            tf = map_odom_transform(t_ns, robot, pose, odom)
        else:
            tf = map_base_transform(t_ns, robot, *pose)
        self.writer.write(self.tf_topic, tf, t_ns)

    def _observe_tags(
        self, t_ns: int, data: bytes, det_times: list[float]
    ) -> list[tuple[TagDetection, str, np.ndarray]]:
        """Tags in a robot frame: (detection, pattern/mount signature, corners in the base
        frame) of those within range; annotations written for all."""
        setup, rgeo = self.setup, self.setup.rgeo
        assert rgeo is not None
        gray = _imdecode(data)
        t0 = time.perf_counter()
        dets = _oriented(gray, detect_tags(gray, setup.det_cfg), rgeo, setup)
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
            if math.hypot(ctr[0], ctr[1]) <= self.max_range_m:
                obs.append((d, sig, pb))
        self.writer.write(
            annotations_topic(setup.rcam_name), _annotations(t_ns, dets, labels), t_ns
        )
        return obs

    def _on_frame(self, t_ns: int, message: object, det_times: list[float]) -> None:
        self.stats.robot_frames += 1
        rgeo = self.setup.rgeo
        assert rgeo is not None
        obs = self._observe_tags(t_ns, message.data, det_times)  # type: ignore[attr-defined]
        raw = _bridge_fix(obs, self.tag_map, rgeo, self.setup, self.cfg)
        # a two-fold ambiguous pose (a far tag near head-on) is no fix: only Fig. 4.20's
        # bridging-alone scores see it
        bridge = raw if raw is not None and _usable_start(raw[1], self.cfg.max_sigma_m) else None
        fix = self.icam.at(t_ns)
        self._count_fixes(bridge, fix)
        # every mode's estimate comes out of the same pass (I-Cam and Basic are by-products)
        icam_pose, basic_pose = _by_product_poses(bridge, fix)
        self.ekf.t_ns = t_ns
        fused = self._ekf_update(t_ns, bridge, obs)
        if fused or fix is not None or bridge is not None:
            self.stats.frames_with_fix += 1
        self.bridge_only.append((t_ns, None if raw is None else raw[0]))
        self.other[Mode.ICAM].append((t_ns, icam_pose))
        self.other[Mode.BASIC].append((t_ns, basic_pose))
        self._output_full(t_ns)
        if self.cfg.mode is not Mode.FULL:
            self._output_by_product(t_ns, icam_pose if self.cfg.mode is Mode.ICAM else basic_pose)

    def _count_fixes(self, bridge: tuple[Pose, np.ndarray] | None, fix: np.ndarray | None) -> None:
        """Count the frame's usable bridged pose and I-Cam fix."""
        if bridge is not None:
            self.stats.bridge_fixes += 1
        if fix is not None:
            self.stats.icam_fixes += 1

    def _output_full(self, t_ns: int) -> None:
        """Full mode's estimate at a robot frame: none before the filter starts; else the
        filter's pose now, or the smoother's once it knows what followed."""
        if not self.ekf.initialized:
            self.other[Mode.FULL].append((t_ns, None))
            if self.cfg.mode is Mode.FULL:
                self.est.append((t_ns, None))
            return
        if self.cfg.mode is Mode.FULL:
            self.stats.frames_with_pose += 1
            if self._odom_tree:
                self._odom_at[t_ns] = self.odom_pose
        if self.ekf.smoother is not None:
            # the smoothed covariance also counts the map's and the cameras' systematic
            # errors as independent between fixes, and reads ~10x too sure of itself: the
            # std reported with a smoothed pose is the filter's (the larger of the two)
            self._causal_sigma[t_ns] = self.ekf.sigma_m
            self.ekf.output(t_ns)  # emitted by the smoother once it knows what followed
        else:
            self._emit_full(t_ns, self.ekf.kf.x, self.ekf.kf.P)

    def _output_by_product(self, t_ns: int, pose: Pose | None) -> None:
        """I-Cam or Basic mode: the run's estimate at a robot frame, written when it has one."""
        self.est.append((t_ns, pose))
        if pose is not None:
            self.stats.frames_with_pose += 1
            self.writer.write(POSE_TOPIC, pose_in_frame(t_ns, pose[0], pose[1], pose[2]), t_ns)
            self._write_map_frame(t_ns, pose)

    def _emit_full(self, t_ns: int, x: np.ndarray, p: np.ndarray) -> None:
        """Full mode's pose at a robot frame (smoothed unless ``--no-smooth``)."""
        pose = (float(x[0, 0]), float(x[1, 0]), float(x[2, 0]))
        sigma = self._causal_sigma.pop(t_ns, None) or position_sigma(p)
        self.other[Mode.FULL].append((t_ns, pose))
        if self.cfg.mode is Mode.FULL:
            self.est.append((t_ns, pose))
            self.sigmas[t_ns] = sigma
            self.writer.write(POSE_TOPIC, pose_in_frame(t_ns, *pose), t_ns)
            self._write_map_frame(t_ns, pose)

    def _ekf_update(
        self,
        t_ns: int,
        bridge: tuple[Pose, np.ndarray] | None,
        obs: list[tuple[TagDetection, str, np.ndarray]],
    ) -> bool:
        """Full mode: every tag seen, as the mapped tag it is most likely to be (the least NIS
        among those sharing its signature, Eq. 4.11's nearest-candidate rule), gated by NIS.
        Before the filter has a state (no I-Cam fix yet) it starts from the unique tags' bridged
        pose. True if anything was fused."""
        ekf, fused, rejected = self.ekf, False, False
        if not ekf.initialized:
            if bridge is None:
                return False  # wait for a usable bridged pose or an I-Cam fix
            ekf.init(*bridge)
            return True
        rgeo = self.setup.rgeo
        assert rgeo is not None
        for d, sig, _ in obs:
            mapped = self.tag_map.candidates(sig)
            if not mapped:
                continue
            if len(mapped) > 1:
                self.stats.ambiguous_matches += 1
            ok, tag = self._fuse_tag(d, mapped, rgeo)
            self.stats.rejected_updates += not ok
            rejected |= not ok
            if ok:
                fused = True
                self.stats.tag_observations += 1
                k = self.tag_map.tags.index(tag)
                self.robot_sightings[k] = self.robot_sightings.get(k, 0) + 1
        # frames in a row where the tags only disagreed with the state: after a few, a pose
        # bridged from uniquely identified tags restarts the filter (slip, kidnapping)
        self._bad_frames = 0 if fused or not rejected else self._bad_frames + 1
        if self._bad_frames >= self.cfg.ekf.max_rejects and bridge is not None:
            ekf.init(*bridge)
            self._bad_frames = 0
            self.stats.restarts += 1
            return True
        return fused

    def _fuse_tag(
        self, d: TagDetection, mapped: list[MapTag], rgeo: CameraGeometry
    ) -> tuple[bool, MapTag]:
        """One tag seen: its corner pixels are the measurement, h(r) their reprojection from
        the mapped corners (Eq. 4.12's role, with the heading the corners carry). Among tags
        sharing the signature the one with the least NIS is taken (Eq. 4.11's nearest
        candidate). While the heading is still unknown (started from an I-Cam fix) the
        bridged pose is used instead: the reprojection is too non-linear in the heading."""
        ekf, cfg, setup = self.ekf, self.cfg, self.setup
        if ekf.sigma_yaw > 0.3:
            options = []
            e = cfg.ekf
            for tag in mapped:  # each tag it may be, each PnP branch the pixels allow
                for pose, cov, _ in bridge_branches(
                    [BridgeObservation(d, tag.corners)],
                    rgeo,
                    setup.tag_size_m,
                    e.corner_sigma_px,
                    e.bridge_floor_m,
                    e.bridge_floor_rad,
                ):
                    options.append((ekf.pose_nis(pose, cov), (pose, cov), tag))
            if not options:
                return False, mapped[0]
            _, meas, tag = min(options, key=lambda o: o[0])
            ok = ekf.update_pose(*meas)
            if ok:
                ekf.floor_position(tag.sigma_m)
            return ok, tag
        z = np.asarray(d.corners, float).reshape(-1)
        scored = []
        for tag in mapped:
            if not _in_front(ekf.pose, tag.corners, rgeo):
                continue  # a tag sharing the pattern behind the robot cannot be this one
            # each corner's pixel noise, the camera's pitch, roll and mount error (all corners
            # together), and the map's error of the tag's position and yaw seen from here
            f = float(rgeo.K[0, 0])
            map_cov = np.diag([tag.sigma_m**2] * 3 + [cfg.ekf.map_yaw_rad**2])
            r = corner_covariance(
                len(z) // 2,
                cfg.ekf.corner_sigma_px,
                f * cfg.ekf.camera_tilt_rad,
                map_jacobian(ekf.pose, tag.corners, rgeo),
                map_cov,
            )
            jac = corner_jacobian(ekf.pose, tag.corners, rgeo)
            hx = partial(_reproject, world=tag.corners, cam=rgeo)
            scored.append((ekf.measurement_nis(z, hx, jac, r), tag, hx, jac, r))
        if not scored:
            return False, mapped[0]
        scored.sort(key=lambda o: o[0])
        if len(scored) > 1 and scored[1][0] - scored[0][0] < cfg.ekf.ambiguity_nis:
            # two mapped tags explain the corners about equally well: taking either could
            # pull the robot towards the wrong one (Eq. 4.11's nearest rule, with a margin)
            self.stats.ambiguous_skipped += 1
            return False, scored[0][1]
        _, tag, hx, jac, r = scored[0]
        ok = ekf.update_measurement(z, hx, jac, r)
        if ok:
            ekf.floor_position(tag.sigma_m)
        return ok, tag

    def finish(self) -> None:
        """The smoother emits the poses it still holds. I-Cam mode writes its poses once the
        pass is over: one per infrastructure frame that saw the IR light, at that frame's time
        (the ground truth is only where they are scored)."""
        self.ekf.finish()
        if self.cfg.mode is Mode.ICAM:
            for t in self.icam.times.tolist():
                fix = self.icam.at(int(t))
                if fix is not None:
                    pose = pose_in_frame(int(t), float(fix[0]), float(fix[1]), 0.0)
                    self.writer.write(POSE_TOPIC, pose, int(t))
                    self._write_map_frame(int(t), (float(fix[0]), float(fix[1]), 0.0))
