"""View bridging (dissertation §4.2.3 A): tags localized by the infrastructure cameras (Eq. 4.6)
localize the robot that sees the same tags (Eqs. 4.7-4.9).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from trackctl.bridgeloc.detect import TagDetection
from trackctl.logs.messages import CameraModel, Transform

__all__ = [
    "BridgeObservation",
    "bridge_branches",
    "bridge_pose",
    "corner_jacobian",
    "map_jacobian",
    "project_corners",
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


@dataclass(eq=False)
class MapTag:
    """A tag localized in the ground frame by the infrastructure cameras (Eq. 4.6).

    Sightings are kept (corners, weight); the running weighted mean is what new sightings are
    merged against, and :meth:`TagMap.finalize` replaces it by the robust mean once."""

    pattern_id: str
    mount: str
    corners: np.ndarray
    weight: float
    samples: list[tuple[np.ndarray, float]] = field(default_factory=list)
    _sum: np.ndarray | None = None
    cameras: dict[str, int] = field(default_factory=dict)
    """Sightings per infrastructure camera."""
    nearest_m: float = math.inf
    """Distance of the nearest camera that saw it (its systematic error grows with it)."""
    sigma_m: float = 0.02
    """Std of a mapped corner (m): the sightings' scatter, at least 1 cm (set by
    :meth:`robust_mean`)."""

    @property
    def center(self) -> np.ndarray:
        return self.corners.mean(axis=0)

    @property
    def signature(self) -> str:
        """What the robot can tell apart: pattern + above/below its camera."""
        return f"{self.pattern_id}/{self.mount}"

    @property
    def sightings(self) -> int:
        return len(self.samples)

    def add_sample(self, corners: np.ndarray, weight: float) -> None:
        """O(1): the running weighted mean (the robust one is computed once, at the end)."""
        if self._sum is None:
            self._sum = self.corners * self.weight
        self.samples.append((corners, weight))
        self._sum = self._sum + corners * weight
        self.weight += weight
        self.corners = self._sum / self.weight

    def robust_mean(self, trim: float = 0.2, systematic_per_m: float = 0.0) -> None:
        """Weighted mean without the worst ``trim`` share of sightings (by distance to the
        median), the estimate the map keeps; ``sigma_m`` = the sightings' scatter, at least
        1 cm, plus ``systematic_per_m`` x the nearest camera's distance (calibration, bias)."""
        stack = np.stack([p for p, _ in self.samples])
        ws = np.array([w for _, w in self.samples])
        if len(stack) >= 5:
            med = np.median(stack, axis=0)
            err = np.linalg.norm(stack - med, axis=2).mean(axis=1)
            keep = err <= np.quantile(err, 1.0 - trim)
        else:
            keep = np.ones(len(stack), bool)
        self.corners = np.average(stack[keep], axis=0, weights=ws[keep])
        spread = np.linalg.norm(stack[keep] - self.corners, axis=2).mean(axis=1)
        scatter = float(np.sqrt(np.average(spread**2, weights=ws[keep])))
        systematic = systematic_per_m * (self.nearest_m if math.isfinite(self.nearest_m) else 0.0)
        self.sigma_m = math.hypot(0.01, scatter, systematic)
        self.weight = float(ws.sum())


