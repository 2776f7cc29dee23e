"""ROS bags (ROS 1 ``.bag`` and ROS 2 rosbag2) into trackctl logs: topics mapped by message
type, messages converted.

A robot records a ROS 1 bag or a rosbag2 (a directory with ``metadata.yaml`` and MCAP or sqlite3
``.db3`` files, or a bare ``.mcap``); `rosbags <https://gitlab.com/ternaris/rosbags>`_ reads every
form without a ROS installation. :func:`plan_ros2` maps each ROS topic to a *role* by its message
type; camera NAMEs come from the topic's namespace, robot NAMEs from the frames and namespaces
(:mod:`trackctl.ingest.ros_robot`: one robot, one namespace; ``--robot NAME`` overrides);
``--map ROS_TOPIC=ROLE:NAME`` overrides one topic (or ``ROS_TOPIC=ignore``). ROS 1 type names
(``nav_msgs/Odometry``) are read as their ROS 2 twins (``nav_msgs/msg/Odometry``):

=============== ======================================== =========================================
role            ROS type                                 trackctl topic(s)
=============== ======================================== =========================================
``odometry``    ``nav_msgs/msg/Odometry``                ``/robot/NAME/odom`` (v, lateral v, omega
                                                         and the 2-D pose; ``/robot/NAME/SOURCE/
                                                         odom`` when a robot has several) and
                                                         ``/robot/NAME/reference/SOURCE`` (its pose)
``imu``         ``sensor_msgs/msg/Imu``                  ``/robot/NAME/imu`` (``/robot/NAME/SOURCE/
                                                         imu`` when a robot has several)
``pose``        ``geometry_msgs/msg/PoseStamped``,       ``/robot/NAME/reference/SOURCE``
                ``geometry_msgs/msg/PoseWithCovariance`` (foxglove.PoseInFrame)
                ``Stamped``
``gps``         ``sensor_msgs/msg/NavSatFix``            ``/robot/NAME/gps`` (foxglove.LocationFix)
                                                         and ``/robot/NAME/reference/SOURCE``
                                                         (local ENU metres from the first fix)
``image``       ``sensor_msgs/msg/CompressedImage``,     ``/NAME/image`` (foxglove.CompressedImage;
                ``sensor_msgs/msg/Image``                raw images are PNG-encoded, lossless)
``camera_info`` ``sensor_msgs/msg/CameraInfo``           ``/NAME/calibration``,
                                                         ``/NAME/camera_model`` (pose from
                                                         ``/tf_static`` when it chains to the world)
``tf``          ``tf2_msgs/msg/TFMessage``               ``/tf``, ``/tf_static`` (foxglove
                                                         FrameTransforms)
=============== ======================================== =========================================

Each message keeps its header stamp as its time field (``t_ns``, the image timestamp); the log
time is the bag's receive time, so the merged log stays in the bag's order.

A message that cannot be used (NaN or infinite values, a zero quaternion, an image shorter than
``height*step``, a topic whose schema is not what its type says, undecodable bytes) is skipped
and counted; each topic with skipped messages gives one warning naming the bag, the topic and the
field. A bag damaged further in (a forged record length, a damaged chunk) is read up to the damage,
with a warning; a bag that does not open at all is an :class:`~trackctl.errors.InputError`.
"""

from __future__ import annotations

import math
import sqlite3
import warnings
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from trackctl.errors import IncompleteInputWarning, InputError
from trackctl.ingest.ros_robot import (
    ROBOT_ROLES,
    GeoOrigin,
    TopicFacts,
    enu_from_fix,
    fix_is_valid,
    pose_in_frame_3d,
    robot_names,
    source_name,
)
from trackctl.logs import topics
from trackctl.logs.messages import CameraModel, Imu, Pose2D, Quat, Transform, Vec3, WheelOdometry

__all__ = [
    "ROLES",
    "AUTO_ROLES",
    "TopicPlan",
    "parse_maps",
    "plan_ros2",
    "read_ros2",
    "ros_metadata",
    "WORLD_FRAMES",
]

