"""BridgeLoc over a log: camera images + wheel odometry -> robot poses, tag detections, report.

One library function, :func:`run`, is the whole pipeline; ``trackctl bridgeloc eval`` and the
``bridgeloc`` processor call it. Two streaming passes: (1) the infrastructure cameras localize the
static tags (Eq. 4.6) and the robot's IR light (I-Cam); (2) the robot's images and odometry are
replayed in time order: bridging (Eq. 4.9) and the EKF (Eqs. 4.10-4.12).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from enum import StrEnum

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
from trackctl.bridgeloc.detect import DetectorConfig, TagDetection, detect_tags
from trackctl.bridgeloc.ekf import EkfConfig, RobotEkf
from trackctl.errors import InputError, MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.geometry.odometry import DiffDrive
from trackctl.logs import topics
from trackctl.logs.foxglove import pose_in_frame
from trackctl.logs.messages import CameraModel, GroundTruth, MetricReport, WheelOdometry
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress

__all__ = ["POSE_TOPIC", "BridgeLocConfig", "Mode", "PoseMethod", "annotations_topic", "run"]

POSE_TOPIC = "/bridgeloc/pose"


def annotations_topic(camera: str) -> str:
    """Tag detections of a camera: ``/NAME/tag_annotations`` (foxglove.ImageAnnotations)."""
    return f"/{camera}/tag_annotations"


class Mode(StrEnum):
    """``full``: EKF with odometry; ``basic``: I-Cam + bridging only; ``icam``: I-Cam only."""

    FULL = "full"
    BASIC = "basic"
    ICAM = "icam"


class PoseMethod(StrEnum):
    """Robot pose from the bridged corners: Eq. 4.9 least squares, or one solvePnP."""

    LSTSQ = "lstsq"
    PNP = "pnp"


@dataclass(frozen=True, slots=True)
class BridgeLocConfig:
    """Configuration of a BridgeLoc run (``None`` = take it from the log's ``bridgeloc``
    metadata, else the default)."""

    mode: Mode = Mode.FULL
    pose: PoseMethod = PoseMethod.LSTSQ
    robot: str | None = None
    robot_camera: str | None = None
    tag_n: int | None = None
    tag_size_m: float | None = None
    ir_height_m: float | None = None
    max_sigma_m: float = 0.5
    """Full mode: a position counts as localized while the EKF's position std is below this."""
    max_range_m: float = 4.5
    """Tags seen by the robot farther than this are not used (the paper's 4 m detection limit)."""
    ir_threshold: int = 235
    ir_min_area_px: int = 2
    ekf: EkfConfig = field(default_factory=EkfConfig)


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


