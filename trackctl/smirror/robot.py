"""The robot side of S-Mirror (§4.1.2 C, Fig. 4.5): LED detection in a node's image, a pose fix
through the node's calibrated camera, and dead reckoning calibrated at every fix.

The fusion is an extended Kalman filter (filterpy) over (x, y, yaw): wheel odometry drives the
prediction, LED fixes the update. With a fix far more certain than the dead-reckoned pose the
update is exactly Fig. 4.5's offset calibration (the odometry offset is deducted from then on);
the filter also weighs a far, noisy fix against a short, good dead-reckoning run. Fixes arrive
late (communication and processing delay): the filter rewinds to the frame's time, updates and
replays the odometry since, so the offset is computed at the instant the image was taken.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np

from trackctl.geometry.camera import PinholeCamera
from trackctl.geometry.odometry_ekf import DiffDriveEkf, OdometryNoise, wrap

__all__ = [
    "LedConfig",
    "LedFix",
    "detect_leds",
    "fix_from_leds",
    "locate_robot",
    "PoseFilter",
    "wrap",
]


@dataclass(frozen=True, slots=True)
class LedConfig:
    """The robot's LED markers and how they are told apart from the scene."""

    led_height_m: float = 0.32
    led_front_m: float = 0.15
    led_back_m: float = -0.15
    front_hue: tuple[int, int] = (45, 80)
    """OpenCV hue range (0..180) of the front LED (green)."""
    back_hue: tuple[int, int] = (135, 170)
    """Hue range of the back LED (magenta)."""
    min_saturation: int = 110
    min_value: int = 150
    max_blob_px: float = 400.0
    """Largest blob (pixels, at a 686 px focal length; scaled by focal length squared) that can
    be an LED: a diffused LED glows ~4 cm wide, 15-140 px from 3-11 m. Bigger blobs of the LED
    colours are clothes, signs or lamps and never taken for the robot."""
    candidates: int = 4
    """Blobs of each colour tried in pairs (largest first)."""


@dataclass(frozen=True, slots=True)
class LedFix:
    """A pose fix from one node image."""

    t_ns: int
    x_m: float
    y_m: float
    yaw_rad: float
    range_m: float
    """Ground distance from the node camera (its error grows with it)."""
    node: str


def _blobs(
    hsv: np.ndarray, hue: tuple[int, int], cfg: LedConfig, max_area: float
) -> list[tuple[int, float, float]]:
    """(area, x, y) of the blobs of one LED colour that are small enough to be an LED."""
    mask = cv2.inRange(hsv, (hue[0], cfg.min_saturation, cfg.min_value), (hue[1], 255, 255))
    n, _, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    return [
        (int(stats[k, cv2.CC_STAT_AREA]), float(cents[k, 0]), float(cents[k, 1]))
        for k in range(1, n)
        if stats[k, cv2.CC_STAT_AREA] <= max_area
    ]


def locate_robot(
    crops: list[tuple[int, int, np.ndarray]],
    cam: PinholeCamera,
    cfg: LedConfig,
    t_ns: int,
    near: tuple[float, float] | None = None,
) -> LedFix | None:
    """The robot's pose from the LED-coloured blobs in ``crops`` (full-frame offsets x, y).

    Blobs too large for an LED are ignored; of the remaining front/back pairs (the largest
    ``cfg.candidates`` of each colour), the fix is the pair whose two points on the LED plane
    lie the LEDs' distance apart (within 40 %), the one nearest ``near`` (the robot's predicted
    position) when given, else the one closest to that distance. None when no pair fits:
    clothes, signs or lamps in the LEDs' colours are not taken for the robot.
    """
    max_area = cfg.max_blob_px * (cam.model.fx_px / 686.0) ** 2
    found: list[list[tuple[int, float, float]]] = [[], []]
    for x0, y0, image in crops:
        hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
        for k, hue in enumerate((cfg.front_hue, cfg.back_hue)):
            found[k] += [(a, x + x0, y + y0) for a, x, y in _blobs(hsv, hue, cfg, max_area)]
    fronts = sorted(found[0], reverse=True)[: cfg.candidates]
    backs = sorted(found[1], reverse=True)[: cfg.candidates]
    spacing = cfg.led_front_m - cfg.led_back_m
    best: tuple[float, LedFix] | None = None
    for _, fx, fy in fronts:
        for _, bx, by in backs:
            fix = fix_from_leds(
                np.array([fx, fy]),
                np.array([bx, by]),
                cam,
                cfg,
                t_ns,
                gate_m=(0.6 * spacing, 1.4 * spacing),
            )
            if fix is None:
                continue
            if near is not None:
                score = math.hypot(fix.x_m - near[0], fix.y_m - near[1])
            else:
                pts = cam.ground_point(np.array([[fx, fy], [bx, by]]), cfg.led_height_m)
                score = abs(float(np.linalg.norm(pts[0, :2] - pts[1, :2])) - spacing)
            if best is None or score < best[0]:
                best = (score, fix)
    return None if best is None else best[1]


