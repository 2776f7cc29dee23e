"""Builders of Foxglove well-known messages (protobuf) from trackctl's plain values."""

from __future__ import annotations

import math

from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

__all__ = ["pose_in_frame"]


def pose_in_frame(
    t_ns: int, x_m: float, y_m: float, yaw_rad: float, frame_id: str = "world", z_m: float = 0.0
) -> PoseInFrame:
    """A planar pose (yaw about +z) as a foxglove.PoseInFrame."""
    msg = PoseInFrame(frame_id=frame_id)
    msg.timestamp.FromNanoseconds(int(t_ns))
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x_m, y_m, z_m
    msg.pose.orientation.z = math.sin(yaw_rad / 2.0)
    msg.pose.orientation.w = math.cos(yaw_rad / 2.0)
    return msg
