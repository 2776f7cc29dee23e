"""Scene clutter for rendered frames: printed text and signage, what real walls carry.

Real indoor walls hold posters, notices, exit signs, door frames and arrows: dark strokes,
brackets and framed boxes on light paper, exactly the shapes a square-tag detector can mistake
for a tag ("[" next to "]", a framed sign). The BridgeLoc simulator hangs such posters on its
walls (``realistic`` preset) and the tests feed them to the detector alone.
"""

from __future__ import annotations

import string

import cv2
import numpy as np

__all__ = ["signage_texture", "signage_image"]

_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
    cv2.FONT_HERSHEY_PLAIN,
    cv2.FONT_HERSHEY_COMPLEX_SMALL,
)
_CHARS = string.ascii_letters + string.digits + "[](){}#%&@=+-_/|<>!?.,:;"


def signage_texture(rng: np.random.Generator, width_px: int, height_px: int) -> np.ndarray:
    """A sharp grayscale poster: lines of text in OpenCV's Hershey fonts at random sizes and
    weights, framed boxes, filled signs with light lettering ("EXIT") and arrows."""
    w, h = int(width_px), int(height_px)
    img = np.full((h, w), int(rng.integers(170, 240)), np.uint8)
    scale_px = min(w, h) / 480
    for _ in range(int(rng.integers(8, 20))):
        font = _FONTS[int(rng.integers(len(_FONTS)))]
        scale = float(rng.uniform(0.4, 2.5)) * scale_px
        thick = max(1, int(round(int(rng.integers(1, 5)) * scale_px)))
        text = "".join(rng.choice(list(_CHARS), int(rng.integers(3, 14))))
        org = (int(rng.integers(0, max(1, w - 50))), int(rng.integers(20, max(21, h))))
        cv2.putText(img, text, org, font, scale, int(rng.integers(0, 70)), thick, cv2.LINE_AA)
    for _ in range(int(rng.integers(1, 5))):
        bw = int(rng.integers(20, 150) * scale_px) + 2
        bh = int(rng.integers(15, 100) * scale_px) + 2
        x, y = int(rng.integers(0, max(1, w - bw))), int(rng.integers(0, max(1, h - bh)))
        ink = int(rng.integers(0, 60))
        kind = int(rng.integers(3))
        if kind == 0:  # a framed notice
            t = max(1, int(rng.integers(2, 8) * scale_px))
            cv2.rectangle(img, (x, y), (x + bw, y + bh), ink, t)
        elif kind == 1:  # a filled sign with light lettering
            cv2.rectangle(img, (x, y), (x + bw, y + bh), ink, -1)
            cv2.putText(img, "EXIT", (x + 3, y + bh - 4), _FONTS[0], bh / 40, 230, 2)
        else:
            t = max(1, int(rng.integers(3, 10) * scale_px))
            cv2.arrowedLine(img, (x, y), (x + bw, y + bh), ink, t, tipLength=0.3)
    return img


def signage_image(seed: int, width_px: int = 640, height_px: int = 480) -> np.ndarray:
    """A camera's view of a poster-covered wall: the poster blurred (sigma 0.5-1.2 px), with
    sensor noise (sigma 3) and JPEG (quality 70), decoded back to grayscale."""
    rng = np.random.default_rng(seed)
    sharp = signage_texture(rng, width_px, height_px).astype(np.float64)
    blurred = cv2.GaussianBlur(sharp, (0, 0), float(rng.uniform(0.5, 1.2)))
    noisy = np.clip(blurred + rng.normal(0, 3, blurred.shape), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", noisy, [int(cv2.IMWRITE_JPEG_QUALITY), 70])
    assert ok
    out = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    assert out is not None
    return np.asarray(out)