def run(
    reader: LogReader,
    writer: LogWriter,
    config: BridgeLocConfig | None = None,
    progress: Progress | None = None,
) -> MetricReport:
    """Localize the robot of a BridgeLoc log; write poses and tag annotations; score vs truth.

    Raises:
        MissingTopicError: the robot camera's images or calibration (``/NAME/camera_model``) are
            missing (basic and full modes), or no infrastructure camera has a world pose.
    """
    cfg = config or BridgeLocConfig()
    started = time.perf_counter()
    meta = reader.metadata().get("bridgeloc", {})
    robot = cfg.robot or meta.get("robot", "r1")
    rcam_name = cfg.robot_camera or meta.get("robot_camera", "r1cam")
    n = cfg.tag_n or int(meta.get("tag_n", 2))
    size_m = cfg.tag_size_m or float(meta.get("tag_size_m", 0.30))
    ir_h = cfg.ir_height_m or float(meta.get("ir_height_m", 0.65))
    tops = reader.topics()
    models = _models(reader)
    needs_robot = cfg.mode is not Mode.ICAM
    if needs_robot:
        if topics.image(rcam_name) not in tops:
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
    det_cfg = DetectorConfig(n=n)
    rgeo = CameraGeometry.from_model(models[rcam_name]) if needs_robot else None
    cam_h = float(rgeo.t[2]) if rgeo is not None else 0.5
    tag_map = TagMap(cam_h)
    fixes: dict[int, list[np.ndarray]] = {}
    det_times: list[float] = []
    n_msgs = 0
    # ---- pass 1: infrastructure cameras -> tag map (Eq. 4.6) and IR fixes (I-Cam)
    geos = {name: CameraGeometry.from_model(m) for name, m in infra.items()}
    pins = {name: PinholeCamera(m) for name, m in infra.items()}
    infra_period: dict[str, int] = {}
    last_t: dict[str, int] = {}
    for msg in reader.messages([topics.image(c) for c in infra]):
        n_msgs += 1
        if progress is not None and n_msgs % 200 == 0:
            progress(n_msgs, None)
        cam = (
            msg.message.frame_id
            if msg.message.frame_id in infra
            else msg.topic.strip("/").split("/")[0]
        )
        gray = _imdecode(msg.message.data)
        t0 = time.perf_counter()
        dets = detect_tags(gray, det_cfg)
        det_times.append(time.perf_counter() - t0)
        for d in dets:
            tag_map.add(d, geos[cam], size_m)
        writer.write(
            annotations_topic(cam),
            _annotations(msg.log_time_ns, dets, [d.pattern_id for d in dets]),
            msg.log_time_ns,
        )
        px = ir_light(gray, cfg.ir_threshold, cfg.ir_min_area_px)
        if px is not None:
            g = pins[cam].ground_point(px[None], ground_z=ir_h)[0]
            if not np.isnan(g).any():
                fixes.setdefault(msg.log_time_ns, []).append(g[:2])
        if cam in last_t:
            infra_period.setdefault(cam, msg.log_time_ns - last_t[cam])
        last_t[cam] = msg.log_time_ns
    tag_map.finalize()
    half_period = max(infra_period.values(), default=200_000_000) // 2
    fix_times = np.array(sorted(fixes), dtype=np.int64)

    def icam_fix(t_ns: int) -> np.ndarray | None:
        if not len(fix_times):
            return None
        i = int(np.searchsorted(fix_times, t_ns))
        best = None
        for j in (i - 1, i):
            if (
                0 <= j < len(fix_times)
                and abs(int(fix_times[j]) - t_ns) <= half_period
                and (best is None or abs(int(fix_times[j]) - t_ns) < abs(best - t_ns))
            ):
                best = int(fix_times[j])
        return None if best is None else np.mean(fixes[best], axis=0)

    # ---- pass 2: robot camera + odometry in time order
    rmeta = reader.metadata().get(f"robot/{robot}", {})
    drive = DiffDrive(
        float(rmeta.get("ticks_per_m", 2000.0)), float(rmeta.get("wheel_base_m", 0.30))
    )
    ekf = RobotEkf(cfg.ekf)
    truth: dict[int, tuple[float, float]] = {}
    est: list[tuple[int, tuple[float, float, float] | None]] = []
    other: dict[Mode, list[tuple[int, tuple[float, float, float] | None]]] = {m: [] for m in Mode}
    bridge_only: list[tuple[int, tuple[float, float, float] | None]] = []
    stats = {
        "bridge_fixes": 0,
        "icam_fixes": 0,
        "tag_observations": 0,
        "robot_frames": 0,
        "ambiguous_matches": 0,
    }
    prev_ticks: tuple[int, int] | None = None
    odom_topic = topics.odom(robot)
    stream = [topics.GROUND_TRUTH, odom_topic]
    if needs_robot:
        stream.append(topics.image(rcam_name))
    frame_topic = topics.image(rcam_name) if needs_robot else None
    if cfg.mode is Mode.ICAM:
        # I-Cam positions are the infrastructure frames; evaluate at ground-truth instants
        frame_topic = topics.GROUND_TRUTH
    for msg in reader.messages([t for t in stream if t in tops]):
        n_msgs += 1
        if progress is not None and n_msgs % 500 == 0:
            progress(n_msgs, None)
        if msg.topic == topics.GROUND_TRUTH:
            gt: GroundTruth = msg.message
            for e in gt.entities:
                if e.entity_id == robot:
                    truth[msg.log_time_ns] = (e.position_m.x, e.position_m.y)
            if frame_topic != topics.GROUND_TRUTH:
                continue
        if msg.topic == odom_topic:
            od: WheelOdometry = msg.message
            if od.left_ticks is None or od.right_ticks is None:
                continue
            if prev_ticks is not None and needs_robot:
                ds, dyaw = drive.motion_from_ticks(
                    od.left_ticks - prev_ticks[0], od.right_ticks - prev_ticks[1]
                )
                ekf.predict(ds, dyaw)
            prev_ticks = (od.left_ticks, od.right_ticks)
            continue
        t_ns = msg.log_time_ns
        fix = icam_fix(t_ns)
        if cfg.mode is Mode.ICAM:
            est.append((t_ns, None if fix is None else (float(fix[0]), float(fix[1]), 0.0)))
            continue
        stats["robot_frames"] += 1
        assert rgeo is not None
        gray = _imdecode(msg.message.data)
        t0 = time.perf_counter()
        dets = detect_tags(gray, det_cfg)
        det_times.append(time.perf_counter() - t0)
        labels = []
        obs = []  # (detection, signature, corners in base frame)
        for d in dets:
            pc = tag_corners_in_camera(d, rgeo, size_m)
            if pc is None:
                labels.append(d.pattern_id)
                continue
            pb = pc @ rgeo.R.T + rgeo.t
            ctr = pb.mean(axis=0)
            mount = "above" if ctr[2] > cam_h else "below"
            sig = f"{d.pattern_id}/{mount}"
            labels.append(sig)
            if math.hypot(ctr[0], ctr[1]) <= cfg.max_range_m:
                obs.append((d, sig, pb))
        writer.write(annotations_topic(rcam_name), _annotations(t_ns, dets, labels), t_ns)
        bridge = _bridge_fix(obs, tag_map, rgeo, cfg.pose)
        if bridge is not None:
            stats["bridge_fixes"] += 1
        if fix is not None:
            stats["icam_fixes"] += 1
        # every mode's estimate comes out of the same pass (I-Cam and Basic are by-products)
        icam_pose = None if fix is None else (float(fix[0]), float(fix[1]), 0.0)
        basic_pose: tuple[float, float, float] | None = None
        if fix is not None:
            basic_pose = (float(fix[0]), float(fix[1]), bridge[2] if bridge else 0.0)
        elif bridge is not None:
            basic_pose = bridge
        full_pose: tuple[float, float, float] | None = None
        c = cfg.ekf
        if fix is not None:
            ekf.update_pose(float(fix[0]), float(fix[1]), None, c.fix_sigma_m, 0.0)
        if not ekf.initialized and bridge is not None:
            ekf.update_pose(*bridge, c.bridge_sigma_m, c.bridge_yaw_sigma_rad)
        elif ekf.initialized:
            for _, sig, pb in obs:
                ctr = pb.mean(axis=0)
                rng_m = math.hypot(ctr[0], ctr[1])
                bearing = math.atan2(ctr[1], ctr[0])
                cands = tag_map.candidates(sig)
                if not cands:
                    continue
                seen_at = ekf.observed_position(rng_m, bearing)  # Eq. 4.11
                dists = [float(np.linalg.norm(t.center[:2] - seen_at)) for t in cands]
                k = int(np.argmin(dists))
                if len(cands) > 1:
                    stats["ambiguous_matches"] += 1
                if dists[k] > c.gate_m + 2 * ekf.sigma_m:
                    continue
                ekf.update_range_bearing(rng_m, bearing, cands[k].center[:2])  # Eq. 4.12
                stats["tag_observations"] += 1
        if ekf.initialized and ekf.sigma_m <= cfg.max_sigma_m:
            full_pose = ekf.pose
        bridge_only.append((t_ns, bridge))
        other[Mode.ICAM].append((t_ns, icam_pose))
        other[Mode.BASIC].append((t_ns, basic_pose))
        other[Mode.FULL].append((t_ns, full_pose))
        pose = {Mode.ICAM: icam_pose, Mode.BASIC: basic_pose, Mode.FULL: full_pose}[cfg.mode]
        est.append((t_ns, pose))
        if pose is not None:
            writer.write(POSE_TOPIC, pose_in_frame(t_ns, pose[0], pose[1], pose[2]), t_ns)
    if cfg.mode is Mode.ICAM:
        for t_ns, pose in est:
            if pose is not None:
                writer.write(POSE_TOPIC, pose_in_frame(t_ns, pose[0], pose[1], 0.0), t_ns)
    metrics = _score(est, truth, cfg, len(tag_map.tags), meta, bridge_only)
    for m, rows in other.items():
        if rows:  # the same run scored as the other modes would be (same frames, same fixes)
            sm = _score(rows, truth, cfg, len(tag_map.tags), {})
            metrics[f"success_rate_{m.value}"] = sm["success_rate"]
            metrics[f"error_m_mean_{m.value}"] = sm["error_m_mean"]
    metrics.update({k: v for k, v in stats.items()})
    metrics["tags_mapped"] = len(tag_map.tags)
    metrics["tag_map_error_m_mean"] = _map_error(tag_map, meta)
    metrics["detect_ms_median"] = (
        round(1000 * float(np.median(det_times)), 3) if det_times else None
    )
    metrics["ms_per_frame"] = round(
        1000 * (time.perf_counter() - started) / max(1, len(det_times)), 3
    )
    return MetricReport(
        t_ns=reader.end_ns or 0,
        processor="bridgeloc",
        metrics=metrics,
        params={
            "mode": cfg.mode.value,
            "pose": cfg.pose.value,
            "robot": robot,
            "robot_camera": rcam_name,
            "tag_n": n,
            "tag_size_m": size_m,
            "max_sigma_m": cfg.max_sigma_m,
            "max_range_m": cfg.max_range_m,
        },
    )


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