def detect_leds(
    crops: list[tuple[int, int, np.ndarray]], cfg: LedConfig
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Pixel centroids (full-frame coordinates) of the front and back LED, or None when unseen.

    ``crops`` are ``(x, y, image)`` with x/y the crop's top-left pixel in the full frame (a
    whole frame is one crop at 0, 0). The largest blob of each LED colour over all crops wins.
    """
    best: list[tuple[int, float, float] | None] = [None, None]
    for x0, y0, image in crops:
        hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
        for k, hue in enumerate((cfg.front_hue, cfg.back_hue)):
            for area, x, y in _blobs(hsv, hue, cfg, math.inf):
                kept = best[k]
                if kept is None or area > kept[0]:
                    best[k] = (area, x + x0, y + y0)
    front, back = best
    return (
        None if front is None else np.array(front[1:]),
        None if back is None else np.array(back[1:]),
    )


def fix_from_leds(
    front_px: np.ndarray,
    back_px: np.ndarray,
    cam: PinholeCamera,
    cfg: LedConfig,
    t_ns: int,
    gate_m: tuple[float, float] = (0.08, 0.8),
) -> LedFix | None:
    """Robot pose from its two LEDs: both rays meet the LED plane; centre and heading follow.

    Returns None when the two ground points are implausibly close or far apart (a false blob).
    """
    pts = cam.ground_point(np.vstack([front_px, back_px]), ground_z=cfg.led_height_m)
    if not np.isfinite(pts).all():
        return None
    f, b = pts[0, :2], pts[1, :2]
    base = float(np.linalg.norm(f - b))
    if not gate_m[0] <= base <= gate_m[1]:
        return None
    d = (f - b) / base
    centre = f - cfg.led_front_m * d
    rng = float(np.linalg.norm(centre - cam.position[:2]))
    return LedFix(
        t_ns, float(centre[0]), float(centre[1]), math.atan2(d[1], d[0]), rng, cam.model.camera
    )


@dataclass(frozen=True, slots=True)
class FilterConfig:
    """Noise model of the fusion."""

    odom_rel_sigma: float = 0.03
    """Relative error of a wheel-odometry distance increment."""
    yaw_per_m_sigma: float = 0.03
    """Heading random walk per metre travelled (rad/m): differential wheel scale, slip."""
    yaw_rel_sigma: float = 0.05
    """Relative error of a heading increment (turns in place scrub the wheels)."""
    fix_px_sigma: float = 0.8
    """LED centroid error in pixels (JPEG, noise, partial blobs)."""
    fix_floor_m: float = 0.03
    calib_rad: float = 0.003
    """Residual calibration error of a node camera (rad): a ground error growing with range."""
    heading_bias_sigma: float = 0.1
    """Prior std of the heading bias per metre (rad/m): opposite wheel-scale errors of +-1.5 %
    on a 0.30 m wheel base (uncalibrated platforms show 1-2 %, Borenstein & Feng's UMBmark)."""
    heading_bias_walk: float = 0.002
    """Random walk of that bias per metre (rad/m per sqrt(m)): load, floor, tyre wear."""
    gate_chi2: float = 16.27
    """Mahalanobis gate of a fix (chi-square, 3 dof, 99.9 %)."""
    max_rejects: int = 3
    """After this many consecutive rejected fixes the filter trusts the camera again."""


class PoseFilter:
    """Dead reckoning + LED fixes, with rewind for late fixes (keeps a few seconds of history)."""

    def __init__(
        self,
        x: float,
        y: float,
        yaw: float,
        t_ns: int,
        cfg: FilterConfig,
        localized: bool = True,
    ) -> None:
        self.cfg = cfg
        self.localized = localized
        """False until the first fix when the start is unknown: the state is then a placeholder
        (dead reckoning from nowhere) and the first fix sets it, at the fix's time."""
        self.ekf = DiffDriveEkf()
        self._noise = OdometryNoise(
            cfg.odom_rel_sigma,
            cfg.yaw_per_m_sigma,
            cfg.yaw_rel_sigma,
            cfg.heading_bias_sigma,
            cfg.heading_bias_walk,
        )
        self.ekf.x = np.array([[x], [y], [yaw], [0.0]])
        self.ekf.P = np.diag([0.05**2, 0.05**2, 0.05**2, cfg.heading_bias_sigma**2])
        self.ekf.R = np.eye(3)
        self.t_ns = t_ns
        # (t_ns, x, P, increment that led here)
        self._hist: deque[tuple[int, np.ndarray, np.ndarray, tuple[float, float]]] = deque(
            maxlen=150
        )
        self._hist.append((t_ns, self.ekf.x.copy(), self.ekf.P.copy(), (0.0, 0.0)))
        self.rejects = 0
        self.last_nis: float | None = None
        """Normalized innovation squared of the last fix that was tested against the state."""

    @property
    def pose(self) -> tuple[float, float, float]:
        return float(self.ekf.x[0, 0]), float(self.ekf.x[1, 0]), float(self.ekf.x[2, 0])

    @property
    def heading_bias(self) -> float:
        """The learnt heading bias per metre (rad/m)."""
        return float(self.ekf.x[3, 0])

    def _predict(self, ds: float, dyaw: float) -> None:
        self.ekf.predict_odometry(ds, dyaw, self._noise)

    def step(self, t_ns: int, ds: float, dyaw: float) -> None:
        """Dead-reckon one odometry increment."""
        self._predict(ds, dyaw)
        self.t_ns = t_ns
        self._hist.append((t_ns, self.ekf.x.copy(), self.ekf.P.copy(), (ds, dyaw)))

    def fix_sigma(
        self, fix: LedFix, cam: PinholeCamera, led_height_m: float
    ) -> tuple[float, float]:
        """(position sigma m, heading sigma rad) of a fix at its range (ground error ~ d^2)."""
        drop = max(0.3, float(cam.position[2]) - led_height_m)
        d = math.hypot(fix.range_m, drop)
        per_px = d * d / (cam.model.fx_px * drop)
        sp = math.hypot(
            self.cfg.fix_floor_m, self.cfg.fix_px_sigma * per_px, self.cfg.calib_rad * d * d / drop
        )
        sy = min(1.5, math.sqrt(2) * math.hypot(self.cfg.fix_px_sigma * per_px, 0.01) / 0.3)
        return sp, sy

    def apply_fix(self, fix: LedFix, sigma_pos: float, sigma_yaw: float) -> bool:
        """Fuse a (possibly late) fix taken at ``fix.t_ns``; False when gated out or too old."""
        idx = None
        for i in range(len(self._hist) - 1, -1, -1):
            if self._hist[i][0] <= fix.t_ns:
                idx = i
                break
        if idx is None:
            return False
        later = list(self._hist)[idx + 1 :]
        t0, x0, p0, _ = self._hist[idx]
        saved = (self.ekf.x.copy(), self.ekf.P.copy())
        self.ekf.x, self.ekf.P = x0.copy(), p0.copy()
        z = np.array([[fix.x_m], [fix.y_m], [fix.yaw_rad]])
        r = np.diag([sigma_pos**2, sigma_pos**2, sigma_yaw**2])
        if not self.localized:
            # the first fix of an unknown start: the pose is the fix, its covariance the fix's;
            # the heading bias keeps its prior
            self.localized = True
            x_new = np.vstack([z, self.ekf.x[3:]])
            p_new = np.zeros((4, 4))
            p_new[:3, :3] = r
            p_new[3, 3] = self.ekf.P[3, 3]
            self._replay(idx, t0, x_new, p_new, later)
            return True
        y = z - self.ekf.x[:3]
        y[2, 0] = wrap(float(y[2, 0]))
        s = self.ekf.P[:3, :3] + r
        d2 = float((y.T @ np.linalg.solve(s, y))[0, 0])
        self.last_nis = d2
        if d2 > self.cfg.gate_chi2 and self.rejects < self.cfg.max_rejects:
            self.rejects += 1
            self.ekf.x, self.ekf.P = saved
            return False
        if d2 > self.cfg.gate_chi2:
            # the camera keeps disagreeing: the dead-reckoned pose is what is wrong (wheel slip,
            # a bad start); widen its covariance by the disagreement so the fix takes over
            self.ekf.P[:3, :3] = self.ekf.P[:3, :3] + np.diag(y[:, 0] ** 2)
        self.rejects = 0
        self.ekf.update(
            z,
            HJacobian=lambda _x: np.eye(3, 4),
            Hx=lambda x: x[:3],
            R=r,
            residual=lambda a, b: np.array(
                [[a[0, 0] - b[0, 0]], [a[1, 0] - b[1, 0]], [wrap(a[2, 0] - b[2, 0])]]
            ),
        )
        self.ekf.x[2, 0] = wrap(float(self.ekf.x[2, 0]))
        self._replay(idx, t0, self.ekf.x.copy(), self.ekf.P.copy(), later)
        return True

    def _replay(
        self,
        idx: int,
        t0: int,
        x: np.ndarray,
        p: np.ndarray,
        later: list[tuple[int, np.ndarray, np.ndarray, tuple[float, float]]],
    ) -> None:
        """Set the state at history entry ``idx`` and replay the odometry since then."""
        self.ekf.x, self.ekf.P = x.copy(), p.copy()
        self.ekf.x[2, 0] = wrap(float(self.ekf.x[2, 0]))
        while len(self._hist) > idx + 1:
            self._hist.pop()
        self._hist[idx] = (t0, self.ekf.x.copy(), self.ekf.P.copy(), self._hist[idx][3])
        for t, _, _, (ds, dyaw) in later:
            self.step(t, ds, dyaw)