ROLES = ("odometry", "imu", "pose", "gps", "image", "camera_info", "tf", "ignore")
AUTO_ROLES: dict[str, str] = {
    "nav_msgs/msg/Odometry": "odometry",
    "sensor_msgs/msg/Imu": "imu",
    "geometry_msgs/msg/PoseStamped": "pose",
    "geometry_msgs/msg/PoseWithCovarianceStamped": "pose",
    "sensor_msgs/msg/NavSatFix": "gps",
    "sensor_msgs/msg/CompressedImage": "image",
    "sensor_msgs/msg/Image": "image",
    "sensor_msgs/msg/CameraInfo": "camera_info",
    "tf2_msgs/msg/TFMessage": "tf",
}
_ACCEPTS: dict[str, tuple[str, ...]] = {}
for _type, _role in AUTO_ROLES.items():
    _ACCEPTS[_role] = (*_ACCEPTS.get(_role, ()), _type)

WORLD_FRAMES = ("world", "map")
"""Root frames a camera's tf chain may end in to give it a world pose (the first one found)."""

# trailing topic segments that name the data, not the device (``/cam0/image_raw/compressed``)
_GENERIC = {
    "compressed",
    "image_raw",
    "image_rect",
    "image_rect_color",
    "image_color",
    "image_mono",
    "image",
    "color",
    "rgb",
    "camera_info",
    "odom",
    "odometry",
    "wheel_odom",
    "filtered",
    "imu",
    "imu_data",
    "data",
    "data_raw",
    "fix",
    "pose",
}
_DEFAULT_NAME = {"odometry": "robot", "imu": "robot", "image": "camera", "camera_info": "camera"}


@dataclass(frozen=True, slots=True)
class TopicPlan:
    """What becomes of one ROS topic."""

    ros_topic: str
    ros_type: str
    count: int
    role: str
    name: str
    """Camera NAME, or the robot NAME of a robot topic."""
    why: str
    """``auto`` (by message type), ``--map``, ``--robot``, or why it is ignored."""
    source: str = ""
    """A robot topic's name inside its robot (``wheel_odometry``; its reference topic)."""
    alone: bool = True
    """The robot's only topic of its role (``/robot/NAME/odom`` rather than ``.../SOURCE/odom``)."""
    origin: GeoOrigin | None = None
    """A GPS topic's ENU origin (its first valid fix)."""

    def _robot_topic(self, leaf: str) -> str:
        middle = "" if self.alone else f"{self.source}/"
        return f"/robot/{self.name}/{middle}{leaf}"

    @property
    def reference(self) -> str:
        """The reference trajectory topic of a robot topic (``/robot/NAME/reference/SOURCE``)."""
        return f"/robot/{self.name}/reference/{self.source or self.role}"

    @property
    def targets(self) -> tuple[str, ...]:
        """The trackctl topics it is written to."""
        if self.role == "odometry":
            return (self._robot_topic("odom"), self.reference)
        if self.role == "imu":
            return (self._robot_topic("imu"),)
        if self.role == "pose":
            return (self.reference,)
        if self.role == "gps":
            return (self._robot_topic("gps"), self.reference)
        if self.role == "image":
            return (topics.image(self.name),)
        if self.role == "camera_info":
            return (topics.calibration(self.name), topics.camera_model(self.name))
        if self.role == "tf":
            return (topics.TF_STATIC if self.ros_topic.endswith("tf_static") else topics.TF,)
        return ()


def parse_maps(values: Sequence[str]) -> dict[str, tuple[str, str]]:
    """``--map ROS_TOPIC=ROLE:NAME`` (or ``ROS_TOPIC=ignore``) values.

    Raises:
        InputError: a malformed value, an unknown role, or a topic mapped twice.
    """
    out: dict[str, tuple[str, str]] = {}
    for value in values:
        topic, sep, rest = value.partition("=")
        role, _, name = rest.partition(":")
        if not sep or not topic.startswith("/") or not role:
            raise InputError(
                f"--map {value!r}: expected ROS_TOPIC=ROLE:NAME, e.g. --map /odom=odometry:r1"
            )
        if role not in ROLES:
            raise InputError(f"--map {value!r}: role {role!r} is not one of {', '.join(ROLES)}")
        if role not in ("ignore", "tf") and (not name or "/" in name or " " in name):
            raise InputError(f"--map {value!r}: NAME is required and must not contain '/'")
        if topic in out:
            raise InputError(f"--map: topic {topic} is mapped twice")
        out[topic] = (role, name)
    return out


def _name_from_topic(topic: str, role: str) -> str:
    parts = [p for p in topic.split("/") if p]
    while parts and parts[-1] in _GENERIC:
        parts.pop()
    return "_".join(parts) or _DEFAULT_NAME.get(role, "robot")