Estimates = list[tuple[int, tuple[float, float, float] | None]]


def _score(
    est: Estimates,
    truth: dict[int, tuple[float, float]],
    cfg: BridgeLocConfig,
    n_tags: int,
    meta: dict[str, str],
    bridge_only: Estimates | None = None,
) -> dict[str, float | int | str | None]:
    errors = []
    positions = localized = 0
    for t_ns, pose in est:
        gt = truth.get(t_ns)
        if gt is None:
            continue
        positions += 1
        if pose is None:
            continue
        localized += 1
        e = math.dist(pose[:2], gt)
        errors.append(e)
    out: dict[str, float | int | str | None] = {
        "system": "bridgeloc",
        "mode": cfg.mode.value,
        "tags": int(len(json.loads(meta["tags_truth"]))) if "tags_truth" in meta else n_tags,
        "positions": positions,
        "localized": localized,
        "success_rate": round(localized / positions, 4) if positions else None,
        "error_m_mean": round(float(np.mean(errors)), 4) if errors else None,
        "error_m_median": round(float(np.median(errors)), 4) if errors else None,
    }
    if meta.get("field") == "office" and "tags_truth" in meta and bridge_only is not None:
        # Fig. 4.20 is about view bridging itself: score the bridging fixes alone
        rows = [
            (*truth[t], math.dist(p[:2], truth[t]))
            for t, p in bridge_only
            if p is not None and t in truth
        ]
        out.update(_office_grid(rows, json.loads(meta["tags_truth"])[0]))
    return out


