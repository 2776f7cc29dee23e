"""The dead-reckoning filter both robot systems share (S-Mirror, BridgeLoc).

filterpy's :class:`~filterpy.kalman.ExtendedKalmanFilter` over (x, y, yaw, b): b is the heading
bias per metre of travel (rad/m) that opposite wheel scale errors cause (left wheel +e, right -e:
b = 2e / wheel base). Uncalibrated differential-drive platforms show 1-2 % scale errors
(Borenstein & Feng, UMBmark, 1996): about 0.1 rad per metre on a 0.30 m wheel base, far more than
random encoder noise, so the filter learns b from its fixes instead of treating it as noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

__all__ = ["OdometryNoise", "DiffDriveEkf", "wrap", "nis"]


def wrap(a: float) -> float:
    """Angle in (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))


@dataclass(frozen=True, slots=True)
class OdometryNoise:
    """Noise of wheel odometry increments."""

    rel_sigma: float = 0.03
    """Relative error of a distance increment (wheel radius, slip)."""
    yaw_per_m_sigma: float = 0.03
    """Heading random walk per metre travelled (rad/sqrt(m)): uneven floor, slip."""
    yaw_rel_sigma: float = 0.05
    """Relative error of a heading increment (encoder quantization and timing in fast turns)."""
    yaw_per_rad_sigma: float = 0.06
    """Heading random walk per radian turned (rad/sqrt(rad)): the effective wheel base is a few
    percent off and tyres scrub differently in every turn (UMBmark), so a 90° turn errs by
    ~5 % (0.075 rad). A random walk in the angle turned keeps that figure whatever the
    odometry rate; a relative error per increment alone would shrink with the square root of
    the number of increments in a turn."""
    heading_bias_sigma: float = 0.1
    """Prior std of the heading bias per metre (rad/m): +-1.5 % opposite wheel-scale errors on a
    0.30 m wheel base (UMBmark: 1-2 % on uncalibrated platforms)."""
    heading_bias_walk: float = 0.002
    """Random walk of that bias per metre (rad/m per sqrt(m)): load, floor, tyre wear."""


class DiffDriveEkf(ExtendedKalmanFilter):  # type: ignore[misc]  # filterpy has no types
    """filterpy's EKF with the unicycle motion (heading bias included) as its state prediction."""

    x: np.ndarray

    def __init__(self, dim_z: int = 3) -> None:
        super().__init__(dim_x=4, dim_z=dim_z)

    def predict_x(self, u: Any = 0) -> None:
        ds, dyaw = float(u[0]), float(u[1])
        dyaw += float(self.x[3, 0]) * ds
        mid = float(self.x[2, 0]) + dyaw / 2
        self.x = self.x + np.array([[ds * math.cos(mid)], [ds * math.sin(mid)], [dyaw], [0.0]])
        self.x[2, 0] = wrap(float(self.x[2, 0]))

    def predict_odometry(self, ds: float, dyaw: float, noise: OdometryNoise) -> None:
        """One odometry increment (distance m, heading change rad) with its Jacobian and noise."""
        yaw = float(self.x[2, 0]) + (dyaw + float(self.x[3, 0]) * ds) / 2
        c, s = math.cos(yaw), math.sin(yaw)
        h = 0.5 * ds  # d(mid yaw)/d(b) = ds / 2
        self.F = np.array(
            [
                [1, 0, -ds * s, -ds * s * h],
                [0, 1, ds * c, ds * c * h],
                [0, 0, 1.0, ds],
                [0, 0, 0, 1.0],
            ]
        )
        # noise enters through the increments: Q = G diag(var_ds, var_dyaw) G^T, plus the
        # bias's random walk
        g = np.array([[c, -0.5 * ds * s], [s, 0.5 * ds * c], [0, 1.0], [0, 0]])
        var_ds = (noise.rel_sigma * ds) ** 2 + 1e-8
        var_dyaw = (
            (noise.yaw_rel_sigma * dyaw) ** 2
            + noise.yaw_per_rad_sigma**2 * abs(dyaw)
            + noise.yaw_per_m_sigma**2 * abs(ds)
            + 1e-8
        )
        q = g @ np.diag([var_ds, var_dyaw]) @ g.T
        q[3, 3] += noise.heading_bias_walk**2 * abs(ds) + 1e-12
        self.Q = q
        self.predict(u=np.array([ds, dyaw]))


def nis(innovation: np.ndarray, s: np.ndarray) -> float:
    """Normalized innovation squared y^T S^-1 y (chi-square with len(y) dof when consistent)."""
    y = np.asarray(innovation, float).reshape(-1, 1)
    try:
        d2 = float((y.T @ np.linalg.solve(s, y))[0, 0])
    except np.linalg.LinAlgError:
        return math.inf
    return d2 if math.isfinite(d2) and d2 >= 0 else math.inf