def _open(bag: Path) -> Any:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if not bag.exists():
        raise InputError(f"--ros {bag}: no such file or directory")
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as err:  # rosbags raises its own ReaderError / AnyReaderError, zstd errors
        raise InputError(f"--ros {bag}: not a readable ROS bag ({err})") from err
    return reader


def _first_frames(reader: Any, conns: Sequence[Any]) -> tuple[str, ...]:
    """Frame ids of a topic's first message (child frame first); none when it does not
    decode: the read proper counts and warns about it."""
    try:
        for conn, _, raw in reader.messages(connections=list(conns)):
            msg = reader.deserialize(raw, conn.msgtype)
            child = str(getattr(msg, "child_frame_id", "") or "")
            return tuple(f for f in (child, str(msg.header.frame_id)) if f)
    except Exception:  # noqa: BLE001 - a damaged first message only costs the name hint
        return ()
    return ()


def _first_fix(reader: Any, conns: Sequence[Any]) -> GeoOrigin | None:
    """The first valid fix of a NavSatFix topic (its ENU origin)."""
    try:
        for conn, _, raw in reader.messages(connections=list(conns)):
            msg = reader.deserialize(raw, conn.msgtype)
            if fix_is_valid(msg):
                return GeoOrigin(float(msg.latitude), float(msg.longitude), float(msg.altitude))
    except Exception:  # noqa: BLE001 - a damaged bag: the read proper warns
        return None
    return None


@dataclass(frozen=True, slots=True)
class _BagTopics:
    """The topics of a bag: type, message count, and the facts naming its robots."""

    types: dict[str, str]
    counts: Counter[str]
    facts: dict[str, TopicFacts]
    origins: dict[str, GeoOrigin | None]


def _survey(bag: Path, roles: Mapping[str, str]) -> _BagTopics:
    """Types and counts of every topic; the first frames of each robot topic and the first fix
    of each GPS topic (``roles``: topic -> role)."""
    reader = _open(bag)
    try:
        counts: Counter[str] = Counter()
        types: dict[str, str] = {}
        by_topic: dict[str, list[Any]] = {}
        for c in sorted(reader.connections, key=lambda c: c.topic):
            counts[c.topic] += c.msgcount
            types[c.topic] = c.msgtype
            by_topic.setdefault(c.topic, []).append(c)
        facts: dict[str, TopicFacts] = {}
        origins: dict[str, GeoOrigin | None] = {}
        for topic, conns in by_topic.items():
            role = roles.get(topic) or AUTO_ROLES.get(types[topic], "ignore")
            if role in ROBOT_ROLES:
                facts[topic] = TopicFacts(topic, role, _first_frames(reader, conns))
            if role == "gps":
                origins[topic] = _first_fix(reader, conns)
    finally:
        reader.close()
    return _BagTopics(types, counts, facts, origins)


def _role_of(
    topic: str, ros_type: str, maps: Mapping[str, tuple[str, str]]
) -> tuple[str, str, str]:
    """(role, NAME or "", why) of one topic.

    Raises:
        InputError: a ``--map`` role its type cannot fill.
    """
    if topic in maps:
        role, name = maps[topic]
        if role not in ("ignore",) and ros_type not in _ACCEPTS.get(role, ()):
            raise InputError(
                f"--map {topic}={role}:{name}: {topic} is {ros_type}; role {role} takes "
                f"{' or '.join(_ACCEPTS.get(role, ()))}"
            )
        return role, name, "--map"
    if ros_type in AUTO_ROLES:
        return AUTO_ROLES[ros_type], "", "auto"
    return "ignore", "", f"no role for {ros_type}"


def plan_ros2(
    bag: Path, maps: Mapping[str, tuple[str, str]] | None = None, robot: str | None = None
) -> list[TopicPlan]:
    """Each topic of ``bag`` with its role and trackctl NAME (automatic unless mapped; every
    robot topic belongs to ``robot`` when given).

    Raises:
        InputError: the bag does not open, a ``--map`` names a topic the bag lacks or a role its
            type cannot fill, ``robot`` is not a valid name, or two topics map to one topic.
    """
    maps = dict(maps or {})
    if robot is not None and (not robot or "/" in robot or " " in robot):
        raise InputError(f"--robot {robot!r}: a NAME without '/' or spaces is required")
    survey = _survey(bag, {t: r for t, (r, _) in maps.items()})
    missing = sorted(set(maps) - set(survey.types))
    if missing:
        raise InputError(
            f"--map {missing[0]}: the bag has no such topic "
            f"(topics: {', '.join(sorted(survey.types))})"
        )
    roles = {t: _role_of(t, ros_type, maps) for t, ros_type in sorted(survey.types.items())}
    auto_robot = [survey.facts[t] for t, (r, n, _) in roles.items() if r in ROBOT_ROLES and not n]
    robots = robot_names(auto_robot, robot)
    plans = _mark_shared(
        [_plan(t, role, name, why, survey, robots, robot) for t, (role, name, why) in roles.items()]
    )
    _check_unique(bag, plans)
    return plans


