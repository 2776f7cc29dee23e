"""Planar dead reckoning: differential-drive ticks, the planar twist, or the robot's own poses.

Motion between two odometry samples is a body-frame increment ``(forward m, left m, heading
change rad)``: from encoder ticks (no sideways motion), from the twist held over the interval
(``v_mps``, ``vy_mps``, ``omega_rps``: the whole planar twist of ``nav_msgs/Odometry``), or from
the robot's own poses (the SE(2) step from one to the next, :func:`pose_increment`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = [
    "DiffDrive",
    "integrate_step",
    "increment",
    "planar_increment",
    "pose_increment",
    "compose",
    "wrap_angle",
]


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


def planar_increment(
    last: Any, now: Any, drive: DiffDrive, prefer_ticks: bool = True
) -> tuple[float, float, float] | None:
    """(forward m, left m, heading change rad) between two odometry samples from ticks or the
    whole planar twist of ``last`` held until ``now`` (x, y and yaw rate; a missing lateral
    speed counts as 0); None when the samples have nothing in common."""
    step = increment(last, now, drive, prefer_ticks)
    if step is None:
        return None
    ds, dyaw = step
    vy = getattr(last, "vy_mps", None)
    ticks = last.left_ticks is not None and now.left_ticks is not None
    if vy is None or (ticks and (prefer_ticks or last.v_mps is None)):
        return ds, 0.0, dyaw
    return ds, vy * (now.t_ns - last.t_ns) / 1e9, dyaw


def wrap_angle(a: float) -> float:
    """An angle in [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def pose_increment(a: Any, b: Any) -> tuple[float, float, float]:
    """The SE(2) step from pose ``a`` to pose ``b`` (``Pose2D``-like) in ``a``'s frame:
    (forward m, left m, heading change rad)."""
    c, s = math.cos(a.yaw_rad), math.sin(a.yaw_rad)
    dx, dy = b.x_m - a.x_m, b.y_m - a.y_m
    return c * dx + s * dy, -s * dx + c * dy, wrap_angle(b.yaw_rad - a.yaw_rad)


def compose(
    x: float, y: float, yaw: float, step: tuple[float, float, float], mid: bool = True
) -> tuple[float, float, float]:
    """Advance a planar pose by a body-frame step; ``mid``: the step is rotated by the
    mid-step heading (a twist or ticks held over the interval, second-order accurate), else by
    the start heading (an exact SE(2) step between two poses)."""
    fwd, left, dyaw = step
    heading = yaw + dyaw / 2.0 if mid else yaw
    c, s = math.cos(heading), math.sin(heading)
    return x + c * fwd - s * left, y + s * fwd + c * left, yaw + dyaw