class TagMap:
    """Tags in the ground frame, accumulated over infrastructure camera frames (tags are static).

    Adding a sighting is O(tags of that pattern); the robust mean of each tag is computed once
    in :meth:`finalize` (O(sightings log sightings) in all)."""

    def __init__(
        self, camera_height_m: float, merge_m: float = 0.6, systematic_per_m: float = 0.0
    ) -> None:
        self.camera_height_m = camera_height_m
        self.merge_m = merge_m
        self.systematic_per_m = systematic_per_m
        self.tags: list[MapTag] = []
        self._by_pattern: dict[str, list[MapTag]] = {}

    def add(self, det: TagDetection, cam: CameraGeometry, size_m: float) -> MapTag | None:
        """Eq. 4.6: V_o^(G) = Υ(Θ^(C→G)) V_o^(C) + V_c^(G) for every corner; merge into the map."""
        pw = _upright_branch(det, cam, size_m)
        if pw is None:
            return None
        pc = (pw - cam.t) @ cam.R
        dist = float(np.linalg.norm(pc.mean(axis=0)))
        weight = 1.0 / max(dist, 0.3) ** 4  # corner noise grows ~ d^2 in position
        ctr = pw.mean(axis=0)
        same = self._by_pattern.setdefault(det.pattern_id, [])
        for tag in same:
            if np.linalg.norm(tag.center - ctr) < self.merge_m:
                tag.add_sample(pw, weight)
                tag.cameras[cam.name] = tag.cameras.get(cam.name, 0) + 1
                tag.nearest_m = min(tag.nearest_m, dist)
                return tag
        mount = "above" if ctr[2] > self.camera_height_m else "below"
        tag = MapTag(
            det.pattern_id, mount, pw, weight, [(pw, weight)], cameras={cam.name: 1}, nearest_m=dist
        )
        self.tags.append(tag)
        same.append(tag)
        return tag

    def candidates(self, signature: str) -> list[MapTag]:
        """Tags sharing a signature (pattern + mount)."""
        return [t for t in self.tags if t.signature == signature]

    def finalize(
        self,
        frames: Mapping[str, int] | None = None,
        min_samples: int = 3,
        min_share: float = 0.2,
    ) -> None:
        """Robust mean of every tag; re-derive above/below from the final centres. A tag is a
        fixture seen by fixed cameras, so it is kept only if seen ``min_samples`` times and in
        at least ``min_share`` of the frames of some camera (``frames``: frames per camera);
        a misread or a passing pattern (a person's shirt) is not."""
        frames = frames or {}

        def stable(t: MapTag) -> bool:
            if len(t.samples) < min_samples:
                return False
            return not frames or any(
                n >= min_share * frames.get(c, n) for c, n in t.cameras.items()
            )

        self.tags = [t for t in self.tags if stable(t)]
        for t in self.tags:
            t.robust_mean(systematic_per_m=self.systematic_per_m)
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


@dataclass(frozen=True)
class BridgeObservation:
    """One tag seen by the robot camera and the map tag it is taken to be."""

    detection: TagDetection
    world: np.ndarray
    """The map tag's corners (4, 3) in the ground frame."""


def _ippe_branches(det: TagDetection, cam: CameraGeometry, size_m: float) -> list[np.ndarray]:
    """Both solutions of the planar-square PnP (a small tag's pose is two-fold ambiguous), as
    corners in the robot's base frame."""
    obj = _object_square(size_m)
    n, rvecs, tvecs, _ = cv2.solvePnPGeneric(
        obj,
        det.corners.astype(np.float64).reshape(-1, 1, 2),
        cam.K,
        cam.dist,
        flags=cv2.SOLVEPNP_IPPE_SQUARE,
    )
    out = []
    for k in range(n):
        rot, _ = cv2.Rodrigues(rvecs[k])
        pc = obj @ rot.T + tvecs[k].reshape(1, 3)
        if (pc[:, 2] > 0).all():
            out.append(pc @ cam.R.T + cam.t)
    return out


def _upright_branch(det: TagDetection, cam: CameraGeometry, size_m: float) -> np.ndarray | None:
    """World corners of a tag seen by a fixed camera (``cam`` = world <- camera).

    Of the planar PnP's two solutions, the one whose reprojection is better, unless both fit
    the corners within a pixel (a small tag seen near head-on): tags hang on vertical walls, so
    the one whose face is nearer vertical is taken. Averaging sightings of either branch gave a
    map tag turned 40° off its wall, which then pulled the robot 0.7 m off."""
    obj = _object_square(size_m)
    img = det.corners.astype(np.float64).reshape(-1, 1, 2)
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(
        obj, img, cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE
    )
    options = []
    for k in range(n):
        rot, _ = cv2.Rodrigues(rvecs[k])
        pc = obj @ rot.T + tvecs[k].reshape(1, 3)
        if (pc[:, 2] > 0).all():
            pw = pc @ cam.R.T + cam.t
            nrm = np.cross(pw[1] - pw[0], pw[3] - pw[0])
            tilt = abs(float(nrm[2])) / max(float(np.linalg.norm(nrm)), 1e-12)
            options.append((float(np.ravel(errs)[k]), tilt, pw))
    if not options:
        return None
    options.sort(key=lambda o: o[0])
    if len(options) == 2 and options[1][0] < 1.0:
        return min(options, key=lambda o: o[1])[2]
    return options[0][2]