def _plan(
    topic: str,
    role: str,
    name: str,
    why: str,
    survey: _BagTopics,
    robots: Mapping[str, str],
    robot: str | None,
) -> TopicPlan:
    """The plan of one topic: its NAME (the robot of a robot topic) and source."""
    if role in ROBOT_ROLES:
        name = name or robots[topic]
        why = "--robot" if robot and why == "auto" else why
    elif role not in ("ignore", "tf") and not name:
        name = _name_from_topic(topic, role)
    source = source_name(topic, role, name, _GENERIC) if role in ROBOT_ROLES else ""
    return TopicPlan(
        topic,
        survey.types[topic],
        survey.counts[topic],
        role,
        name,
        why,
        source,
        origin=survey.origins.get(topic),
    )


def _mark_shared(plans: list[TopicPlan]) -> list[TopicPlan]:
    """Robot topics that share their robot and role with another: written under their source."""
    from dataclasses import replace

    per: Counter[tuple[str, str]] = Counter(
        (p.name, p.role) for p in plans if p.role in ROBOT_ROLES
    )
    return [
        replace(p, alone=False) if p.role in ROBOT_ROLES and per[(p.name, p.role)] > 1 else p
        for p in plans
    ]


def _check_unique(bag: Path, plans: Sequence[TopicPlan]) -> None:
    """Raises InputError when two topics would write one trackctl topic."""
    seen: dict[str, str] = {}
    for p in plans:
        for target in p.targets:
            if target in seen and p.role != "tf":
                raise InputError(
                    f"--ros {bag}: {seen[target]} and {p.ros_topic} both map to {target}; "
                    f"name one with --map {p.ros_topic}={p.role}:OTHER"
                )
            seen[target] = p.ros_topic


def ros_metadata(plans: Sequence[TopicPlan]) -> dict[str, dict[str, str]]:
    """Metadata records of a conversion: what became of each converted ROS topic
    (``ros/topic/<ROS topic>``: type, role, robot or camera, trackctl topics) and the ENU origin
    of each GPS topic (``ros/gps/NAME/SOURCE``)."""
    out: dict[str, dict[str, str]] = {}
    for p in plans:
        if p.targets:
            out[f"ros/topic{p.ros_topic}"] = {
                "ros_topic": p.ros_topic,
                "type": p.ros_type,
                "role": p.role,
                "name": p.name,
                "targets": ",".join(p.targets),
            }
        if p.role == "gps" and p.origin is not None:
            out[f"ros/gps/{p.name}/{p.source}"] = {
                "ros_topic": p.ros_topic,
                "reference_topic": p.reference,
                "frame_id": f"{p.name}/enu",
                "origin_lat_deg": repr(p.origin.lat_deg),
                "origin_lon_deg": repr(p.origin.lon_deg),
                "origin_alt_m": repr(p.origin.alt_m),
                "origin": "first valid fix (WGS84), East-North-Up metres",
            }
    return out


# -- conversions ----------------------------------------------------------------------------------


class _Skip(Exception):
    """A message that cannot be used: the field at fault and why."""

    def __init__(self, field_name: str, why: str) -> None:
        super().__init__(f"{field_name}: {why}")
        self.field_name = field_name
        self.why = why


def _finite(values: Mapping[str, float | None]) -> None:
    """Raises _Skip naming the first NaN or infinite value."""
    for key, value in values.items():
        if value is not None and not math.isfinite(value):
            raise _Skip(key, f"{value} is not a finite number")


def _stamp(header: Any, fallback: int) -> int:
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns > 0 else fallback


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _quat_of(q: Any, where: str) -> Quat | None:
    """A ROS quaternion, normalised; None when it is all zeros (no orientation given).

    Raises:
        _Skip: a NaN or infinite component.
    """
    quat = Quat(float(q.x), float(q.y), float(q.z), float(q.w))
    _finite({f"{where}.{k}": v for k, v in quat._asdict().items()})
    norm = math.sqrt(sum(v * v for v in quat))
    if norm < 1e-9:
        return None
    return Quat(*(v / norm for v in quat))


