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
]

REGION_HEADER_BYTES = 12
"""Per region: x, y, w, h (uint16 each) and the JPEG length (uint32)."""
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
    """Fewer changed pixels than this in the whole frame: nothing moved (the old image is sent)."""


@dataclass(frozen=True, slots=True)
class ForegroundPayload:
    """What a node sends for one frame: the changed regions as JPEG crops."""

    t_ns: int
    regions: tuple[tuple[int, int, bytes], ...]
    """(x, y, JPEG bytes) per region, x/y the crop's top-left pixel in the full frame."""

    @property
    def size_bytes(self) -> int:
        """Bytes on the wire: message header + per-region header + JPEG data."""
        return MESSAGE_HEADER_BYTES + sum(REGION_HEADER_BYTES + len(b) for _, _, b in self.regions)


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
        self.last_payload: ForegroundPayload | None = None
        self.last_mask_px = 0
        self.last_sense_ms = 0.0

    def sense(self, frame: np.ndarray) -> np.ndarray:
        """Update the background model with a frame; returns the cleaned foreground mask."""
        started = time.perf_counter()
        mask = self._mog.apply(frame)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        mask = cv2.dilate(mask, self._kernel, iterations=1)
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
                        boxes[i] = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])]
                        del boxes[j]
                        merged = True
                        break
                if merged:
                    break
        return [(x0, y0, x1 - x0, y1 - y0) for x0, y0, x1, y1 in boxes]

    def encode(self, t_ns: int, frame: np.ndarray, mask: np.ndarray) -> tuple[ForegroundPayload, bool]:
        """The payload for a request on this frame, and whether it is "new".

        When nothing moved (fewer than ``motion_px`` changed pixels) the previous payload is sent
        again as the "old" image (Fig. 4.4); otherwise the changed regions are JPEG-encoded.
        """
        if self.last_payload is not None and self.last_mask_px < self.config.motion_px:
            return self.last_payload, False
        params = [int(cv2.IMWRITE_JPEG_QUALITY), self.config.jpeg_quality]
        crops = []
        for x, y, bw, bh in self.regions(mask):
            ok, buf = cv2.imencode(".jpg", frame[y : y + bh, x : x + bw], params)
            if ok:
                crops.append((x, y, buf.tobytes()))
        payload = ForegroundPayload(t_ns, tuple(crops))
        self.last_payload = payload
        return payload, True

    def full_frame_bytes(self, frame: np.ndarray) -> int:
        """Bytes of the whole frame at the same JPEG quality (what a plain camera stream sends)."""
        ok, buf = cv2.imencode(".jpg", frame, [int(cv2.IMWRITE_JPEG_QUALITY), self.config.jpeg_quality])
        return MESSAGE_HEADER_BYTES + (len(buf) if ok else 0)
