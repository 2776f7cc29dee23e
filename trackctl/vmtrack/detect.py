"""Person detection in camera frames, full-frame or confined by motion predictions (§3.1.2 C).

The detector is a sliding-window classifier over an image pyramid, as in the paper; its window
score is computed on a foreground mask (difference to a background model of the static camera):
the share of foreground inside a person-shaped window minus the share in the ring around it, which
peaks when the window fits one person. Window sums come from an integral image (OpenCV), so each
pyramid level costs one pass over its pixels; overlapping hits are merged with OpenCV's NMS.

**Full search** slides the window over the whole frame at every pyramid level. **Motion-predicted
search** (the paper's acceleration) slides it only over the image region where each tracked person
can be now, given the last position, the phone's velocity and its error, and only at the pyramid
levels matching the person's predicted image height; full search remains for initialization and
recovery.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import cv2
import numpy as np

from trackctl.geometry.camera import PinholeCamera

__all__ = [
    "DetectorConfig",
    "person_height_px",
    "Region",
    "BackgroundModel",
    "detect_people",
    "predict_region",
]


@dataclass(frozen=True, slots=True)
class DetectorConfig:
    """Sliding-window parameters (pixels of the pyramid level the window slides over)."""

    window_h_px: int = 28
    """Window height at every level; the person's height maps to it through the level's scale."""
    aspect: float = 0.3
    """Window width / height (shoulders over body height)."""
    scale_step: float = 1.25
    """Size ratio of consecutive pyramid levels."""
    max_levels: int = 12
    threshold: float = 0.45
    """Minimum score (inside fill - ring fill) of a detection."""
    diff_threshold: int = 28
    """Grey-level difference to the background that counts as foreground."""
    stride_px: int = 2
    nms_iou: float = 0.3
    contained: float = 0.5
    """A window with more than this share of its area inside a better one is a body part."""
    level_margin: int = 1
    """Motion-predicted search also tries this many levels either side of the predicted one."""
    person_height_m: float = 1.7
    """Body height used to predict a person's image height from the ground position."""
    height_tolerance: float = 1.45
    """A window may be this factor taller or shorter than a person standing at its foot point."""
    refine_feet: bool = True
    """Move each box's bottom to the lowest foreground row connected to the body (the window
    score favours the torso: legs are thin and often close to the floor's colour)."""
    feet_threshold: int = 18
    """Grey-level difference that counts as foreground when looking for the feet."""
    feet_span: float = 0.5
    """Width of the strip searched for the feet, as a share of the box height, centred on the
    box. A walking stride spreads the feet ~0.75 m apart (0.45 of a 1.7 m body), wider than the
    shoulders the window fits (``aspect``); a strip as narrow as the box sees the floor between
    the legs and stops at the crotch or a coat's hem, which puts a far person 1 m or more too
    far away."""
    shadows: bool = True
    """Cast shadows (darker, same chromaticity) are not foreground."""
    shadow_ratio: tuple[float, float] = (0.45, 0.92)
    """Brightness against the background that a shadow may have."""
    shadow_chroma: float = 0.08
    """Largest per-channel deviation of the brightness ratio from its mean, in a shadow."""
    ghost_edge_ratio: float = 1.0
    """A detection whose outline has more edge strength in the background than in the frame
    by this factor is a ghost (dropped)."""


@dataclass(frozen=True, slots=True)
class Region:
    """Where a tracked person can be in one camera: a pixel box and the expected height."""

    x0: int
    y0: int
    x1: int
    y1: int
    height_px: float
    extra_levels: int = 0
    """Pyramid levels searched beyond ``level_margin`` either side (recovery)."""


