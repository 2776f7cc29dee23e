"""View bridging (dissertation §4.2.3 A): tags localized by the infrastructure cameras (Eq. 4.6)
localize the robot that sees the same tags (Eqs. 4.7-4.9).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from trackctl.bridgeloc.detect import TagDetection
from trackctl.logs.messages import CameraModel, Transform

__all__ = [
    "CameraGeometry",
    "MapTag",
    "TagMap",
    "bridge_lstsq",
    "bridge_pnp",
    "tag_corners_in_camera",
]


def _rt(tf: Transform) -> tuple[np.ndarray, np.ndarray]:
    q = tf.rotation
    r = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    t = np.array([tf.translation.x, tf.translation.y, tf.translation.z])
    return r, t


@dataclass(frozen=True)
class CameraGeometry:
    """Intrinsics and the pose of a camera (world <- camera, or base <- camera on the robot)."""

    name: str
    K: np.ndarray  # noqa: N815
    dist: np.ndarray
    R: np.ndarray  # noqa: N815
    t: np.ndarray

    @classmethod
    def from_model(cls, model: CameraModel) -> CameraGeometry:
        if model.world_from_camera is None:
            raise ValueError(f"camera {model.camera!r} has no pose")
        r, t = _rt(model.world_from_camera)
        k = np.array([[model.fx_px, 0, model.cx_px], [0, model.fy_px, model.cy_px], [0, 0, 1.0]])
        d = np.asarray(model.distortion or (0.0,) * 5, float)
        return cls(model.camera, k, d, r, t)


def _object_square(size_m: float) -> np.ndarray:
    h = size_m / 2
    # the order SOLVEPNP_IPPE_SQUARE requires: TL, TR, BR, BL with y up
    return np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], np.float64)


def tag_corners_in_camera(
    det: TagDetection, cam: CameraGeometry, size_m: float
) -> np.ndarray | None:
    """Corners (4, 3) of a detected tag in the camera's optical frame (V_o^(C), V_o^(R)).

    ``cv2.solvePnP`` with ``SOLVEPNP_IPPE_SQUARE`` (the planar-square solver) on the sub-pixel
    corners, distortion included.
    """
    obj = _object_square(size_m)
    ok, rvec, tvec = cv2.solvePnP(
        obj,
        det.corners.astype(np.float64).reshape(-1, 1, 2),
        cam.K,
        cam.dist,
        flags=cv2.SOLVEPNP_IPPE_SQUARE,
    )
    if not ok:
        return None
    rot, _ = cv2.Rodrigues(rvec)
    pts = obj @ rot.T + tvec.reshape(1, 3)
    if (pts[:, 2] <= 0).any():
        return None
    return pts


@dataclass
class MapTag:
    """A tag localized in the ground frame by the infrastructure cameras (Eq. 4.6)."""

    pattern_id: str
    mount: str
    corners: np.ndarray
    weight: float
    samples: list[tuple[np.ndarray, float]] = field(default_factory=list)

    @property
    def center(self) -> np.ndarray:
        return self.corners.mean(axis=0)

    @property
    def signature(self) -> str:
        """What the robot can tell apart: pattern + above/below its camera."""
        return f"{self.pattern_id}/{self.mount}"


class TagMap:
    """Tags in the ground frame, accumulated over infrastructure camera frames (tags are static)."""

    def __init__(self, camera_height_m: float, merge_m: float = 0.6) -> None:
        self.camera_height_m = camera_height_m
        self.merge_m = merge_m
        self.tags: list[MapTag] = []

    def add(self, det: TagDetection, cam: CameraGeometry, size_m: float) -> MapTag | None:
        """Eq. 4.6: V_o^(G) = Υ(Θ^(C→G)) V_o^(C) + V_c^(G) for every corner; merge into the map."""
        pc = tag_corners_in_camera(det, cam, size_m)
        if pc is None:
            return None
        pw = pc @ cam.R.T + cam.t
        dist = float(np.linalg.norm(pc.mean(axis=0)))
        weight = 1.0 / max(dist, 0.3) ** 4  # corner noise grows ~ d^2 in position
        ctr = pw.mean(axis=0)
        for tag in self.tags:
            if tag.pattern_id == det.pattern_id and np.linalg.norm(tag.center - ctr) < self.merge_m:
                tag.samples.append((pw, weight))
                ws = np.array([w for _, w in tag.samples])
                # weighted median-like robust mean: drop the worst 20% by distance to the median
                stack = np.stack([p for p, _ in tag.samples])
                med = np.median(stack, axis=0)
                err = np.linalg.norm(stack - med, axis=2).mean(axis=1)
                keep = err <= np.quantile(err, 0.8) if len(err) >= 5 else np.ones(len(err), bool)
                tag.corners = np.average(stack[keep], axis=0, weights=ws[keep])
                tag.weight = float(ws.sum())
                return tag
        mount = "above" if ctr[2] > self.camera_height_m else "below"
        tag = MapTag(det.pattern_id, mount, pw, weight, [(pw, weight)])
        self.tags.append(tag)
        return tag

    def candidates(self, signature: str) -> list[MapTag]:
        """Tags sharing a signature (pattern + mount)."""
        return [t for t in self.tags if t.signature == signature]

    def finalize(self, min_samples: int = 3) -> None:
        """Drop tags seen fewer than ``min_samples`` times (misreads), re-derive above/below from
        the final (averaged) centres."""
        self.tags = [t for t in self.tags if len(t.samples) >= min_samples]
        for t in self.tags:
            t.mount = "above" if t.center[2] > self.camera_height_m else "below"


def bridge_lstsq(world_xy: np.ndarray, robot_xy: np.ndarray) -> tuple[float, float, float]:
    """Eq. 4.9 with known camera height: the planar pose from >= 2 corresponding points.

    The robot cannot roll or pitch, so Υ(Θ^(R→G)) is a yaw rotation and
    ``V_o^(G) = Υ(θ) V_o^(R) + V_r^(G)`` is linear in (cos θ, sin θ, x_r, y_r): two equations per
    point, solved by the pseudo-inverse (``np.linalg.lstsq``), then (cos θ, sin θ) normalised.
    """
    w = np.asarray(world_xy, float).reshape(-1, 2)
    r = np.asarray(robot_xy, float).reshape(-1, 2)
    if len(w) < 2:
        raise ValueError("bridging needs at least 2 points with a known camera height")
    a = np.zeros((2 * len(w), 4))
    a[0::2] = np.column_stack([r[:, 0], -r[:, 1], np.ones(len(r)), np.zeros(len(r))])
    a[1::2] = np.column_stack([r[:, 1], r[:, 0], np.zeros(len(r)), np.ones(len(r))])
    sol, *_ = np.linalg.lstsq(a, w.reshape(-1), rcond=None)
    yaw = math.atan2(sol[1], sol[0])
    c, s = math.cos(yaw), math.sin(yaw)
    # re-solve the translation with the normalised rotation
    rot = np.array([[c, -s], [s, c]])
    t = (w - r @ rot.T).mean(axis=0)
    return float(t[0]), float(t[1]), yaw


def bridge_pnp(
    world_pts: np.ndarray, image_pts: np.ndarray, cam: CameraGeometry
) -> tuple[float, float, float] | None:
    """The alternative: one ``cv2.solvePnP`` of the robot camera against the mapped corners.

    ``cam`` holds base <- camera; returns the base pose (x, y, yaw) in the ground frame.
    """
    ok, rvec, tvec = cv2.solvePnP(
        np.asarray(world_pts, np.float64),
        np.asarray(image_pts, np.float64).reshape(-1, 1, 2),
        cam.K,
        cam.dist,
        flags=cv2.SOLVEPNP_IPPE if len(world_pts) == 4 else cv2.SOLVEPNP_ITERATIVE,
    )
    if not ok:
        return None
    r_cw, _ = cv2.Rodrigues(rvec)
    r_wc = r_cw.T
    p_cam = -r_wc @ tvec.reshape(3)
    r_wb = r_wc @ cam.R.T  # world <- base = world <- cam * cam <- base
    p_base = p_cam - r_wb @ cam.t
    yaw = math.atan2(r_wb[1, 0], r_wb[0, 0])
    return float(p_base[0]), float(p_base[1]), yaw
