"""Continuous localization (dissertation §4.2.3 C, Eqs. 4.10-4.12): an EKF over the robot pose
r_t = (x, y, θ) with odometry as control and range-bearing tag observations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from trackctl.geometry.odometry import integrate_step

__all__ = ["EkfConfig", "RobotEkf", "wrap"]


def wrap(a: float) -> float:
    """Angle in (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))


@dataclass(frozen=True, slots=True)
class EkfConfig:
    """Noise model of the EKF."""

    odom_dist_frac: float = 0.03
    """Std of travelled distance per step, as a fraction of it."""
    odom_yaw_frac: float = 0.03
    odom_yaw_floor_rad: float = 0.002
    odom_dist_floor_m: float = 0.001
    range_sigma_frac: float = 0.06
    """Std of a tag's measured range, fraction of the range (+ 3 cm)."""
    bearing_sigma_rad: float = 0.04
    fix_sigma_m: float = 0.12
    """Std of an absolute position fix (I-Cam)."""
    bridge_sigma_m: float = 0.15
    bridge_yaw_sigma_rad: float = 0.08
    gate_m: float = 1.2
    """A tag observation whose observed position (Eq. 4.11) is farther than this from every
    candidate is ignored."""


class _Ekf(ExtendedKalmanFilter):
    """filterpy's EKF with the nonlinear diff-drive motion as its state prediction."""

    x: np.ndarray

    def predict_x(self, u: Any = 0) -> None:
        ds, dyaw = float(u[0]), float(u[1])
        x, y, th = integrate_step(
            float(self.x[0, 0]), float(self.x[1, 0]), float(self.x[2, 0]), ds, dyaw
        )
        self.x = np.array([[x], [y], [wrap(th)]])


def _res_angle(idx: int):  # noqa: ANN202
    def residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        y = a - b
        y[idx, 0] = wrap(float(y[idx, 0]))
        return y

    return residual


class RobotEkf:
    """EKF of Eqs. 4.10-4.12 with odometry control and range-bearing / position observations."""

    def __init__(self, config: EkfConfig | None = None) -> None:
        self.cfg = config or EkfConfig()
        self.kf = _Ekf(dim_x=3, dim_z=2)
        self.initialized = False

    def init(self, x: float, y: float, yaw: float, sigma_m: float, sigma_yaw: float) -> None:
        self.kf.x = np.array([[x], [y], [wrap(yaw)]])
        self.kf.P = np.diag([sigma_m**2, sigma_m**2, sigma_yaw**2])
        self.initialized = True

    @property
    def pose(self) -> tuple[float, float, float]:
        x = self.kf.x
        return float(x[0, 0]), float(x[1, 0]), float(x[2, 0])

    @property
    def sigma_m(self) -> float:
        """Largest position standard deviation (m)."""
        return float(math.sqrt(max(np.linalg.eigvalsh(self.kf.P[:2, :2]).max(), 0.0)))

    def predict(self, ds: float, dyaw: float) -> None:
        """Control c_t from the wheel encoders: g(r, c) = integrate_step (mid-point heading)."""
        if not self.initialized:
            return
        c = self.cfg
        th = float(self.kf.x[2, 0]) + dyaw / 2
        self.kf.F = np.array([[1, 0, -ds * math.sin(th)], [0, 1, ds * math.cos(th)], [0, 0, 1]])
        v = np.array(
            [[math.cos(th), -ds * math.sin(th) / 2], [math.sin(th), ds * math.cos(th) / 2], [0, 1]]
        )
        m = np.diag(
            [
                (c.odom_dist_frac * abs(ds) + c.odom_dist_floor_m) ** 2,
                (c.odom_yaw_frac * abs(dyaw) + c.odom_yaw_floor_rad + 0.01 * abs(ds)) ** 2,
            ]
        )
        self.kf.Q = v @ m @ v.T
        self.kf.predict(u=np.array([ds, dyaw]))

    def observed_position(self, rng_m: float, bearing: float) -> np.ndarray:
        """Eq. 4.11: where the observed tag is, given the current pose."""
        x, y, th = self.pose
        return np.array([x + rng_m * math.cos(bearing + th), y + rng_m * math.sin(bearing + th)])

    def update_range_bearing(self, rng_m: float, bearing: float, tag_xy: np.ndarray) -> None:
        """Eq. 4.12: h(r) = (range, bearing) to the chosen tag (x_m, y_m)."""
        c = self.cfg
        xm, ym = float(tag_xy[0]), float(tag_xy[1])

        def hx(x: np.ndarray) -> np.ndarray:
            dx, dy = xm - x[0, 0], ym - x[1, 0]
            return np.array([[math.hypot(dx, dy)], [wrap(math.atan2(dy, dx) - x[2, 0])]])

        def hjac(x: np.ndarray) -> np.ndarray:
            dx, dy = xm - x[0, 0], ym - x[1, 0]
            q = max(dx * dx + dy * dy, 1e-6)
            r = math.sqrt(q)
            return np.array([[-dx / r, -dy / r, 0.0], [dy / q, -dx / q, -1.0]])

        r_mat = np.diag([(c.range_sigma_frac * rng_m + 0.03) ** 2, c.bearing_sigma_rad**2])
        z = np.array([rng_m, bearing])[:, None]  # filterpy 2.0: column vectors
        self.kf.update(z, hjac, hx, R=r_mat, residual=_res_angle(1))
        self.kf.x[2, 0] = wrap(float(self.kf.x[2, 0]))

    def update_pose(
        self, x: float, y: float, yaw: float | None, sigma_m: float, sigma_yaw: float
    ) -> None:
        """An absolute fix: position (I-Cam) or position + heading (bridging)."""
        if not self.initialized:
            self.init(
                x, y, 0.0 if yaw is None else yaw, sigma_m, math.pi if yaw is None else sigma_yaw
            )
            return
        if yaw is None:
            h = np.array([[1.0, 0, 0], [0, 1.0, 0]])
            z = np.array([x, y])[:, None]
            r_mat = np.eye(2) * sigma_m**2
            self.kf.update(z, lambda _x: h, lambda s: h @ s, R=r_mat)
        else:
            h = np.eye(3)
            z = np.array([x, y, yaw])[:, None]
            r_mat = np.diag([sigma_m**2, sigma_m**2, sigma_yaw**2])
            self.kf.update(z, lambda _x: h, lambda s: h @ s, R=r_mat, residual=_res_angle(2))
        self.kf.x[2, 0] = wrap(float(self.kf.x[2, 0]))