class BackgroundModel:
    """Per-camera background that survives light changes and people who stand still.

    * **Start**: the per-pixel temporal median of frames sampled from the start of the log
      (people walking through the samples do not survive the median).
    * **Exposure**: each frame's global gain against the background (the median ratio over a
      coarse grid; people are a minority of the pixels) is divided out before differencing, so a
      dimmed scene or auto-exposure flicker does not turn the floor into foreground.
    * **Adaptation**: :meth:`update` blends every frame into the background (time constant
      ``tau_s``) *except* where people are (the tracker's predictions and the detections: the
      feedback that keeps a person who stops from being absorbed).
    * **Shadows**: a pixel darker than the background by a factor in ``shadow_ratio`` with its
      chromaticity kept is a cast shadow, not foreground (Prati et al. 2003, the rule OpenCV's
      MOG2 uses).
    """

    def __init__(self, frames: list[np.ndarray]) -> None:
        if not frames:
            raise ValueError("BackgroundModel needs at least one frame")
        self._float = np.median(np.stack(frames), axis=0).astype(np.float32)
        self.gain = 1.0
        self._last_ns: int | None = None

    def set_frame(self, image: np.ndarray) -> float:
        """Estimate (and keep, for :meth:`foreground`) the exposure gain of ``image``."""
        small = cv2.resize(image, (64, 48), interpolation=cv2.INTER_AREA).astype(np.float32)
        bg = cv2.resize(self._float, (64, 48), interpolation=cv2.INTER_AREA)
        if small.ndim == 3:
            small, bg = small.mean(axis=2), bg.mean(axis=2)
        valid = bg > 20
        self.gain = float(np.median(small[valid] / bg[valid])) if valid.any() else 1.0
        return self.gain

    def foreground(
        self, image: np.ndarray, cfg: DetectorConfig, box: Region | None = None
    ) -> np.ndarray:
        """Foreground mask (float32 0/1) of ``image``, over ``box`` only when given.

        Colour frames compare every channel (the largest difference counts): clothes as bright
        as the floor still differ in hue.
        """
        if box is None:
            img, bg = image, self._float
        else:
            img = image[box.y0 : box.y1, box.x0 : box.x1]
            bg = self._float[box.y0 : box.y1, box.x0 : box.x1]
        ref = cv2.convertScaleAbs(bg, alpha=self.gain)  # background at this frame's exposure
        diff = cv2.absdiff(img, ref)
        if diff.ndim == 3:  # OpenCV per-channel max: numpy's axis reductions are slow here
            b, g, r = cv2.split(diff)
            diff = cv2.max(cv2.max(b, g), r)
        _, mask = cv2.threshold(diff, cfg.diff_threshold, 1, cv2.THRESH_BINARY)
        if cfg.shadows:
            ys, xs = np.nonzero(mask)  # only changed pixels can be shadows
            if len(ys):
                ratio = img[ys, xs].astype(np.float32) / (ref[ys, xs].astype(np.float32) + 1.0)
                if ratio.ndim == 2:
                    mean = ratio.mean(axis=1)
                    chroma = np.abs(ratio - mean[:, None]).max(axis=1)
                else:
                    mean, chroma = ratio, np.zeros_like(ratio)
                lo, hi = cfg.shadow_ratio
                shadow = (mean >= lo) & (mean <= hi) & (chroma <= cfg.shadow_chroma)
                mask[ys[shadow], xs[shadow]] = 0
        opened = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        return np.asarray(opened, np.float32)

    def ghost(self, image: np.ndarray, box: np.ndarray, cfg: DetectorConfig) -> bool:
        """Whether the foreground in ``box`` (x, y, w, h) is a ghost: floor revealed where the
        background still holds someone who has left. An object's outline has edges in the
        frame; a ghost's outline has them in the background instead (Cucchiara et al. 2003)."""
        h_img, w_img = image.shape[:2]
        x, y, w, h = box
        reg = Region(
            max(0, int(x - 0.2 * w)),
            max(0, int(y - 0.1 * h)),
            min(w_img, int(x + 1.2 * w) + 1),
            min(h_img, int(y + 1.1 * h) + 1),
            h,
        )
        if reg.x1 - reg.x0 < 6 or reg.y1 - reg.y0 < 6:
            return False
        mask = self.foreground(image, cfg, reg).astype(np.uint8)
        kernel = np.ones((3, 3), np.uint8)
        outline = cv2.dilate(mask, kernel) - cv2.erode(mask, kernel)
        if outline.sum() < 8:
            return False

        def edges(img: np.ndarray) -> float:
            grey = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
            grey = grey.astype(np.float32)
            mag = cv2.magnitude(
                cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1)
            )
            return float(mag[outline > 0].mean())

        crop = image[reg.y0 : reg.y1, reg.x0 : reg.x1]
        bg = np.clip(self._float[reg.y0 : reg.y1, reg.x0 : reg.x1] * self.gain, 0, 255)
        return edges(bg.astype(np.uint8)) > cfg.ghost_edge_ratio * edges(crop)

    def update(
        self, image: np.ndarray, t_ns: int, keep_out: list[Region], tau_s: float | None
    ) -> None:
        """Blend ``image`` (at the background's exposure) into the background outside
        ``keep_out``, with time constant ``tau_s`` (None: never)."""
        last, self._last_ns = self._last_ns, t_ns
        if tau_s is None or last is None or t_ns <= last:
            return
        alpha = 1.0 - math.exp(-(t_ns - last) / 1e9 / tau_s)
        mask = np.full(image.shape[:2], 255, np.uint8)
        for r in keep_out:
            mask[r.y0 : r.y1, r.x0 : r.x1] = 0
        src = image.astype(np.float32) * (1.0 / max(self.gain, 1e-3))
        cv2.accumulateWeighted(src, self._float, alpha, mask)

    @property
    def image(self) -> np.ndarray:
        """The background now, as an 8-bit image."""
        return np.clip(self._float, 0, 255).astype(np.uint8)


