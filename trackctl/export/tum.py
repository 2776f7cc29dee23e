"""TUM trajectory export of a pose topic (what evo reads).

One line per pose: ``timestamp x y z qx qy qz qw``, the timestamp in seconds of log time with 9
decimals (exact nanoseconds), the position in metres, the orientation as a unit quaternion; a
planar pose (yaw only) is a rotation about +z. Pose topics: ``foxglove.PoseInFrame`` (dead
reckoning ``/robot/<R>/dead_reckoning``, ``/smirror/<R>/pose``, ``/bridgeloc/pose``) and
``trackctl.GroundTruth`` (``/ground_truth``: one entity chosen by name; an entity without a yaw
gets the identity rotation).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from typing import IO, Any

from trackctl.errors import InputError
from trackctl.logs.messages import GroundTruth
from trackctl.logs.reader import LogMessage, LogReader
from trackctl.progress import Progress

__all__ = ["SCHEMAS", "POSE_IN_FRAME", "entity_names", "pick_robot", "write_tum", "tum_time"]

POSE_IN_FRAME = "foxglove.PoseInFrame"
SCHEMAS = (POSE_IN_FRAME, GroundTruth.SCHEMA)
"""The schemas a TUM export takes."""

Pose = tuple[float, float, float, float, float, float, float]


def tum_time(t_ns: int) -> str:
    """Nanoseconds as seconds with 9 decimals, exactly (no float rounding)."""
    sign = "-" if t_ns < 0 else ""
    sec, nsec = divmod(abs(int(t_ns)), 1_000_000_000)
    return f"{sign}{sec}.{nsec:09d}"


def entity_names(reader: LogReader, topic: str) -> list[str]:
    """Every entity id on a GroundTruth topic, in order of first appearance."""
    names: dict[str, None] = {}
    for msg in reader.messages([topic]):
        if isinstance(msg.message, GroundTruth):
            names.update((e.entity_id, None) for e in msg.message.entities)
    return list(names)


def pick_robot(reader: LogReader, topic: str, robot: str | None) -> str:
    """The entity of a GroundTruth topic to export: ``robot``, or the only one there is.

    Raises:
        InputError: the topic holds several entities and none was chosen, or not the one chosen.
    """
    names = entity_names(reader, topic)
    if robot is not None and robot in names:
        return robot
    listed = ", ".join(names) or "none"
    if robot is not None:
        raise InputError(
            f"{reader.path}: {topic} holds no pose of --robot {robot}; it has: {listed}"
        )
    if len(names) == 1:
        return names[0]
    raise InputError(
        f"{reader.path}: {topic} holds the poses of {len(names)} entities: choose one with "
        f"--robot NAME ({listed})"
    )


def _yaw_quat(yaw_rad: float | None) -> tuple[float, float, float, float]:
    if yaw_rad is None:
        return 0.0, 0.0, 0.0, 1.0
    return 0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0)


def _poses(message: Any, robot: str | None) -> Iterator[Pose]:
    """The pose(s) of one message (a PoseInFrame, or the chosen entity of a GroundTruth)."""
    if isinstance(message, GroundTruth):
        for e in message.entities:
            if e.entity_id == robot:
                p = e.position_m
                yield (p.x, p.y, p.z, *_yaw_quat(e.yaw_rad))
        return
    pose = getattr(message, "pose", None)
    if pose is not None:
        p, q = pose.position, pose.orientation
        yield (p.x, p.y, p.z, q.x, q.y, q.z, q.w)


def write_tum(
    messages: Iterable[LogMessage],
    out: IO[str],
    robot: str | None = None,
    progress: Progress | None = None,
    total: int | None = None,
) -> tuple[int, int]:
    """Write the TUM lines of ``messages`` (one topic, log-time order) to ``out``.

    Returns:
        ``(messages, lines)`` read and written.
    """
    count = lines = 0
    for msg in messages:
        count += 1
        for x, y, z, qx, qy, qz, qw in _poses(msg.message, robot):
            out.write(
                f"{tum_time(msg.log_time_ns)} {x:.6f} {y:.6f} {z:.6f} "
                f"{qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}\n"
            )
            lines += 1
        if progress is not None:
            progress(count, total, "exporting")
    return count, lines
