"""Odometry increments from encoder ticks or from velocities (ROS twist)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from trackctl.geometry.odometry import DiffDrive, increment
from trackctl.logs.messages import WheelOdometry

DRIVE = DiffDrive(ticks_per_m=1000, wheel_base_m=0.5)


def test_ticks_first_then_velocities() -> None:
    a = WheelOdometry(0, "r", 0, 0, v_mps=1.0, omega_rps=0.5)
    b = WheelOdometry(100_000_000, "r", 100, 300, v_mps=1.0, omega_rps=0.5)
    assert increment(a, b, DRIVE) == pytest.approx((0.2, 0.4))
    assert increment(a, b, DRIVE, prefer_ticks=False) == pytest.approx((0.1, 0.05))
    ticks_only = WheelOdometry(0, "r", 0, 0)
    assert increment(ticks_only, WheelOdometry(1, "r", v_mps=1.0, omega_rps=0.0), DRIVE) is None


@given(st.floats(-2, 2), st.floats(-3, 3), st.integers(1, 10**9))
def test_velocities_are_held_over_the_interval(v: float, w: float, dt_ns: int) -> None:
    a = WheelOdometry(0, "r", v_mps=v, omega_rps=w)
    b = WheelOdometry(dt_ns, "r", v_mps=0.0, omega_rps=0.0)
    assert increment(a, b, DRIVE) == pytest.approx((v * dt_ns / 1e9, w * dt_ns / 1e9))