def _odometry(msg: Any, plan: TopicPlan, t_ns: int) -> list[tuple[str, Any]]:
    """An Odometry as WheelOdometry (the planar twist and the 2-D pose) and, when it has an
    orientation, its pose as the source's reference."""
    pose, lin, ang = msg.pose.pose, msg.twist.twist.linear, msg.twist.twist.angular
    pos = Vec3(float(pose.position.x), float(pose.position.y), float(pose.position.z))
    twist = {"twist.linear.x": float(lin.x), "twist.linear.y": float(lin.y)}
    _finite({**twist, "twist.angular.z": float(ang.z)})
    _finite({f"pose.position.{k}": v for k, v in pos._asdict().items()})
    quat = _quat_of(pose.orientation, "pose.orientation")
    odo = WheelOdometry(
        t_ns=t_ns,
        frame_id=f"robot/{plan.name}",
        v_mps=float(lin.x),
        vy_mps=float(lin.y),
        omega_rps=float(ang.z),
        pose=None if quat is None else Pose2D(pos.x, pos.y, _yaw(quat)),
    )
    out: list[tuple[str, Any]] = [(plan.targets[0], odo)]
    if quat is not None:
        frame = str(msg.header.frame_id).lstrip("/") or f"{plan.name}/odom"
        out.append((plan.reference, pose_in_frame_3d(t_ns, pos, quat, frame)))
    return out


def _pose(msg: Any, plan: TopicPlan, t_ns: int) -> list[tuple[str, Any]]:
    """A PoseStamped or PoseWithCovarianceStamped as the source's reference."""
    pose = msg.pose.pose if hasattr(msg.pose, "covariance") else msg.pose
    pos = Vec3(float(pose.position.x), float(pose.position.y), float(pose.position.z))
    _finite({f"pose.position.{k}": v for k, v in pos._asdict().items()})
    quat = _quat_of(pose.orientation, "pose.orientation")
    if quat is None:
        raise _Skip("pose.orientation", "zero quaternion")
    frame = str(msg.header.frame_id).lstrip("/") or "map"
    return [(plan.reference, pose_in_frame_3d(t_ns, pos, quat, frame))]


def _gps(msg: Any, plan: TopicPlan, t_ns: int) -> list[tuple[str, Any]]:
    """A NavSatFix as a foxglove.LocationFix and as ENU metres from the topic's first fix
    (no orientation: the reference's is the identity)."""
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix

    if not fix_is_valid(msg):
        raise _Skip("status/latitude/longitude/altitude", "no fix, or not finite, or out of range")
    if plan.origin is None:
        raise _Skip("latitude", "no origin fix")
    fix = LocationFix(
        frame_id=str(msg.header.frame_id) or plan.name,
        latitude=float(msg.latitude),
        longitude=float(msg.longitude),
        altitude=float(msg.altitude),
        position_covariance_type=int(msg.position_covariance_type),  # type: ignore[arg-type]
    )
    fix.position_covariance.extend(float(v) for v in msg.position_covariance)
    fix.timestamp.FromNanoseconds(t_ns)
    enu = Vec3(*enu_from_fix(msg, plan.origin))
    ref = pose_in_frame_3d(t_ns, enu, Quat(0.0, 0.0, 0.0, 1.0), f"{plan.name}/enu")
    return [(plan.targets[0], fix), (plan.reference, ref)]


def _imu(msg: Any, name: str, t_ns: int) -> Imu:
    a, g, q = msg.linear_acceleration, msg.angular_velocity, msg.orientation
    # REP 145: covariance[0] == -1 means the field is not provided
    has_q = float(msg.orientation_covariance[0]) != -1.0
    has_g = float(msg.angular_velocity_covariance[0]) != -1.0
    imu = Imu(
        t_ns=t_ns,
        frame_id=f"robot/{name}",
        accel_mps2=Vec3(float(a.x), float(a.y), float(a.z)),
        gyro_rps=Vec3(float(g.x), float(g.y), float(g.z)) if has_g else None,
        orientation=_quat_of(q, "orientation") if has_q else None,
    )
    _finite(
        {
            k.replace("accel_mps2", "linear_acceleration").replace(
                "gyro_rps", "angular_velocity"
            ): v
            for k, v in imu.finite_values().items()
        }
    )
    return imu


