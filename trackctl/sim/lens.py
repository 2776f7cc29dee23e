"""Lens distortion for rendered frames: draw the ideal pinhole image, then warp it.

Renderers project with an ideal pinhole; :class:`LensDistortion` maps every output pixel to
where the ideal image holds its content (``cv2.undistortPoints`` of the pixel grid under the
camera's distortion, computed once) and ``cv2.remap`` applies it, so a frame looks as it would
through the lens the camera model describes (OpenCV's plumb_bob coefficients).
"""

from __future__ import annotations

import cv2
import numpy as np

from trackctl.logs.messages import CameraModel

__all__ = ["LensDistortion"]


class LensDistortion:
    """The remap of one camera's distortion (identity when it has none)."""

    def __init__(self, model: CameraModel) -> None:
        self.active = any(abs(d) > 0 for d in model.distortion)
        if not self.active:
            return
        k = np.array([[model.fx_px, 0, model.cx_px], [0, model.fy_px, model.cy_px], [0, 0, 1]])
        w, h = model.width_px, model.height_px
        grid = np.stack(
            np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32)), axis=-1
        ).reshape(-1, 1, 2)
        und = cv2.undistortPoints(grid, k, np.asarray(model.distortion, float), P=k)
        und = und.reshape(h, w, 2)
        self.map_x = und[..., 0].astype(np.float32)
        self.map_y = und[..., 1].astype(np.float32)

    def apply(self, ideal: np.ndarray) -> np.ndarray:
        """The frame as the lens shows it."""
        if not self.active:
            return ideal
        return cv2.remap(
            ideal, self.map_x, self.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
