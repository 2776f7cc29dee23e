"""The shared dead-reckoning filter: its turn noise does not depend on the odometry rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackctl.geometry.odometry_ekf import DiffDriveEkf, OdometryNoise


def _turned(steps: int, noise: OdometryNoise) -> DiffDriveEkf:
    f = DiffDriveEkf()
    f.x = np.zeros((4, 1))
    f.P = np.diag([1e-6, 1e-6, 1e-6, 1e-12])
    for _ in range(steps):
        f.predict_odometry(0.0, (math.pi / 2) / steps, noise)
    return f


def test_a_turn_errs_by_the_same_amount_at_any_odometry_rate() -> None:
    noise = OdometryNoise()
    slow, fast = _turned(10, noise), _turned(400, noise)
    assert fast.x[2, 0] == pytest.approx(math.pi / 2)
    # the per-radian random walk dominates: 10 or 400 increments, nearly the same heading std
    assert math.sqrt(fast.P[2, 2]) == pytest.approx(math.sqrt(slow.P[2, 2]), rel=0.2)
    expected = noise.yaw_per_rad_sigma * math.sqrt(math.pi / 2)
    assert math.sqrt(fast.P[2, 2]) == pytest.approx(expected, rel=0.1)