def project_corners(
    pose: tuple[float, float, float] | np.ndarray, world: np.ndarray, cam: CameraGeometry
) -> np.ndarray:
    """Pixels (M, 2) of world points seen by the robot camera with the base at ``pose``
    (x, y, yaw on the floor; ``cam`` holds base <- camera), lens distortion included."""
    x, y, yaw = (float(v) for v in pose)
    c, s = math.cos(yaw), math.sin(yaw)
    r_wb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    r_wc = r_wb @ cam.R
    p_c = r_wb @ cam.t + [x, y, 0.0]
    r_cw = r_wc.T
    rvec, _ = cv2.Rodrigues(r_cw)
    px, _ = cv2.projectPoints(np.asarray(world, np.float64), rvec, -r_cw @ p_c, cam.K, cam.dist)
    return px.reshape(-1, 2)


def _central_differences(
    fn: Callable[[np.ndarray], np.ndarray], steps: tuple[float, ...]
) -> np.ndarray:
    """d fn / d v at v = 0, one column per entry of ``v`` (its step in ``steps``)."""
    cols = []
    for i, eps in enumerate(steps):
        d = np.zeros(len(steps))
        d[i] = eps
        cols.append((fn(d) - fn(-d)).reshape(-1) / (2 * eps))
    return np.column_stack(cols)


def map_jacobian(
    pose: tuple[float, float, float] | np.ndarray, world: np.ndarray, cam: CameraGeometry
) -> np.ndarray:
    """d pixels / d (the mapped tag's x, y, z, yaw), (2M, 4): the tag moved as a whole, and
    turned about the vertical through its centre (central differences, as
    :func:`corner_jacobian`)."""
    w = np.asarray(world, float)
    ctr = w.mean(axis=0)

    def moved(v: np.ndarray) -> np.ndarray:
        c, s = math.cos(v[3]), math.sin(v[3])
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return project_corners(pose, (w - ctr) @ rot.T + ctr + v[:3], cam)

    return _central_differences(moved, (1e-4, 1e-4, 1e-4, 1e-5))


def corner_jacobian(
    pose: tuple[float, float, float] | np.ndarray, world: np.ndarray, cam: CameraGeometry
) -> np.ndarray:
    """d pixels / d (x, y, yaw), (2M, 3), by central differences (projectPoints has no
    derivative with respect to our planar pose parametrisation)."""
    p = np.asarray(pose, float)
    return _central_differences(lambda d: project_corners(p + d, world, cam), (1e-4, 1e-4, 1e-5))