OFFICE_DISTANCES = (1.0, 2.0, 3.0, 4.0)
OFFICE_ANGLES = (-60.0, -45.0, -30.0, 0.0, 30.0, 45.0, 60.0)


def _office_grid(per_frame: list[tuple[float, float, float]], tag: dict) -> dict[str, float | None]:
    """Median error per test spot (distance x view angle to the tag), Fig. 4.20."""
    c = np.array(tag["center_m"][:2])
    nrm = np.array(tag["normal"])
    tang = np.array([-nrm[1], nrm[0]])
    cells: dict[tuple[float, float], list[float]] = {}
    for x, y, e in per_frame:
        v = np.array([x, y]) - c
        d = float(np.linalg.norm(v))
        a = math.degrees(math.atan2(float(v @ tang), float(v @ nrm)))
        for dd in OFFICE_DISTANCES:
            for aa in OFFICE_ANGLES:
                if abs(d - dd) < 0.03 and abs(a - aa) < 1.0:
                    cells.setdefault((dd, aa), []).append(e)
    out: dict[str, float | None] = {}
    near = []
    for (dd, aa), es in sorted(cells.items()):
        med = float(np.median(es))
        out[f"office_median_m_d{dd:g}_a{aa:+g}"] = round(med, 4)
        if dd <= 3.0 and abs(aa) <= 45.0:
            near.append(med)
    out["office_median_m_worst_d_le3_a_le45"] = round(max(near), 4) if near else None
    return out


def _map_error(tag_map: TagMap, meta: dict[str, str]) -> float | None:
    if "tags_truth" not in meta or not tag_map.tags:
        return None
    truth = [np.array(t["center_m"]) for t in json.loads(meta["tags_truth"])]
    errs = [min(float(np.linalg.norm(t.center - g)) for g in truth) for t in tag_map.tags]
    return round(float(np.mean(errs)), 4)
