"""Camera frames as vm-track's detection source: decode, detect people, place them on the ground.

Used when the log holds ``/<camera>/image`` (foxglove.CompressedImage) with a calibrated
``/<camera>/camera_model``. Each camera gets a background model from frames sampled across the
log; each frame is searched in full or only where the tracker predicts people (see
:mod:`trackctl.vmtrack.detect`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from trackctl.errors import InputError, MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.logs import topics
from trackctl.logs.messages import BBox, CameraModel, Detection, Detections, Vec3
from trackctl.logs.reader import LogReader, TopicInfo
from trackctl.vmtrack.detect import (
    BackgroundModel,
    DetectorConfig,
    Region,
    detect_people,
    person_height_px,
    predict_region,
)

__all__ = ["FrameConfig", "FrameDetector", "image_cameras", "detections_topic", "decode_image"]

IMAGE_SCHEMA = "foxglove.CompressedImage"


def detections_topic(camera: str) -> str:
    """Where vm-track writes what it detected in a camera's frames."""
    return f"/vmtrack/{camera}/detections"


@dataclass(frozen=True, slots=True)
class FrameConfig:
    """How frames are searched."""

    predicted: bool = True
    """Confine the search to motion-predicted regions (False: full search of every frame)."""
    full_search_every: int = 6
    """Frames between full searches that pick up people entering the view."""
    region_m: float = 0.4
    """Ground radius of a predicted region on top of the prediction's uncertainty."""
    visual_speed_sigma_mps: float = 0.6
    """Velocity uncertainty of a track without a phone (its prediction is visual only)."""
    background_frames: int = 100
    """Frames sampled for each camera's starting (median) background."""
    background_init_s: float | None = None
    """The starting background is sampled from the log's first seconds (None, the default:
    from the whole log, evenly). Offline the whole log is known: people who stand in the first
    seconds (a group talking at the start of PETS 2009 S2L1) do not win a whole-log median and
    are detected from the first frame; only a person standing in one place for more than half
    of the log would be in it (unseen while they stand; the floor they reveal when they leave
    is a ghost, which the adaptation heals). Sampling costs a decode of ``background_frames``
    frames and their median, once per camera."""
    background_tau_s: float | None = 10.0
    """Time constant of the background's adaptation outside people (None: static)."""
    protect_moved_m: float = 1.0
    """A track keeps the background from absorbing it once it has moved this far (or has a
    phone): a ghost (floor revealed where the starting background holds a person) never moves,
    so it heals."""
    foot_sigma_frac: float = 0.05
    """Std of a detected foot point's row as a share of the box height (legs, shoes, shadow)."""
    foot_sigma_px: float = 1.5
    """Pixel std added to both axes of the foot point (JPEG, blur)."""
    ground_sigma_m: float = 0.15
    """Ground std added on top of the pixel noise (a body is not a point; calibration)."""
    detector: DetectorConfig = field(default_factory=DetectorConfig)


def image_cameras(reader: LogReader, present: dict[str, TopicInfo]) -> dict[str, PinholeCamera]:
    """Calibrated cameras of every image topic, by camera name.

    Raises:
        MissingTopicError: an image topic's camera has no ``/<camera>/camera_model`` with a world
            pose (needed to place detections on the ground).
    """
    cams: dict[str, PinholeCamera] = {}
    for topic, info in sorted(present.items()):
        if info.schema_name != IMAGE_SCHEMA:
            continue
        name = topic.strip("/").split("/")[0]
        model_topic = topics.camera_model(name)
        model: CameraModel | None = None
        if model_topic in present and present[model_topic].schema_name != CameraModel.SCHEMA:
            raise MissingTopicError(
                f"{reader.path}: {model_topic} has schema {present[model_topic].schema_name!r}, "
                f"expected {CameraModel.SCHEMA}; vm-track needs it to place people found in "
                f"{topic} on the ground"
            )
        if model_topic in present:
            for m in reader.messages([model_topic]):
                model = m.message
                break
        if model is None or model.world_from_camera is None:
            raise MissingTopicError(
                f"{reader.path}: {model_topic} is missing or has no world pose; vm-track needs "
                f"it to place people found in {topic} on the ground"
            )
        cams[name] = PinholeCamera(model)
    return cams


def decode_image(data: bytes) -> np.ndarray | None:
    """BGR image of an encoded frame, or None when the bytes do not decode."""
    if not data:
        return None
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)


