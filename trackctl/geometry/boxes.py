"""Image boxes of people standing on ground points (the MOT export and vm-track's overlays).

A person is ``height_m`` tall and :data:`BOX_WIDTH_SHARE` of that wide, standing on the ground
point: the box's bottom edge is the projected foot point, its top the projected head point.
Pixels are trackctl's: origin at the top-left corner of the top-left pixel.
"""

from __future__ import annotations

import numpy as np

from trackctl.geometry.camera import PinholeCamera
from trackctl.logs.messages import BBox

__all__ = ["BOX_WIDTH_SHARE", "person_boxes", "clip_box"]

BOX_WIDTH_SHARE = 0.41
"""A standing person's box width as a share of its height (MOTChallenge's pedestrians)."""


def person_boxes(camera: PinholeCamera, points: np.ndarray, height_m: float) -> list[BBox | None]:
    """The box of a person standing on each ground point (N, 2 or 3; z is ignored, the person
    stands on z = 0); None where the foot or the head is behind the camera."""
    if len(points) == 0:
        return []
    pts = np.asarray(points, float).reshape(len(points), -1)
    feet = np.column_stack([pts[:, 0], pts[:, 1], np.zeros(len(pts))])
    heads = feet + np.array([0.0, 0.0, height_m])
    foot_px, foot_front = camera.project(feet)
    head_px, head_front = camera.project(heads)
    out: list[BBox | None] = []
    for k in range(len(pts)):
        h_px = float(foot_px[k, 1] - head_px[k, 1])
        if not (foot_front[k] and head_front[k]) or h_px <= 0:
            out.append(None)
            continue
        w_px = BOX_WIDTH_SHARE * h_px
        out.append(BBox(float(foot_px[k, 0]) - w_px / 2, float(head_px[k, 1]), w_px, h_px))
    return out


def clip_box(box: BBox, width_px: int, height_px: int) -> BBox | None:
    """The part of ``box`` inside a ``width_px`` x ``height_px`` image; None when none is."""
    x0, y0 = max(0.0, box.x_px), max(0.0, box.y_px)
    x1 = min(float(width_px), box.x_px + box.w_px)
    y1 = min(float(height_px), box.y_px + box.h_px)
    if x1 <= x0 or y1 <= y0:
        return None
    return BBox(x0, y0, x1 - x0, y1 - y0)
