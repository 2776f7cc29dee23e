"""Stage 0 of VM-Tracking, the inputs: frames or detections, cameras and phones, planned before
any work; and stage 1's reading of the phones' motion (PDR, :mod:`~trackctl.vmtrack.motion`).
"""

from __future__ import annotations

import warnings
from collections.abc import Container
from dataclasses import dataclass, field

import numpy as np

from trackctl.errors import IncompleteInputWarning, MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.logs import topics
from trackctl.logs.messages import (
    CameraModel,
    Detections,
    Imu,
)
from trackctl.logs.reader import LogReader, TopicInfo
from trackctl.vmtrack.config import Mode, Source, VmTrackConfig
from trackctl.vmtrack.frames import FrameDetector, image_cameras
from trackctl.vmtrack.motion import PhoneMotion


def _detection_points(reader: LogReader, det_topics: list[str]) -> dict[str, PinholeCamera]:
    """Cameras needed to place box-only detections on the ground (checked up front).

    Raises:
        MissingTopicError: a detections topic holds boxes without ground points and its camera
            has no calibrated world pose (``/<camera>/camera_model``).
    """
    cams: dict[str, PinholeCamera] = {}
    present = reader.topics()
    for topic in det_topics:
        cam = topic.split("/")[1]
        model_topic = topics.camera_model(cam)
        if model_topic in present:
            for m in reader.messages([model_topic], expect={model_topic: CameraModel.SCHEMA}):
                model: CameraModel = m.message
                if model.world_from_camera is not None:
                    cams[cam] = PinholeCamera(model)
                break
        if cam in cams:
            continue
        # Fail before any work when the first frame with boxes already needs the calibration.
        for m in reader.messages([topic], expect={topic: Detections.SCHEMA}):
            dets: Detections = m.message
            if not dets.detections:
                continue
            if any(d.ground_m is None for d in dets.detections):
                raise MissingTopicError(
                    f"{reader.path}: {model_topic} is missing or has no world pose; vm-track "
                    f"needs it to place {topic} boxes on the ground"
                )
            break
    return cams


@dataclass
class Inputs:
    """What a run reads: where detections come from, and which phones."""

    mode: Mode
    det_topics: list[str]
    imu_topics: list[str]
    detector: FrameDetector | None = None
    cams: dict[str, PinholeCamera] = field(default_factory=dict)

    def stream_topics(self, present: Container[str]) -> list[str]:
        """Detection (or image) topics, then RSSI and ground truth when the log has them."""
        extra = [t for t in (topics.RSSI, topics.GROUND_TRUTH) if t in present]
        return self.det_topics + extra


def plan_inputs(reader: LogReader, cfg: VmTrackConfig) -> Inputs:
    """Stage 0: frames or detections, cameras, phones; errors before any work.

    Raises:
        MissingTopicError: no detections and no frames (or ``--source frames`` without frames).
    """
    present = reader.topics()
    det_topics = sorted(t for t, i in present.items() if i.schema_name == Detections.SCHEMA)
    det_topics = [t for t in det_topics if not t.startswith("/vmtrack/")]
    has_images = any(i.schema_name == "foxglove.CompressedImage" for i in present.values())
    imu_topics = sorted(t for t, i in present.items() if i.schema_name == Imu.SCHEMA)
    if cfg.source is Source.FRAMES or (cfg.source is Source.AUTO and has_images):
        inputs = _frame_inputs(reader, present, cfg, imu_topics)
    elif not det_topics:
        raise MissingTopicError(
            f"{reader.path}: no trackctl.Detections topic (/<camera>/detections) and no "
            f"camera frames; vm-track needs person detections. The log has: "
            f"{', '.join(sorted(present))}"
        )
    else:
        cams = _detection_points(reader, det_topics)
        inputs = Inputs(cfg.mode, det_topics, imu_topics, cams=cams)
    if inputs.mode is Mode.VM and not imu_topics:
        warnings.warn(
            f"{reader.path}: no IMU topic: running as V-AF (visual only)", UserWarning, stacklevel=3
        )
        inputs.mode = Mode.V_AF
    return inputs


def _frame_inputs(
    reader: LogReader, present: dict[str, TopicInfo], cfg: VmTrackConfig, imu_topics: list[str]
) -> Inputs:
    """Stage 0 for a log with camera frames: the detector over its image topics."""
    frame_cams = image_cameras(reader, present)
    if not frame_cams:
        raise MissingTopicError(
            f"{reader.path}: no foxglove.CompressedImage topic (/<camera>/image); "
            "--source frames needs camera frames"
        )
    detector = FrameDetector(reader, frame_cams, cfg.frames)
    image_topics = [topics.image(c) for c in sorted(frame_cams)]
    return Inputs(cfg.mode, image_topics, imu_topics, detector=detector)


def phone_motions(reader: LogReader, inputs: Inputs, cfg: VmTrackConfig) -> dict[str, PhoneMotion]:
    """Stage 1: every phone's walking velocity series (PDR), by MID."""
    phones: dict[str, PhoneMotion] = {}
    if inputs.mode is not Mode.VM:
        return phones
    for msg in reader.messages(inputs.imu_topics):
        imu: Imu = msg.message
        mid = imu.frame_id.split("/", 1)[1] if "/" in imu.frame_id else imu.frame_id
        phones.setdefault(mid, PhoneMotion(mid, cfg.motion)).add(imu)
    for p in phones.values():
        p.finish()
    return phones


MAX_GROUND_M = 1e4
"""Farthest ground point from the site origin vm-track uses (10 km: an indoor site is far
smaller; the position grid spans the points)."""


def _on_site(xy: np.ndarray) -> bool:
    return bool(np.isfinite(xy).all() and (np.abs(xy) <= MAX_GROUND_M).all())


def ground_points(
    reader: LogReader, topic: str, dets: Detections, cams: dict[str, PinholeCamera]
) -> list[tuple[str, np.ndarray]]:
    """Ground points (camera, xy) of a detections message: given, or the box's foot point
    projected through the calibrated camera. A given point that is not finite or lies farther
    than :data:`MAX_GROUND_M` from the origin (junk from another tool) is skipped, with one
    warning per topic; a projected one is dropped silently (a foot at the horizon)."""
    out = []
    for d in dets.detections:
        if d.ground_m is not None:
            xy = np.array([d.ground_m.x, d.ground_m.y])
            if _on_site(xy):
                out.append((dets.camera, xy))
            else:
                warnings.warn(
                    f"{reader.path}: {topic}: detections whose ground point is NaN, infinite "
                    f"or beyond {MAX_GROUND_M:g} m are skipped",
                    IncompleteInputWarning,
                    stacklevel=2,
                )
            continue
        cam = cams.get(dets.camera)
        if cam is None:
            raise MissingTopicError(
                f"{reader.path}: {topics.camera_model(dets.camera)} is missing or has no "
                f"world pose; vm-track needs it to place {topic} boxes on the ground"
            )
        foot = np.array([[d.box.x_px + d.box.w_px / 2, d.box.y_px + d.box.h_px]])
        g = cam.ground_point(foot)[0]
        if _on_site(g[:2]):
            out.append((dets.camera, g[:2]))
    return out
