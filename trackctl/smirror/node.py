"""The S-Mirror node (dissertation §4.1.2 B, Fig. 4.4): background model, visual motion detection,
foreground-only encoding, cast-mode decision and E-beacons.

Every byte a node sends is measured: image payloads are the actual ``cv2.imencode`` output of the
changed regions plus a fixed per-region header, beacons the actual JSON bytes of the node's
configuration.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from enum import StrEnum

import cv2
import numpy as np

from trackctl.logs.messages import CameraModel

__all__ = [
    "CastMode",
    "NodeConfig",
    "ForegroundPayload",
    "MirrorNode",
    "decide_cast",
    "beacon_bytes",
    "REGION_HEADER_BYTES",
    "pack_regions",
]

REGION_HEADER_BYTES = 12
"""Per region: frame x, y, mosaic x, y, width, height (uint16 each)."""
MESSAGE_HEADER_BYTES = 24
"""Per image message: node id, frame stamp, region count, new/old flag."""


class CastMode(StrEnum):
    """How a node delivers an image to its requesters."""

    UNICAST = "unicast"
    BROADCAST = "broadcast"


def decide_cast(requests: int, threshold: int) -> CastMode:
    """The node's cast-mode decision (Fig. 4.4): broadcast from ``threshold`` requests on."""
    return CastMode.BROADCAST if requests >= threshold else CastMode.UNICAST


@dataclass(frozen=True, slots=True)
class NodeConfig:
    """Background model and foreground encoding of a node."""

    history: int = 500
    var_threshold: float = 25.0
    min_region_px: int = 30
    """Changed regions smaller than this (pixels of the box) are noise."""
    pad_px: int = 4
    """Margin around each changed region, so a blob's edge and its LEDs are not cut."""
    jpeg_quality: int = 80
    motion_px: int = 40
    model_scale: float = 0.5
    """Scale of the frame the background model sees."""
    """Fewer changed pixels than this in the whole frame: nothing moved (the old image is sent)."""