def _compressed(msg: Any, name: str, t_ns: int) -> Any:
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    fmt = str(msg.format).lower()
    out = CompressedImage(
        frame_id=name, data=bytes(msg.data), format="png" if "png" in fmt else "jpeg"
    )
    out.timestamp.FromNanoseconds(t_ns)
    return out


_RAW_CHANNELS = {"mono8": 1, "8uc1": 1, "bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4, "mono16": 1}


def _raw_pixels(msg: Any) -> np.ndarray:
    """The pixels of a raw Image (height x width x channels).

    Raises:
        _Skip: an unsupported encoding, or sizes that do not match the data.
    """
    enc = str(msg.encoding).lower()
    if enc not in _RAW_CHANNELS:
        raise _Skip(
            "encoding",
            f"{msg.encoding!r} is not supported (supported: {', '.join(sorted(_RAW_CHANNELS))})",
        )
    dtype = np.dtype(np.uint16 if enc == "mono16" else np.uint8)
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    row_bytes = width * _RAW_CHANNELS[enc] * dtype.itemsize
    data = bytes(msg.data)
    if height <= 0 or width <= 0 or step < row_bytes or step % dtype.itemsize:
        raise _Skip("step", f"height {height}, width {width}, step {step} do not fit {enc}")
    if len(data) < height * step:
        raise _Skip("data", f"{len(data)} bytes, shorter than height*step = {height * step}")
    rows = np.frombuffer(data[: height * step], dtype=dtype).reshape(height, -1)
    return rows[:, : width * _RAW_CHANNELS[enc]].reshape(height, width, _RAW_CHANNELS[enc])


def _raw(msg: Any, name: str, t_ns: int) -> Any:
    import cv2
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    img: Any = _raw_pixels(msg)
    enc = str(msg.encoding).lower()
    if enc == "rgb8":
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    elif enc == "rgba8":
        img = cv2.cvtColor(img, cv2.COLOR_RGBA2BGRA)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise _Skip("data", "the image does not encode as PNG")
    out = CompressedImage(frame_id=name, data=buf.tobytes(), format="png")
    out.timestamp.FromNanoseconds(t_ns)
    return out


def _link(tf: Any, i: int) -> tuple[Vec3, Quat]:
    """One transform of a TFMessage, checked.

    Raises:
        _Skip: a NaN/infinite value or a zero quaternion.
    """
    tr = tf.transform.translation
    trans = Vec3(float(tr.x), float(tr.y), float(tr.z))
    _finite({f"transforms[{i}].transform.translation.{k}": v for k, v in trans._asdict().items()})
    q = _quat_of(tf.transform.rotation, f"transforms[{i}].transform.rotation")
    if q is None:
        raise _Skip(f"transforms[{i}].transform.rotation", "zero quaternion")
    return trans, q


def _transforms(msg: Any, t_fallback: int) -> Any:
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    out = FrameTransforms()
    for i, tf in enumerate(msg.transforms):
        tr, q = _link(tf, i)
        ft = out.transforms.add()
        ft.timestamp.FromNanoseconds(_stamp(tf.header, t_fallback))
        ft.parent_frame_id = str(tf.header.frame_id)
        ft.child_frame_id = str(tf.child_frame_id)
        ft.translation.x, ft.translation.y, ft.translation.z = tr
        ft.rotation.x, ft.rotation.y, ft.rotation.z, ft.rotation.w = q
    return out


def _matrix(tr: Vec3, q: Quat) -> np.ndarray:
    """A transform as a 4x4 matrix (``q`` normalised)."""
    from scipy.spatial.transform import Rotation

    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(list(q)).as_matrix()
    m[:3, 3] = list(tr)
    return m


def _quat(m: np.ndarray) -> Quat:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(m[:3, :3]).as_quat()
    return Quat(float(x), float(y), float(z), float(w))


class _StaticTree:
    """``/tf_static`` as parent links, to give cameras a world pose (links that cannot be used
    are left out: the read proper warns about their message)."""

    def __init__(self) -> None:
        self.parent: dict[str, tuple[str, np.ndarray]] = {}

    def add(self, msg: Any) -> None:
        for i, tf in enumerate(msg.transforms):
            try:
                tr, q = _link(tf, i)
            except _Skip:
                continue
            child = str(tf.child_frame_id).lstrip("/")
            parent = str(tf.header.frame_id).lstrip("/")
            self.parent[child] = (parent, _matrix(tr, q))

    def world_from(self, frame: str) -> np.ndarray | None:
        """``world <- frame`` when the chain ends in a world frame."""
        m = np.eye(4)
        seen = set()
        frame = frame.lstrip("/")
        while frame not in WORLD_FRAMES:
            if frame in seen or frame not in self.parent:
                return None
            seen.add(frame)
            frame, link = self.parent[frame]
            m = link @ m
        return m


def _camera_model(msg: Any, name: str, t_ns: int, tree: _StaticTree) -> CameraModel:
    k = [float(v) for v in msg.k]
    d = tuple(float(v) for v in msg.d)
    if len(k) != 9:
        raise _Skip("k", f"{len(k)} values, expected 9")
    _finite({**{f"k[{i}]": v for i, v in enumerate(k)}, **{f"d[{i}]": v for i, v in enumerate(d)}})
    model = str(msg.distortion_model) or "none"
    world = tree.world_from(str(msg.header.frame_id))
    pose = None
    if world is not None:
        t = world[:3, 3]
        pose = Transform(Vec3(float(t[0]), float(t[1]), float(t[2])), _quat(world))
    return CameraModel(
        t_ns=t_ns,
        camera=name,
        width_px=int(msg.width),
        height_px=int(msg.height),
        fx_px=k[0],
        fy_px=k[4],
        cx_px=k[2],
        cy_px=k[5],
        distortion_model=model,
        distortion=d,
        world_from_camera=pose,
    )


Stamped = tuple[int, int, str, Any]


def _static_tree(reader: Any) -> _StaticTree:
    """The bag's ``/tf_static`` links (messages that do not decode are left to the read)."""
    tree = _StaticTree()
    # rosbags reads every connection when given none: ask only for what exists
    statics = [c for c in reader.connections if c.topic == topics.TF_STATIC]
    if not statics:
        return tree
    try:
        for conn, _, raw in reader.messages(connections=statics):
            try:
                tree.add(reader.deserialize(raw, conn.msgtype))
            except Exception:  # noqa: BLE001 - damaged CDR: the read proper counts it
                continue
    except Exception:  # noqa: BLE001 - a damaged bag: the read proper warns
        return tree
    return tree


# what converting a message that does not match its type raises (a schema that lies, sizes
# that do not fit): the message is skipped, never the whole bag
_UNUSABLE = (_Skip, ValueError, TypeError, AttributeError, IndexError, KeyError, OverflowError)


def _why(err: BaseException) -> tuple[str, str]:
    """(field, why) of a conversion failure."""
    if isinstance(err, _Skip):
        return err.field_name, err.why
    if isinstance(err, AttributeError) and getattr(err, "name", None):
        return str(err.name), "missing (the message is not of the topic's type)"
    return "message", f"{type(err).__name__}: {err}"


@dataclass(slots=True)
class _Skips:
    """Messages skipped per topic: how many, and the first one's field and reason."""

    counts: Counter[str] = field(default_factory=Counter)
    first: dict[str, str] = field(default_factory=dict)
    totals: Counter[str] = field(default_factory=Counter)

    def add(self, topic: str, log_ns: int, field_name: str, why: str) -> None:
        self.counts[topic] += 1
        self.first.setdefault(topic, f"first at {log_ns} ns: field {field_name}: {why}")

    def warn(self, bag: Path) -> None:
        """One warning per topic with skipped messages."""
        for topic, n in sorted(self.counts.items()):
            warnings.warn(
                f"{bag}: {topic}: skipped {n} of {self.totals[topic]} messages that cannot be "
                f"used ({self.first[topic]})",
                IncompleteInputWarning,
                stacklevel=3,
            )


@dataclass(slots=True)
class _Converter:
    """ROS messages to trackctl messages, with the state one read carries: the static tf tree
    and the cameras already calibrated (each is written once)."""

    tree: _StaticTree
    calibrated: set[str] = field(default_factory=set)

    def convert(
        self, plan: TopicPlan, msgtype: str, msg: Any, log_ns: int
    ) -> list[tuple[str, Any]]:
        """The ``(trackctl topic, message)`` pairs one ROS message becomes (none for a
        camera's later CameraInfo).

        Raises:
            _Skip, ValueError, AttributeError...: the message cannot be used (see _UNUSABLE).
        """
        t_ns = _stamp(msg.header, log_ns) if hasattr(msg, "header") else log_ns
        name = plan.name
        if plan.role == "odometry":
            return _odometry(msg, plan, t_ns)
        if plan.role == "imu":
            return [(plan.targets[0], _imu(msg, name, t_ns))]
        if plan.role == "pose":
            return _pose(msg, plan, t_ns)
        if plan.role == "gps":
            return _gps(msg, plan, t_ns)
        if plan.role == "image":
            if msgtype.endswith("CompressedImage"):
                return [(topics.image(name), _compressed(msg, name, t_ns))]
            return [(topics.image(name), _raw(msg, name, t_ns))]
        if plan.role == "camera_info" and name not in self.calibrated:
            return self._calibration(msg, name, t_ns)
        if plan.role == "tf":
            return [(plan.targets[0], _transforms(msg, log_ns))]
        return []

    def _calibration(self, msg: Any, name: str, t_ns: int) -> list[tuple[str, Any]]:
        from trackctl.ingest.calibration import to_foxglove_calibration

        model = _camera_model(msg, name, t_ns, self.tree)
        out = [
            (topics.calibration(name), to_foxglove_calibration(model)),
            (topics.camera_model(name), model),
        ]
        self.calibrated.add(name)  # only once it converted: a bad first one is skipped
        return out


def _orphan_rows(bag: Path) -> list[tuple[Path, int]]:
    """sqlite3 storage: the rows of each ``.db3`` whose topic id names no topic (rosbags leaves
    them out silently)."""
    files = [bag] if bag.suffix == ".db3" else sorted(bag.glob("*.db3")) if bag.is_dir() else []
    out = []
    for db in files:
        try:
            con = sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
            try:
                (n,) = con.execute(
                    "SELECT COUNT(*) FROM messages WHERE topic_id NOT IN (SELECT id FROM topics)"
                ).fetchone()
            finally:
                con.close()
        except sqlite3.Error:
            continue  # rosbags opened it: a schema it reads differently is its business
        if n:
            out.append((db, int(n)))
    return out


def read_ros2(bag: Path, plans: Sequence[TopicPlan], order: int = 0) -> Iterator[Stamped]:
    """The bag's mapped messages as ``(log time, order, trackctl topic, message)`` in the bag's
    order. Camera calibrations are written once per camera (the first usable CameraInfo), with
    the pose ``/tf_static`` gives the camera's frame. Messages that cannot be used are skipped
    (one warning per topic); a bag damaged further in is read up to the damage (a warning).

    Raises:
        InputError: the bag does not open.
    """
    by_topic = {p.ros_topic: p for p in plans if p.role != "ignore"}
    if not by_topic:
        return
    for db, n in _orphan_rows(bag):
        warnings.warn(
            f"{db}: skipped {n} messages whose topic_id names no topic (table topics)",
            IncompleteInputWarning,
            stacklevel=2,
        )
    reader = _open(bag)
    skips = _Skips()
    try:
        converter = _Converter(_static_tree(reader))
        wanted = [c for c in reader.connections if c.topic in by_topic]
        if wanted:
            yield from _messages(bag, reader, wanted, by_topic, converter, skips, order)
    finally:
        reader.close()
    skips.warn(bag)


def _messages(
    bag: Path,
    reader: Any,
    wanted: Sequence[Any],
    by_topic: Mapping[str, TopicPlan],
    converter: _Converter,
    skips: _Skips,
    order: int,
) -> Iterator[Stamped]:
    """The converted messages of ``wanted``; stops with a warning where the bag is damaged."""
    n = 0
    stream = iter(reader.messages(connections=list(wanted)))
    while True:
        try:
            conn, log_ns, raw = next(stream)
        except StopIteration:
            return
        except Exception as err:  # noqa: BLE001 - rosbags ReaderError, ZstdError, struct errors
            warnings.warn(
                f"{bag}: the bag is damaged after {n} messages ({type(err).__name__}: {err}); "
                f"the rest of it is left out",
                IncompleteInputWarning,
                stacklevel=3,
            )
            return
        n += 1
        skips.totals[conn.topic] += 1
        try:
            msg = reader.deserialize(raw, conn.msgtype)
            pairs = converter.convert(by_topic[conn.topic], conn.msgtype, msg, log_ns)
        except _UNUSABLE as err:
            skips.add(conn.topic, log_ns, *_why(err))
            continue
        except Exception as err:  # noqa: BLE001 - rosbags' CDR decoder raises assorted errors
            skips.add(conn.topic, log_ns, "message", f"cannot decode {conn.msgtype} ({err})")
            continue
        for topic, out in pairs:
            yield (log_ns, order, topic, out)
