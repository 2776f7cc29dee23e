"""What each track looks like, from the camera frames in the log: the offline re-identification's
evidence (:func:`~trackctl.vmtrack.stitch.reidentify`).

Position alone cannot tell who comes back: a person who leaves the view, or stays hidden behind a
sign for ten seconds, returns as a new track, and so do two people who walk past each other. When
the log holds the frames, the clothes tell: each track gets a colour signature, the mean of
``samples`` descriptors taken from its detections spread over its life. A descriptor is a
hue-saturation histogram (8 x 4 bins) and a brightness histogram (8 bins) of the torso and of the
legs (rows 15-55 % and 55-95 % of the box, its middle 60 % of columns: the background at the
box's sides and the head, often hair or cut off, stay out), each part normalised. Only
detections whose box overlaps no other detection's box in that frame are sampled, so a signature
is one person's, not a group's.

Two signatures are compared with the Bhattacharyya distance (0 the same colours, 1 none shared;
OpenCV's ``HISTCMP_BHATTACHARYYA``, here over both parts at once).

The samples are chosen while the log streams (the detections' boxes are kept per frame, a few
numbers each), then read in one more pass over the image topics that decodes only the frames
sampled: at most ``samples`` per track.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import cv2
import numpy as np

from trackctl.logs import topics
from trackctl.logs.messages import Detections
from trackctl.logs.reader import LogReader
from trackctl.vmtrack.frames import decode_image
from trackctl.vmtrack.tracker import GroundTrack

__all__ = ["AppearanceConfig", "AppearanceBook", "descriptor", "distance", "track_appearance"]

_PARTS = ((0.15, 0.55), (0.55, 0.95))
_COLS = (0.2, 0.8)


@dataclass(frozen=True, slots=True)
class AppearanceConfig:
    """Colour signatures of the tracks (when the log has the frames)."""

    enabled: bool = True
    samples: int = 15
    """Descriptors averaged per track, spread evenly over its isolated detections."""
    min_samples: int = 4
    """A track with fewer isolated detections has no signature (it cannot be re-identified)."""
    match_m: float = 0.3
    """A track's detection is the one within this distance of the point it took."""


class AppearanceBook:
    """The detections' boxes per frame and camera, kept while the log streams."""

    def __init__(self) -> None:
        self.boxes: dict[int, list[tuple[str, np.ndarray, np.ndarray]]] = {}

    def add(self, t_ns: int, camera: str, found: Detections) -> None:
        """Keep one camera's detections of the frame at ``t_ns`` (boxes and ground points)."""
        dets = [(d.box, d.ground_m) for d in found.detections if d.ground_m is not None]
        if not dets:
            return
        boxes = np.array([tuple(box) for box, _ in dets], np.float64).reshape(-1, 4)
        ground = np.array([(g.x, g.y) for _, g in dets], np.float64).reshape(-1, 2)
        self.boxes.setdefault(t_ns, []).append((camera, boxes, ground))

    def isolated_box(
        self, t_ns: int, xy: np.ndarray, match_m: float
    ) -> tuple[str, np.ndarray] | None:
        """(camera, box) of the detection at ground point ``xy`` at ``t_ns``, if its box overlaps
        no other box of that camera's frame."""
        for camera, boxes, ground in self.boxes.get(t_ns, ()):
            d = np.hypot(*(ground - xy).T)
            j = int(np.argmin(d))
            if d[j] > match_m:
                continue
            if _overlaps_other(boxes, j):
                return None
            return camera, boxes[j]
        return None


def _overlaps_other(boxes: np.ndarray, j: int) -> bool:
    """True when box ``j`` overlaps any other box (x, y, w, h) of ``boxes``."""
    b = boxes[j]
    ix = np.minimum(b[0] + b[2], boxes[:, 0] + boxes[:, 2]) - np.maximum(b[0], boxes[:, 0])
    iy = np.minimum(b[1] + b[3], boxes[:, 1] + boxes[:, 3]) - np.maximum(b[1], boxes[:, 1])
    hit = (ix > 0) & (iy > 0)
    hit[j] = False
    return bool(hit.any())


def descriptor(image: np.ndarray, box: np.ndarray) -> np.ndarray | None:
    """The colour descriptor of a BGR image's person box (x, y, w, h px), or None when the box
    holds too few pixels."""
    x, y, w, h = (round(float(v)) for v in box)
    x0, y0 = max(0, x), max(0, y)
    crop = image[y0 : y + h, x0 : x + w]
    if crop.shape[0] < 8 or crop.shape[1] < 4:
        return None
    hsv = cv2.cvtColor(crop, cv2.COLOR_BGR2HSV)
    rows, cols = hsv.shape[:2]
    parts = []
    for lo, hi in _PARTS:
        part = hsv[int(lo * rows) : int(hi * rows), int(_COLS[0] * cols) : int(_COLS[1] * cols)]
        hs = cv2.calcHist([part], [0, 1], None, [8, 4], [0, 180, 0, 256]).ravel()
        v = cv2.calcHist([part], [2], None, [8], [0, 256]).ravel()
        hist = np.concatenate([hs, v])
        parts.append(hist / max(float(hist.sum()), 1.0))
    return np.concatenate(parts)


def distance(a: np.ndarray, b: np.ndarray) -> float:
    """Bhattacharyya distance of two signatures (0 the same colours, 1 nothing in common)."""
    overlap = float(np.sum(np.sqrt(a * b))) / len(_PARTS)
    return float(np.sqrt(max(0.0, 1.0 - overlap)))


def _sample_times(
    trk: GroundTrack, book: AppearanceBook, cfg: AppearanceConfig
) -> list[tuple[int, str, np.ndarray]]:
    """Up to ``cfg.samples`` (time, camera, box) of the track's isolated detections, evenly
    spread over them."""
    found = []
    for t_ns, x, y in trk.hits_log:
        hit = book.isolated_box(t_ns, np.array([x, y]), cfg.match_m)
        if hit is not None:
            found.append((t_ns, *hit))
    if len(found) < cfg.min_samples:
        return []
    pick = np.unique(np.linspace(0, len(found) - 1, min(len(found), cfg.samples)).round())
    return [found[int(i)] for i in pick]


def track_appearance(
    reader: LogReader,
    book: AppearanceBook,
    tracks: Iterable[GroundTrack],
    cfg: AppearanceConfig,
) -> Mapping[int, np.ndarray]:
    """The colour signature of every track with ``cfg.min_samples`` isolated detections, by
    track key (none when the log has no frames or ``cfg`` disables it)."""
    if not cfg.enabled or not book.boxes:
        return {}
    wanted: dict[tuple[str, int], list[tuple[int, np.ndarray]]] = {}
    for trk in tracks:
        for t_ns, camera, box in _sample_times(trk, book, cfg):
            wanted.setdefault((camera, t_ns), []).append((trk.key, box))
    present = reader.topics()
    image_topics = sorted({topics.image(cam) for cam, _ in wanted} & set(present))
    found: dict[int, list[np.ndarray]] = {}
    for msg in reader.messages(image_topics):
        camera = msg.topic.strip("/").split("/")[0]
        todo = wanted.get((camera, msg.log_time_ns))
        if not todo:
            continue
        image = decode_image(bytes(msg.message.data))
        if image is None:
            continue
        for key, box in todo:
            d = descriptor(image, box)
            if d is not None:
                found.setdefault(key, []).append(d)
    return {key: np.mean(ds, axis=0) for key, ds in found.items() if len(ds) >= cfg.min_samples}