@dataclass(frozen=True, slots=True)
class ForegroundPayload:
    """What a node sends for one frame: the changed regions packed into one JPEG mosaic.

    One JPEG for all regions, not one per region: a JPEG file carries ~600 bytes of tables, which
    would dominate small regions.
    """

    t_ns: int
    mosaic: bytes
    """JPEG of the packed regions (empty when nothing changed)."""
    regions: tuple[tuple[int, int, int, int, int, int], ...]
    """(frame x, frame y, mosaic x, mosaic y, width, height) per region, pixels."""

    @property
    def size_bytes(self) -> int:
        """Bytes on the wire: message header + per-region header + JPEG data."""
        return MESSAGE_HEADER_BYTES + REGION_HEADER_BYTES * len(self.regions) + len(self.mosaic)

    def crops(self) -> list[tuple[int, int, np.ndarray]]:
        """Decode the mosaic into (frame x, frame y, image) crops (what the robot receives)."""
        if not self.mosaic:
            return []
        img = cv2.imdecode(np.frombuffer(self.mosaic, np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            return []
        return [(fx, fy, img[my : my + h, mx : mx + w]) for fx, fy, mx, my, w, h in self.regions]


def pack_regions(
    sizes: list[tuple[int, int]], width: int, align: int = 16
) -> tuple[list[tuple[int, int]], tuple[int, int]]:
    """Shelf packing of (w, h) boxes into rows of at most ``width`` pixels.

    Boxes start on ``align``-pixel boundaries so JPEG blocks never mix two regions. Returns each
    box's top-left corner and the mosaic size. (A few boxes per frame: a library bin packer
    would not pay for itself.)
    """

    def up(v: int) -> int:
        return -(-v // align) * align

    order = sorted(range(len(sizes)), key=lambda i: -sizes[i][1])
    pos: list[tuple[int, int]] = [(0, 0)] * len(sizes)
    x = y = shelf = 0
    mosaic_w = 0
    for i in order:
        w, h = sizes[i]
        if x > 0 and x + w > width:
            y += up(shelf)
            x = shelf = 0
        pos[i] = (x, y)
        x += up(w)
        shelf = max(shelf, h)
        mosaic_w = max(mosaic_w, x)
    return pos, (max(align, mosaic_w), max(align, y + up(shelf)))


def beacon_bytes(model: CameraModel, extra: dict[str, object] | None = None) -> int:
    """Size of an E-beacon: the node's configuration (its calibrated camera) as compact JSON."""
    body = {"node": model.camera, "camera": model.to_json(), **(extra or {})}
    return len(json.dumps(body, separators=(",", ":")).encode())


class MirrorNode:
    """One node: keeps the background model over every frame (V sensing) and answers requests."""

    def __init__(self, model: CameraModel, config: NodeConfig) -> None:
        self.model = model
        self.config = config
        self._mog = cv2.createBackgroundSubtractorMOG2(
            history=config.history, varThreshold=config.var_threshold, detectShadows=False
        )
        self._kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
        self._small = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        # the same encoder settings for foreground mosaics and the full-frame comparison
        self._params = [
            int(cv2.IMWRITE_JPEG_QUALITY),
            config.jpeg_quality,
            int(cv2.IMWRITE_JPEG_OPTIMIZE),
            1,
        ]
        self.last_payload: ForegroundPayload | None = None
        self.last_mask_px = 0
        self.last_sense_ms = 0.0

    def sense(self, frame: np.ndarray) -> np.ndarray:
        """Update the background model with a frame; returns the cleaned foreground mask."""
        started = time.perf_counter()
        # the background model runs on a reduced frame (4x fewer pixels at 0.5): region boxes
        # need no full-resolution mask, and the node's budget is ~20 ms per request on one core
        s = self.config.model_scale
        small = (
            frame if s == 1.0 else cv2.resize(frame, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        )
        mask = self._mog.apply(small)
        if s != 1.0:
            mask = cv2.resize(
                mask, (frame.shape[1], frame.shape[0]), interpolation=cv2.INTER_NEAREST
            )
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._small)
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, self._kernel)
        mask = cv2.dilate(mask, self._small, iterations=1)
        self.last_mask_px = int(cv2.countNonZero(mask))
        self.last_sense_ms = (time.perf_counter() - started) * 1e3
        return mask

    def regions(self, mask: np.ndarray) -> list[tuple[int, int, int, int]]:
        """Bounding boxes (x, y, w, h) of the changed regions, padded and merged when they touch."""
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        h, w = mask.shape[:2]
        pad = self.config.pad_px
        boxes = []
        for c in contours:
            x, y, bw, bh = cv2.boundingRect(c)
            if bw * bh < self.config.min_region_px:
                continue
            x0, y0 = max(0, x - pad), max(0, y - pad)
            x1, y1 = min(w, x + bw + pad), min(h, y + bh + pad)
            boxes.append([x0, y0, x1, y1])
        # merge overlapping boxes (a few per frame: the quadratic loop is cheaper than a library)
        merged = True
        while merged and len(boxes) > 1:
            merged = False
            for i in range(len(boxes)):
                for j in range(i + 1, len(boxes)):
                    a, b = boxes[i], boxes[j]
                    if a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]:
                        boxes[i] = [
                            min(a[0], b[0]),
                            min(a[1], b[1]),
                            max(a[2], b[2]),
                            max(a[3], b[3]),
                        ]
                        del boxes[j]
                        merged = True
                        break
                if merged:
                    break
        return [(x0, y0, x1 - x0, y1 - y0) for x0, y0, x1, y1 in boxes]

    def encode(
        self, t_ns: int, frame: np.ndarray, mask: np.ndarray
    ) -> tuple[ForegroundPayload, bool]:
        """The payload for a request on this frame, and whether it is "new".

        When nothing moved (fewer than ``motion_px`` changed pixels) the previous payload is sent
        again as the "old" image (Fig. 4.4); otherwise the changed regions are JPEG-encoded.
        """
        if self.last_payload is not None and self.last_mask_px < self.config.motion_px:
            return self.last_payload, False
        # foreground-only: inside a region's box the unchanged pixels are blanked to one flat
        # grey, which JPEG codes in a few bits, so only the changed pixels cost bytes
        boxes = self.regions(mask)
        if not boxes:
            payload = ForegroundPayload(t_ns, b"", ())
        else:
            pos, (mw, mh) = pack_regions([(w, h) for _, _, w, h in boxes], frame.shape[1])
            mosaic = np.full((mh, mw, 3), 128, np.uint8)
            regions = []
            for (x, y, w, h), (mx, my) in zip(boxes, pos, strict=True):
                crop = frame[y : y + h, x : x + w].copy()
                crop[mask[y : y + h, x : x + w] == 0] = 128
                mosaic[my : my + h, mx : mx + w] = crop
                regions.append((x, y, mx, my, w, h))
            ok, buf = cv2.imencode(".jpg", mosaic, self._params)
            payload = ForegroundPayload(t_ns, buf.tobytes() if ok else b"", tuple(regions))
        self.last_payload = payload
        return payload, True

    def full_frame_bytes(self, frame: np.ndarray) -> int:
        """Bytes of the whole frame at the same JPEG quality (what a plain camera stream sends)."""
        ok, buf = cv2.imencode(".jpg", frame, self._params)
        return MESSAGE_HEADER_BYTES + (len(buf) if ok else 0)
