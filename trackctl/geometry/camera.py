"""Pinhole cameras in the world frame (right-handed, z up; camera optical frame x right, y down,
z forward)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from trackctl.logs.messages import CameraModel, Quat, Transform, Vec3

__all__ = ["PinholeCamera", "ideal_camera", "look_at"]


def ideal_camera(
    name: str,
    width_px: int,
    height_px: int,
    pose: Transform,
    *,
    hfov_deg: float | None = None,
    f_px: float | None = None,
    distortion: tuple[float, ...] = (0.0,) * 5,
) -> CameraModel:
    """A pinhole camera with square pixels and a centred principal point, its focal length from
    the horizontal field of view or given (simulated cameras)."""
    if f_px is None:
        if hfov_deg is None:
            raise ValueError("ideal_camera: give hfov_deg or f_px")
        f_px = width_px / (2 * math.tan(math.radians(hfov_deg) / 2))
    return CameraModel(
        t_ns=0,
        camera=name,
        width_px=width_px,
        height_px=height_px,
        fx_px=f_px,
        fy_px=f_px,
        cx_px=width_px / 2,
        cy_px=height_px / 2,
        distortion_model="plumb_bob",
        distortion=distortion,
        world_from_camera=pose,
    )


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray | None = None) -> Transform:
    """Pose world <- camera of a camera at ``eye`` looking at ``target`` (optical frame)."""
    eye = np.asarray(eye, float)
    target = np.asarray(target, float)
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction is parallel to 'up'")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rot = np.column_stack([x, y, z])  # columns: camera axes in world coordinates
    q = Rotation.from_matrix(rot).as_quat()
    return Transform(Vec3(*map(float, eye)), Quat(*map(float, q)))


@dataclass(frozen=True)
class PinholeCamera:
    """A calibrated camera with a world pose; projection goes through OpenCV."""

    model: CameraModel

    def __post_init__(self) -> None:
        if self.model.world_from_camera is None:
            raise ValueError(f"camera {self.model.camera!r} has no world pose (world_from_camera)")

    # Derived matrices are cached: projection sits on per-frame hot paths (the model is frozen).
    @cached_property
    def K(self) -> np.ndarray:  # noqa: N802 - the conventional name
        m = self.model
        return np.array([[m.fx_px, 0, m.cx_px], [0, m.fy_px, m.cy_px], [0, 0, 1.0]])

    @cached_property
    def dist(self) -> np.ndarray:
        return np.asarray(self.model.distortion or (0.0,) * 5, float)

    @cached_property
    def world_R_cam(self) -> np.ndarray:  # noqa: N802
        q = self.model.world_from_camera.rotation  # type: ignore[union-attr]
        return np.asarray(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), float)

    @cached_property
    def position(self) -> np.ndarray:
        t = self.model.world_from_camera.translation  # type: ignore[union-attr]
        return np.array([t.x, t.y, t.z])

    @cached_property
    def _extrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        r_cw = self.world_R_cam.T
        rvec, _ = cv2.Rodrigues(r_cw)
        return rvec, -r_cw @ self.position

    def to_camera(self, points_w: np.ndarray) -> np.ndarray:
        """World points (N, 3) in the camera optical frame."""
        return np.asarray((np.asarray(points_w, float) - self.position) @ self.world_R_cam)

    def project(self, points_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) of world points and a mask of those in front of the camera."""
        pts = np.asarray(points_w, float).reshape(-1, 3)
        rvec, tvec = self._extrinsics
        px, _ = cv2.projectPoints(pts, rvec, tvec, self.K, self.dist)
        depth = self.to_camera(pts)[:, 2]
        return px.reshape(-1, 2), depth > 1e-6

    def visible(self, points_w: np.ndarray) -> np.ndarray:
        """Mask of world points that project inside the image, in front of the camera."""
        px, front = self.project(points_w)
        m = self.model
        return (
            front
            & (px[:, 0] >= 0)
            & (px[:, 0] < m.width_px)
            & (px[:, 1] >= 0)
            & (px[:, 1] < m.height_px)
        )

    def ground_point(self, pixels: np.ndarray, ground_z: float = 0.0) -> np.ndarray:
        """World points (N, 3) where the rays through ``pixels`` meet the plane z = ground_z.

        Rays that do not meet the plane in front of the camera give NaN rows.
        """
        px = np.asarray(pixels, float).reshape(-1, 1, 2)
        if len(px) == 0:
            return np.empty((0, 3))
        norm = cv2.undistortPoints(px, self.K, self.dist).reshape(-1, 2)
        rays_c = np.column_stack([norm, np.ones(len(norm))])
        rays_w = rays_c @ self.world_R_cam.T
        origin = self.position
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (ground_z - origin[2]) / rays_w[:, 2]
        s = np.where(s > 0, s, np.nan)
        return np.asarray(origin + rays_w * s[:, None])