def bridge_branches(
    observations: list[BridgeObservation],
    cam: CameraGeometry,
    size_m: float,
    sigma_px: float,
    floor_m: float = 0.0,
    floor_rad: float = 0.0,
) -> list[tuple[tuple[float, float, float], np.ndarray, float]]:
    """The robot poses from tags seen and mapped that the pixels allow, with their 3x3
    covariances and reprojection costs (px^2), best first.

    Eq. 4.9 (least squares on the corners in the base frame, known camera height), once per
    solution of the first tag's two-fold planar PnP ambiguity; a solution is kept unless its
    mapped corners reproject worse than the best by more than the noise explains (chi-square
    in 3 dof, 99 %): a small tag seen near head-on keeps both. (Refining it by minimising the
    reprojection error over (x, y, yaw) was tried: one small far tag leaves a valley in which
    the refined pose wanders farther than Eq. 4.9's, 0.12 against 0.08 m on the office log: the
    map's corners are not exact, and Eq. 4.9 leans less on the tag's mapped tilt.) Covariance:
    for one tag, ``sigma_px`` on each corner pixel propagated through the whole chain (planar
    PnP, mount, Eq. 4.9) by finite differences that follow the chosen PnP branch; for several
    tags ``sigma_px``^2 (J^T J)^-1 of the reprojection. Either is long along the valley a far
    tag leaves. ``floor_m`` / ``floor_rad`` are added for what pixel noise does not explain
    (camera mount, tag map, robot tilt).
    """
    if not observations:
        return []
    world = np.concatenate([ob.world for ob in observations])
    image = np.concatenate([ob.detection.corners for ob in observations]).reshape(-1)
    rest = []
    for ob in observations[1:]:
        pc = tag_corners_in_camera(ob.detection, cam, size_m)
        if pc is not None:
            rest.append((ob.world[:, :2], (pc @ cam.R.T + cam.t)[:, :2]))
    w = np.concatenate([observations[0].world[:, :2], *[r[0] for r in rest]])

    def poses(det: TagDetection) -> list[tuple[float, float, float]]:
        return [
            bridge_lstsq(w, np.concatenate([pb[:, :2], *[r[1] for r in rest]]))
            for pb in _ippe_branches(det, cam, size_m)
        ]

    first = observations[0].detection
    cands = poses(first)
    if not cands:
        return []
    cost = [float(np.sum((project_corners(p, world, cam).reshape(-1) - image) ** 2)) for p in cands]
    floor = np.diag([floor_m**2, floor_m**2, floor_rad**2])
    # the cost difference of two poses is chi-square in the pose's 3 dof when both fit
    plausible = float(chi2.ppf(0.99, 3)) * sigma_px**2
    out = []
    for k in np.argsort(cost):
        if cost[k] - min(cost) > plausible:
            continue  # the pixels rule this branch out
        pose = cands[int(k)]
        if len(observations) == 1:
            cov = _branch_cov(first, pose, poses, sigma_px)
        else:  # several tags: the reprojection's information (Eq. 4.9 is near-efficient)
            jac = corner_jacobian(pose, world, cam)
            try:
                cov = sigma_px**2 * np.linalg.inv(jac.T @ jac)
            except np.linalg.LinAlgError:
                cov = None
        if cov is not None:
            out.append((pose, cov + floor, cost[int(k)]))
    return out


def _branch_cov(
    det: TagDetection,
    pose: tuple[float, float, float],
    poses: Callable[[TagDetection], list[tuple[float, float, float]]],
    sigma_px: float,
) -> np.ndarray | None:
    """d pose / d pixel of one tag's corners, following the branch at ``pose`` (finite
    differences), times ``sigma_px``^2."""
    eps = 0.05
    cols = []
    for i in range(8):
        px = np.array(det.corners, np.float64)
        px.flat[i] += eps
        moved = poses(replace(det, corners=px))
        if not moved:
            return None
        near = min(moved, key=lambda p: _pose_dist(p, pose))
        cols.append(
            np.array([near[0] - pose[0], near[1] - pose[1], _wrap(near[2] - pose[2])]) / eps
        )
    jac_px = np.array(cols).T
    return np.asarray(sigma_px**2 * jac_px @ jac_px.T)


def bridge_pose(
    observations: list[BridgeObservation],
    cam: CameraGeometry,
    size_m: float,
    sigma_px: float,
    floor_m: float = 0.0,
    floor_rad: float = 0.0,
) -> tuple[tuple[float, float, float], np.ndarray] | None:
    """The best branch of :func:`bridge_branches`; when the other branch is plausible too, the
    covariance also spans the gap between them (the pose is one or the other)."""
    branches = bridge_branches(observations, cam, size_m, sigma_px, floor_m, floor_rad)
    if not branches:
        return None
    pose, cov, _ = branches[0]
    for other, _, _ in branches[1:]:
        d = np.array([other[0] - pose[0], other[1] - pose[1], _wrap(other[2] - pose[2])])
        cov = cov + np.outer(d, d)
    return pose, cov


def _pose_dist(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1]) + abs(_wrap(a[2] - b[2]))


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))