class FrameDetector:
    """Detects people in the frames of calibrated cameras; keeps stage timings and counts."""

    def __init__(
        self, reader: LogReader, cams: dict[str, PinholeCamera], config: FrameConfig
    ) -> None:
        self.cams = cams
        self.config = config
        self.backgrounds: dict[str, BackgroundModel] = {}
        self.full_searches = 0
        self.region_searches = 0
        self.bad_frames = 0
        self.seconds_decode = 0.0
        self.seconds_detect = 0.0
        started = time.perf_counter()
        self._build_backgrounds(reader)
        self.seconds_background = time.perf_counter() - started

    def _build_backgrounds(self, reader: LogReader) -> None:
        present = reader.topics()
        init_s = self.config.background_init_s
        for name in self.cams:
            topic = topics.image(name)
            info = present.get(topic)
            count = info.count if info is not None else 0
            end_ns = None
            if init_s is not None and info is not None and count > 1 and info.first_ns is not None:
                span = max(1, (info.last_ns or info.first_ns) - info.first_ns)
                end_ns = info.first_ns + int(init_s * 1e9)
                count = max(1, min(count, round(count * init_s * 1e9 / span) + 1))
            step = max(1, count // max(1, self.config.background_frames))
            samples: list[np.ndarray] = []
            for k, m in enumerate(reader.messages([topic])):
                if end_ns is not None and m.log_time_ns > end_ns:
                    break
                if k % step:
                    continue
                image = decode_image(bytes(m.message.data))
                if image is not None:
                    samples.append(image)
            if not samples:
                raise InputError(f"{reader.path}: {topic}: no frame decodes as an image")
            self.backgrounds[name] = BackgroundModel(samples)

    def regions(
        self, camera: str, predictions: list[tuple[np.ndarray, float, bool]]
    ) -> list[Region]:
        """Image regions of the predicted people seen by ``camera``: (ground xy, radius m,
        recovering). A recovering track's region is searched at one more level either side."""
        cam = self.cams[camera]
        dcfg = self.config.detector
        out = []
        for xy, radius, recovering in predictions:
            reg = predict_region(
                cam, xy, radius, dcfg.person_height_m, extra_levels=1 if recovering else 0
            )
            if reg is not None:
                out.append(reg)
        return out

    def detect(
        self,
        t_ns: int,
        camera: str,
        data: bytes,
        predictions: list[tuple[np.ndarray, float, bool]] | None,
        people: list[tuple[np.ndarray, float, bool]] | None = None,
    ) -> tuple[Detections, list[np.ndarray], list[np.ndarray]]:
        """People in one frame: the Detections message, their ground points and the points'
        2x2 covariances (pixel noise through the camera geometry: far people are uncertain
        along the line of sight).

        ``predictions`` None asks for a full search; otherwise only their regions are searched.
        ``people`` (the tracker's predictions of people who have walked, searched or not) are
        kept out of the background's adaptation. A frame that does not decode is skipped and
        counted.
        """
        t0 = time.perf_counter()
        image = decode_image(data)
        t1 = time.perf_counter()
        self.seconds_decode += t1 - t0
        if image is None:
            self.bad_frames += 1
            return Detections(t_ns, camera, ()), [], []
        cam = self.cams[camera]
        background = self.backgrounds[camera]
        background.set_frame(image)
        regions = None if predictions is None else self.regions(camera, predictions)
        if regions is None:
            self.full_searches += 1
        else:
            self.region_searches += 1
        dcfg = self.config.detector
        boxes, scores = detect_people(
            image,
            background,
            dcfg,
            regions,
            lambda feet: person_height_px(cam, feet, dcfg.person_height_m),
        )
        feet = np.column_stack([boxes[:, 0] + boxes[:, 2] / 2, boxes[:, 1] + boxes[:, 3]])
        ground = cam.ground_point(feet)
        covs = self._ground_covariances(cam, feet, boxes)
        keep_out = self.regions(camera, people) if people else []
        background.update(image, t_ns, keep_out, self.config.background_tau_s)
        self.seconds_detect += time.perf_counter() - t1
        dets = []
        points = []
        point_covs = []
        for box, score, g, c in zip(boxes, scores, ground, covs, strict=True):
            if np.isnan(g).any() or not np.isfinite(c).all():
                continue
            dets.append(
                Detection(
                    BBox(*(float(v) for v in box)),
                    round(float(min(1.0, max(0.0, score))), 3),
                    "person",
                    Vec3(float(g[0]), float(g[1]), 0.0),
                )
            )
            points.append(g[:2])
            point_covs.append(c)
        return Detections(t_ns, camera, tuple(dets)), points, point_covs

    def _ground_covariances(
        self, cam: PinholeCamera, feet: np.ndarray, boxes: np.ndarray
    ) -> np.ndarray:
        """2x2 ground covariance of each foot point: J diag(su^2, sv^2) J^T + ground_sigma^2 I,
        J the pixel -> floor Jacobian (central differences through the calibrated camera)."""
        if len(feet) == 0:
            return np.empty((0, 2, 2))
        cfg = self.config
        eps = 0.5
        du = np.array([eps, 0.0])
        dv = np.array([0.0, eps])
        jx = (cam.ground_point(feet + du)[:, :2] - cam.ground_point(feet - du)[:, :2]) / (2 * eps)
        jy = (cam.ground_point(feet + dv)[:, :2] - cam.ground_point(feet - dv)[:, :2]) / (2 * eps)
        jac = np.stack([jx, jy], axis=2)  # (N, 2 ground, 2 pixel)
        su = cfg.foot_sigma_px + 0.1 * boxes[:, 2]
        sv = cfg.foot_sigma_px + cfg.foot_sigma_frac * boxes[:, 3]
        pix = np.zeros((len(feet), 2, 2))
        pix[:, 0, 0] = su**2
        pix[:, 1, 1] = sv**2
        return jac @ pix @ jac.transpose(0, 2, 1) + np.eye(2) * cfg.ground_sigma_m**2