def _level_boxes(
    mask: np.ndarray, scale: float, cfg: DetectorConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Scored window boxes (x, y, w, h in the mask's pixels) at one pyramid level."""
    h_img, w_img = mask.shape
    sw, sh = max(1, round(w_img / scale)), max(1, round(h_img / scale))
    # the mask is float (0/1), so bilinear shrinking keeps partial coverage and is fast
    level = mask if scale == 1.0 else cv2.resize(mask, (sw, sh), interpolation=cv2.INTER_LINEAR)
    wh = cfg.window_h_px
    ww = max(3, round(wh * cfg.aspect))
    pad_x, pad_y = ww // 2 + 1, wh // 6 + 1
    # outside the image (or region) counts as background, so people at the border still score
    level = cv2.copyMakeBorder(level, pad_y, pad_y, pad_x, pad_x, cv2.BORDER_CONSTANT, value=0)
    H, W = level.shape
    if H < wh + 2 * pad_y or W < ww + 2 * pad_x:  # pragma: no cover - padding makes room
        return np.empty((0, 4)), np.empty(0)
    # window sums by OpenCV box filters (centred windows), evaluated on a stride grid
    lv = level
    a_in = wh * ww
    a_out = (wh + 2 * pad_y) * (ww + 2 * pad_x)
    inner = cv2.boxFilter(lv, cv2.CV_32F, (ww, wh), normalize=False, borderType=cv2.BORDER_CONSTANT)
    outer = cv2.boxFilter(
        lv,
        cv2.CV_32F,
        (ww + 2 * pad_x, wh + 2 * pad_y),
        normalize=False,
        borderType=cv2.BORDER_CONSTANT,
    )
    s = cfg.stride_px
    score = (inner / a_in - (outer - inner) / (a_out - a_in))[::s, ::s]
    # local maxima only (one window per person per level)
    peak = cv2.dilate(score, np.ones((3, 3), np.uint8))
    keep = (score >= cfg.threshold) & (score >= peak)
    if not keep.any():
        return np.empty((0, 4)), np.empty(0)
    cy, cx = np.nonzero(keep)
    # centre of the window -> top-left corner in the unpadded level, then in the input's pixels
    ky = cy * s - wh // 2 - pad_y
    kx = cx * s - ww // 2 - pad_x
    fx, fy = w_img / sw, h_img / sh
    boxes = np.column_stack(
        [kx * fx, ky * fy, np.full(len(kx), ww * fx), np.full(len(kx), wh * fy)]
    )
    return boxes, score[keep]


def _levels_for(height_px: float, cfg: DetectorConfig, extra: int = 0) -> list[float]:
    """Pyramid scales whose window matches a person ``height_px`` tall (the paper's predicted
    pyramid levels), with ``level_margin`` neighbours either side."""
    k = math.log(max(height_px, 1.0) / cfg.window_h_px) / math.log(cfg.scale_step)
    centre = round(k)
    return [
        cfg.scale_step**lv
        for lv in range(centre - cfg.level_margin - extra, centre + cfg.level_margin + extra + 1)
        if 0 <= lv < cfg.max_levels
    ]


def detect_people(
    image: np.ndarray,
    background: BackgroundModel,
    cfg: DetectorConfig,
    regions: list[Region] | None = None,
    expected_height: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Person boxes (N, 4: x, y, w, h pixels) and scores in one frame (grey or BGR).

    ``regions`` None is the full search (whole frame, every pyramid level); otherwise only the
    given regions at their predicted levels are searched. ``expected_height`` maps foot pixels
    (N, 2) to the image height of a person standing there (from the calibration): windows whose
    size disagrees by more than ``cfg.height_tolerance`` are body parts or clutter, not people.
    """
    all_boxes: list[np.ndarray] = []
    all_scores: list[np.ndarray] = []
    if regions is None:
        mask = background.foreground(image, cfg)
        for lv in range(cfg.max_levels):
            boxes, scores = _level_boxes(mask, cfg.scale_step**lv, cfg)
            all_boxes.append(boxes)
            all_scores.append(scores)
    else:
        for reg in regions:
            mask = background.foreground(image, cfg, reg)
            for scale in _levels_for(reg.height_px, cfg, reg.extra_levels):
                boxes, scores = _level_boxes(mask, scale, cfg)
                if len(boxes):
                    boxes = boxes + np.array([reg.x0, reg.y0, 0, 0])
                all_boxes.append(boxes)
                all_scores.append(scores)
    boxes = np.vstack(all_boxes) if all_boxes else np.empty((0, 4))
    scores = np.concatenate(all_scores) if all_scores else np.empty(0)
    if len(boxes) == 0:
        return boxes, scores
    keep = cv2.dnn.NMSBoxes(
        boxes.round().astype(int).tolist(),
        scores.astype(float).tolist(),
        cfg.threshold,
        cfg.nms_iou,
    )
    idx = np.array(keep, int).reshape(-1)
    boxes, scores = _suppress_parts(boxes[idx], scores[idx], cfg.contained)
    if cfg.refine_feet:
        boxes = refine_feet(image, background, boxes, cfg)
    if cfg.ghost_edge_ratio > 0 and len(boxes):
        real = np.array([not background.ghost(image, b, cfg) for b in boxes])
        boxes, scores = boxes[real], scores[real]
    # a person cut by the bottom edge has no visible foot point to place on the ground
    keep = boxes[:, 1] + boxes[:, 3] < image.shape[0] - 2
    if expected_height is not None and len(boxes):
        feet = np.column_stack([boxes[:, 0] + boxes[:, 2] / 2, boxes[:, 1] + boxes[:, 3]])
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = boxes[:, 3] / expected_height(feet)
        tol = cfg.height_tolerance
        keep &= (ratio > 1 / tol) & (ratio < tol)
    return boxes[keep], scores[keep]


def refine_feet(
    image: np.ndarray, background: BackgroundModel, boxes: np.ndarray, cfg: DetectorConfig
) -> np.ndarray:
    """Boxes whose bottom is moved to the person's real lowest point: in a strip centred on the
    box, ``feet_span`` of its height wide (a stride's feet spread wider than the shoulders), from
    60% of its height down to 40% below it, the lowest row with foreground (at the lower
    ``feet_threshold``) reached from the body without a gap of more than 3 rows. A row counts
    when it holds as many foreground pixels as 15% of half the box's width (a leg, however far
    from the box's centre line the stride has put it)."""
    if len(boxes) == 0:
        return boxes
    h_img, w_img = image.shape[:2]
    low = replace(cfg, diff_threshold=cfg.feet_threshold)
    out = boxes.copy()
    for b in out:
        x, y, w, h = b
        half = max(0.25 * w, 0.5 * cfg.feet_span * h)
        cx = x + 0.5 * w
        x0, x1 = int(max(0, cx - half)), int(min(w_img, cx + half + 1))
        y0, y1 = int(max(0, y + 0.6 * h)), int(min(h_img, y + 1.4 * h + 1))
        if x1 - x0 < 2 or y1 - y0 < 4:
            continue
        strip = background.foreground(image, low, Region(x0, y0, x1, y1, h))
        on = strip.sum(axis=1) > 0.15 * max(1.0, 0.5 * w)
        last, gap = -1, 0
        for r, flag in enumerate(on):
            if flag:
                last, gap = r, 0
            elif last >= 0:
                gap += 1
                if gap > 3:
                    break
        if last >= 0:
            b[3] = max(0.5 * h, y0 + last + 1 - y)
    return out


def _suppress_parts(
    boxes: np.ndarray, scores: np.ndarray, contained: float
) -> tuple[np.ndarray, np.ndarray]:
    """Drop windows lying mostly inside a better-scoring window (a torso or legs of a person
    found whole at another level). IoU-based NMS (OpenCV) misses these: a small box inside a big
    one has a small IoU. Boxes are few after NMS, so a quadratic pass is cheap."""
    order = np.argsort(-scores)
    kept: list[int] = []
    for i in order:
        x, y, w, h = boxes[i]
        inside = False
        for j in kept:
            X, Y, W, H = boxes[j]
            ix = max(0.0, min(x + w, X + W) - max(x, X))
            iy = max(0.0, min(y + h, Y + H) - max(y, Y))
            if ix * iy > contained * w * h:
                inside = True
                break
        if not inside:
            kept.append(int(i))
    return boxes[kept], scores[kept]


def predict_region(
    cam: PinholeCamera,
    xy: np.ndarray,
    radius_m: float,
    person_height_m: float = 1.7,
    margin_px: int = 6,
    extra_levels: int = 0,
) -> Region | None:
    """Image region of a person predicted at ``xy`` (ground, metres) within ``radius_m``.

    Returns None when the prediction is not in front of the camera or falls outside the image.
    """
    m = cam.model
    ring = np.array(
        [
            [xy[0] + dx, xy[1] + dy, z]
            for dx in (-radius_m, radius_m)
            for dy in (-radius_m, radius_m)
            for z in (0.0, person_height_m)
        ]
    )
    px, front = cam.project(ring)
    if not front.all():
        return None
    foot_head, _ = cam.project(np.array([[xy[0], xy[1], 0.0], [xy[0], xy[1], person_height_m]]))
    height = float(np.linalg.norm(foot_head[0] - foot_head[1]))
    # the window's surrounding ring must fit in the region too
    pad = margin_px + 0.25 * height
    x0, y0 = px.min(axis=0) - pad
    x1, y1 = px.max(axis=0) + pad
    x0, y0 = max(0, int(x0)), max(0, int(y0))
    x1, y1 = min(m.width_px, int(math.ceil(x1))), min(m.height_px, int(math.ceil(y1)))
    if x1 - x0 < 8 or y1 - y0 < 16:
        return None
    return Region(x0, y0, x1, y1, height, extra_levels)


def person_height_px(cam: PinholeCamera, feet_px: np.ndarray, person_height_m: float) -> np.ndarray:
    """Image height of a person whose foot is at each pixel of ``feet_px`` (NaN off the floor)."""
    ground = cam.ground_point(feet_px)
    heads = ground + np.array([0.0, 0.0, person_height_m])
    px, front = cam.project(np.nan_to_num(heads))
    height = np.linalg.norm(px - np.asarray(feet_px, float).reshape(-1, 2), axis=1)
    return np.where(front & ~np.isnan(ground).any(axis=1), height, np.nan)
