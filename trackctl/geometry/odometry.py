"""Differential-drive dead reckoning."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["DiffDrive", "integrate_step", "increment"]


@dataclass(frozen=True, slots=True)
class DiffDrive:
    """Wheel geometry of a differential-drive robot."""

    ticks_per_m: float = 2000.0
    wheel_base_m: float = 0.30

    def __post_init__(self) -> None:
        if self.ticks_per_m <= 0 or self.wheel_base_m <= 0:
            raise ValueError(
                f"DiffDrive needs positive ticks_per_m and wheel_base_m, got "
                f"{self.ticks_per_m} and {self.wheel_base_m}"
            )

    def motion_from_ticks(self, d_left: int, d_right: int) -> tuple[float, float]:
        """(distance m, heading change rad) for encoder increments."""
        dl = d_left / self.ticks_per_m
        dr = d_right / self.ticks_per_m
        return (dl + dr) / 2.0, (dr - dl) / self.wheel_base_m


def integrate_step(
    x: float, y: float, yaw: float, ds: float, dyaw: float
) -> tuple[float, float, float]:
    """Advance a planar pose by a distance along the mid-step heading (second-order accurate)."""
    mid = yaw + dyaw / 2.0
    return x + ds * math.cos(mid), y + ds * math.sin(mid), yaw + dyaw


def increment(
    last: Any, now: Any, drive: DiffDrive, prefer_ticks: bool = True
) -> tuple[float, float] | None:
    """(distance m, heading change rad) between two odometry samples (``WheelOdometry``-like):
    from encoder ticks when both have them, else the velocities of ``last`` held until ``now``
    (what ``nav_msgs/Odometry`` twist gives); None when the samples have nothing in common
    (ticks in one, velocities in neither)."""
    ticks = last.left_ticks is not None and now.left_ticks is not None
    ticks = ticks and last.right_ticks is not None and now.right_ticks is not None
    vel = last.v_mps is not None and last.omega_rps is not None
    if ticks and (prefer_ticks or not vel):
        return drive.motion_from_ticks(
            now.left_ticks - last.left_ticks, now.right_ticks - last.right_ticks
        )
    if vel:
        dt = (now.t_ns - last.t_ns) / 1e9
        return last.v_mps * dt, last.omega_rps * dt
    return None
