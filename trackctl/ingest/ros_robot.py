"""Robots in a ROS bag: one robot, one namespace; and their reference trajectories.

A robot's topics rarely share a prefix (a Husky publishes ``/husky_velocity_controller/odom`` and
``/imu/data``), but its frames name it: ``/mustang_base``, ``r1/base_link``. :func:`robot_names`
gives every robot topic (odometry, IMU, pose, GPS) the robot it belongs to, in this order:

1. ``--robot NAME``: every robot topic belongs to NAME;
2. the frames of the first message of each topic: a tf prefix (``r1/base_link`` -> ``r1``) or a
   robot base frame (``mustang_base``, ``husky_base_link`` -> ``mustang``, ``husky``); when the
   frames name one robot, every robot topic belongs to it, when several, each topic to its own;
3. the topics' namespaces, when every robot topic has one and each namespace has an odometry
   (``/r1/odom``, ``/r1/imu``, ``/r2/odom`` -> ``r1``, ``r2``);
4. else one robot, ``robot``.

Each topic keeps a *source* name inside its robot (``/wheel_odometry`` -> ``wheel_odometry``,
``/stereo_odometer/odometry`` -> ``stereo_odometer``); a robot with two odometry sources gets
``/robot/NAME/SOURCE/odom`` for each (``/robot/NAME/odom`` when it has one).

References (what dead reckoning is evaluated against) are written as ``foxglove.PoseInFrame`` on
``/robot/NAME/reference/SOURCE``: the pose of each ``nav_msgs/Odometry`` (the robot's own
integration), ``geometry_msgs/PoseStamped`` and ``PoseWithCovarianceStamped`` (e.g. nav2's
``/amcl_pose``), and ``sensor_msgs/NavSatFix`` converted to a local East-North-Up frame
(:func:`pymap3d.geodetic2enu`) whose origin is the first fix, stated in the log's metadata
``ros/gps/NAME/SOURCE``.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any

from trackctl.logs.messages import Quat, Vec3

__all__ = [
    "ROBOT_ROLES",
    "GeoOrigin",
    "TopicFacts",
    "robot_names",
    "source_name",
    "frame_robot",
    "enu_from_fix",
    "fix_is_valid",
    "pose_in_frame_3d",
]

ROBOT_ROLES = ("odometry", "imu", "pose", "gps")
"""Roles whose topics belong to a robot (``/robot/NAME/...``)."""

DEFAULT_ROBOT = "robot"
_BASE_SUFFIXES = ("_base_footprint", "_base_link", "_base")
_GENERIC_FRAMES = {"base", "base_link", "base_footprint", "odom", "map", "world", "utm", "earth"}
_ROLE_SOURCE = {"odometry": "odom", "imu": "imu", "pose": "pose", "gps": "gps"}


@dataclass(frozen=True, slots=True)
class GeoOrigin:
    """The origin of a GPS topic's local ENU frame: its first valid fix (degrees, metres)."""

    lat_deg: float
    lon_deg: float
    alt_m: float


@dataclass(frozen=True, slots=True)
class TopicFacts:
    """What the first message of a robot topic says about its robot.

    Attributes:
        topic: ROS topic.
        role: Its role (one of :data:`ROBOT_ROLES`).
        frames: Frame ids of its first message (child frame first).
    """

    topic: str
    role: str
    frames: tuple[str, ...] = ()


def frame_robot(frame: str) -> str | None:
    """The robot a frame id names: its tf prefix (``r1/base_link`` -> ``r1``) or the stem of a
    robot base frame (``/mustang_base`` -> ``mustang``); None for a generic frame."""
    parts = [p for p in frame.strip().split("/") if p]
    if not parts:
        return None
    if len(parts) > 1:
        return parts[0] if parts[0] not in _GENERIC_FRAMES else None
    name = parts[0]
    for suffix in _BASE_SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return None


def _namespace(topic: str) -> str | None:
    parts = [p for p in topic.split("/") if p]
    return parts[0] if len(parts) > 1 else None


def _by_namespace(facts: Sequence[TopicFacts]) -> dict[str, str] | None:
    """Each topic's namespace as its robot, when every topic has one and each namespace holds
    an odometry topic; else None."""
    spaces = {f.topic: _namespace(f.topic) for f in facts}
    if not facts or any(s is None for s in spaces.values()):
        return None
    with_odom = {spaces[f.topic] for f in facts if f.role == "odometry"}
    if set(spaces.values()) - with_odom:
        return None
    return {t: s for t, s in spaces.items() if s is not None}


def robot_names(facts: Sequence[TopicFacts], robot: str | None = None) -> dict[str, str]:
    """The robot (NAME) of each robot topic (see the module docstring for the rules)."""
    if robot:
        return {f.topic: robot for f in facts}
    named = {f.topic: next(filter(None, map(frame_robot, f.frames)), None) for f in facts}
    robots = sorted({n for n in named.values() if n})
    if len(robots) == 1:
        return {f.topic: robots[0] for f in facts}
    if robots:
        return {t: n or _fallback(t, robots) for t, n in named.items()}
    spaces = _by_namespace(facts)
    if spaces:
        return spaces
    return {f.topic: DEFAULT_ROBOT for f in facts}


def _fallback(topic: str, robots: Sequence[str]) -> str:
    """A topic without a robot frame among several robots: the one its namespace names, else
    the first."""
    space = _namespace(topic)
    return space if space is not None and space in robots else robots[0]


def source_name(topic: str, role: str, robot: str, generic: Collection[str]) -> str:
    """The name of a topic inside its robot: the topic's meaningful segments without the
    robot's name (``/stereo_odometer/odometry`` -> ``stereo_odometer``, ``/r1/odom`` of r1 ->
    ``odom``)."""
    parts = [p for p in topic.split("/") if p]
    while parts and parts[-1] in generic:
        parts.pop()
    if parts and parts[0] == robot:
        parts = parts[1:]
    return "_".join(parts) or _ROLE_SOURCE.get(role, role)


def fix_is_valid(msg: Any) -> bool:
    """A NavSatFix with a fix (status >= 0) and finite coordinates in range."""
    lat, lon, alt = float(msg.latitude), float(msg.longitude), float(msg.altitude)
    if not all(math.isfinite(v) for v in (lat, lon, alt)):
        return False
    return int(msg.status.status) >= 0 and abs(lat) <= 90.0 and abs(lon) <= 180.0


def enu_from_fix(msg: Any, origin: GeoOrigin) -> tuple[float, float, float]:
    """East, north, up (metres) of a fix from ``origin`` (WGS84, pymap3d)."""
    import pymap3d  # type: ignore[import-untyped]

    e, n, u = pymap3d.geodetic2enu(
        float(msg.latitude),
        float(msg.longitude),
        float(msg.altitude),
        origin.lat_deg,
        origin.lon_deg,
        origin.alt_m,
    )
    return float(e), float(n), float(u)


def pose_in_frame_3d(t_ns: int, position: Vec3, rotation: Quat, frame_id: str) -> Any:
    """A 3-D pose as a foxglove.PoseInFrame."""
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

    msg = PoseInFrame(frame_id=frame_id)
    msg.timestamp.FromNanoseconds(int(t_ns))
    p, q = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = position
    q.x, q.y, q.z, q.w = rotation
    return msg
