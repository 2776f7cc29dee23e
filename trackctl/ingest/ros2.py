"""ROS 2 bags into trackctl logs: topics mapped by message type, messages converted.

A robot records a rosbag2 (a directory with ``metadata.yaml`` and MCAP or sqlite3 ``.db3``
files, or a bare ``.mcap``); `rosbags <https://gitlab.com/ternaris/rosbags>`_ reads every form
without a ROS installation. :func:`plan_ros2` maps each ROS topic to a *role* by its message type
and derives the trackctl NAME from the topic's namespace; ``--map ROS_TOPIC=ROLE:NAME`` overrides
(or ``ROS_TOPIC=ignore``):

=============== ======================================== =========================================
role            ROS 2 type                               trackctl topic(s)
=============== ======================================== =========================================
``odometry``    ``nav_msgs/msg/Odometry``                ``/robot/NAME/odom`` (v, omega and pose)
``imu``         ``sensor_msgs/msg/Imu``                  ``/robot/NAME/imu``
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
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from trackctl.errors import InputError
from trackctl.logs import topics
from trackctl.logs.messages import CameraModel, Imu, Pose2D, Quat, Transform, Vec3, WheelOdometry

__all__ = [
    "ROLES",
    "AUTO_ROLES",
    "TopicPlan",
    "parse_maps",
    "plan_ros2",
    "read_ros2",
    "WORLD_FRAMES",
]

ROLES = ("odometry", "imu", "image", "camera_info", "tf", "ignore")
AUTO_ROLES: dict[str, str] = {
    "nav_msgs/msg/Odometry": "odometry",
    "sensor_msgs/msg/Imu": "imu",
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
    "data",
    "data_raw",
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
    why: str
    """``auto`` (by message type), ``--map``, or why it is ignored."""

    @property
    def targets(self) -> tuple[str, ...]:
        """The trackctl topics it is written to."""
        if self.role == "odometry":
            return (topics.odom(self.name),)
        if self.role == "imu":
            return (topics.robot_imu(self.name),)
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
        raise InputError(f"--ros2 {bag}: no such file or directory")
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as err:  # rosbags raises its own ReaderError / AnyReaderError
        raise InputError(f"--ros2 {bag}: not a readable ROS bag ({err})") from err
    return reader


def plan_ros2(bag: Path, maps: Mapping[str, tuple[str, str]] | None = None) -> list[TopicPlan]:
    """Each topic of ``bag`` with its role and trackctl NAME (automatic unless mapped).

    Raises:
        InputError: the bag does not open, a ``--map`` names a topic the bag lacks or a role its
            type cannot fill, or two topics of one role map to the same NAME.
    """
    maps = dict(maps or {})
    reader = _open(bag)
    try:
        conns = sorted(reader.connections, key=lambda c: c.topic)
        counts: Counter[str] = Counter()
        types: dict[str, str] = {}
        for c in conns:
            counts[c.topic] += c.msgcount
            types[c.topic] = c.msgtype
    finally:
        reader.close()
    missing = sorted(set(maps) - set(types))
    if missing:
        raise InputError(
            f"--map {missing[0]}: the bag has no such topic (topics: {', '.join(sorted(types))})"
        )
    plans = []
    for topic, ros_type in sorted(types.items()):
        if topic in maps:
            role, name = maps[topic]
            why = "--map"
            if role not in ("ignore",) and ros_type not in _ACCEPTS.get(role, ()):
                raise InputError(
                    f"--map {topic}={role}:{name}: {topic} is {ros_type}; role {role} takes "
                    f"{' or '.join(_ACCEPTS.get(role, ()))}"
                )
        elif ros_type in AUTO_ROLES:
            role, name, why = AUTO_ROLES[ros_type], "", "auto"
        else:
            role, name, why = "ignore", "", f"no role for {ros_type}"
        if role not in ("ignore", "tf") and not name:
            name = _name_from_topic(topic, role)
        plans.append(TopicPlan(topic, ros_type, counts[topic], role, name, why))
    seen: dict[tuple[str, ...], str] = {}
    for p in plans:
        for target in p.targets:
            key = (target,)
            if key in seen and p.role != "tf":
                raise InputError(
                    f"--ros2 {bag}: {seen[key]} and {p.ros_topic} both map to {target}; "
                    f"name one with --map {p.ros_topic}={p.role}:OTHER"
                )
            seen[key] = p.ros_topic
    return plans


# -- conversions ----------------------------------------------------------------------------------


def _stamp(header: Any, fallback: int) -> int:
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns > 0 else fallback


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _odometry(msg: Any, name: str, t_ns: int) -> WheelOdometry:
    pose = msg.pose.pose
    return WheelOdometry(
        t_ns=t_ns,
        frame_id=f"robot/{name}",
        v_mps=float(msg.twist.twist.linear.x),
        omega_rps=float(msg.twist.twist.angular.z),
        pose=Pose2D(float(pose.position.x), float(pose.position.y), _yaw(pose.orientation)),
    )


def _imu(msg: Any, name: str, t_ns: int) -> Imu:
    a, g, q = msg.linear_acceleration, msg.angular_velocity, msg.orientation
    # REP 145: covariance[0] == -1 means the field is not provided
    has_q = float(msg.orientation_covariance[0]) != -1.0
    has_g = float(msg.angular_velocity_covariance[0]) != -1.0
    return Imu(
        t_ns=t_ns,
        frame_id=f"robot/{name}",
        accel_mps2=Vec3(float(a.x), float(a.y), float(a.z)),
        gyro_rps=Vec3(float(g.x), float(g.y), float(g.z)) if has_g else None,
        orientation=Quat(float(q.x), float(q.y), float(q.z), float(q.w)) if has_q else None,
    )


def _compressed(msg: Any, name: str, t_ns: int) -> Any:
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    fmt = str(msg.format).lower()
    out = CompressedImage(
        frame_id=name, data=bytes(msg.data), format="png" if "png" in fmt else "jpeg"
    )
    out.timestamp.FromNanoseconds(t_ns)
    return out


_RAW_CHANNELS = {"mono8": 1, "8uc1": 1, "bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4, "mono16": 1}


def _raw(msg: Any, name: str, t_ns: int, where: str) -> Any:
    import cv2
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    enc = str(msg.encoding).lower()
    if enc not in _RAW_CHANNELS:
        raise InputError(
            f"{where}: sensor_msgs/msg/Image encoding {msg.encoding!r} is not supported "
            f"(supported: {', '.join(sorted(_RAW_CHANNELS))})"
        )
    dtype = np.uint16 if enc == "mono16" else np.uint8
    row = np.frombuffer(bytes(msg.data), dtype=dtype).reshape(int(msg.height), -1)
    img: Any = row[:, : int(msg.width) * _RAW_CHANNELS[enc]].reshape(
        int(msg.height), int(msg.width), _RAW_CHANNELS[enc]
    )
    if enc == "rgb8":
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    elif enc == "rgba8":
        img = cv2.cvtColor(img, cv2.COLOR_RGBA2BGRA)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise InputError(f"{where}: the image does not encode as PNG")
    out = CompressedImage(frame_id=name, data=buf.tobytes(), format="png")
    out.timestamp.FromNanoseconds(t_ns)
    return out


def _transforms(msg: Any, t_fallback: int) -> Any:
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    out = FrameTransforms()
    for tf in msg.transforms:
        ft = out.transforms.add()
        ft.timestamp.FromNanoseconds(_stamp(tf.header, t_fallback))
        ft.parent_frame_id = str(tf.header.frame_id)
        ft.child_frame_id = str(tf.child_frame_id)
        tr, q = tf.transform.translation, tf.transform.rotation
        ft.translation.x, ft.translation.y, ft.translation.z = float(tr.x), float(tr.y), float(tr.z)
        ft.rotation.x, ft.rotation.y, ft.rotation.z, ft.rotation.w = (
            float(q.x),
            float(q.y),
            float(q.z),
            float(q.w),
        )
    return out


def _matrix(tr: Any, q: Any) -> np.ndarray:
    """A ROS transform as a 4x4 matrix (scipy normalises the quaternion)."""
    from scipy.spatial.transform import Rotation

    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat([float(q.x), float(q.y), float(q.z), float(q.w)]).as_matrix()
    m[:3, 3] = [float(tr.x), float(tr.y), float(tr.z)]
    return m


def _quat(m: np.ndarray) -> Quat:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(m[:3, :3]).as_quat()
    return Quat(float(x), float(y), float(z), float(w))


class _StaticTree:
    """``/tf_static`` as parent links, to give cameras a world pose."""

    def __init__(self) -> None:
        self.parent: dict[str, tuple[str, np.ndarray]] = {}

    def add(self, msg: Any) -> None:
        for tf in msg.transforms:
            child = str(tf.child_frame_id).lstrip("/")
            parent = str(tf.header.frame_id).lstrip("/")
            self.parent[child] = (parent, _matrix(tf.transform.translation, tf.transform.rotation))

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
        distortion=tuple(float(v) for v in msg.d),
        world_from_camera=pose,
    )


Stamped = tuple[int, int, str, Any]


def _static_tree(reader: Any) -> _StaticTree:
    """The bag's ``/tf_static`` links."""
    tree = _StaticTree()
    # rosbags reads every connection when given none: ask only for what exists
    statics = [c for c in reader.connections if c.topic == topics.TF_STATIC]
    for conn, _, raw in reader.messages(connections=statics) if statics else ():
        tree.add(reader.deserialize(raw, conn.msgtype))
    return tree


def _deserialize(reader: Any, msgtype: str, raw: bytes, where: str) -> Any:
    """One bag message, decoded.

    Raises:
        InputError: damaged CDR (names the bag, topic and time).
    """
    try:
        return reader.deserialize(raw, msgtype)
    except Exception as err:  # rosbags raises struct/index errors on damaged CDR
        raise InputError(f"{where}: cannot decode {msgtype} ({err})") from err


@dataclass(slots=True)
class _Converter:
    """ROS messages to trackctl messages, with the state one read carries: the static tf tree
    and the cameras already calibrated (each is written once)."""

    tree: _StaticTree
    calibrated: set[str] = field(default_factory=set)

    def convert(
        self, plan: TopicPlan, msgtype: str, msg: Any, log_ns: int, where: str
    ) -> list[tuple[str, Any]]:
        """The ``(trackctl topic, message)`` pairs one ROS message becomes (none for a
        camera's later CameraInfo)."""
        t_ns = _stamp(msg.header, log_ns) if hasattr(msg, "header") else log_ns
        name = plan.name
        if plan.role == "odometry":
            return [(topics.odom(name), _odometry(msg, name, t_ns))]
        if plan.role == "imu":
            return [(topics.robot_imu(name), _imu(msg, name, t_ns))]
        if plan.role == "image":
            if msgtype.endswith("CompressedImage"):
                return [(topics.image(name), _compressed(msg, name, t_ns))]
            return [(topics.image(name), _raw(msg, name, t_ns, where))]
        if plan.role == "camera_info" and name not in self.calibrated:
            return self._calibration(msg, name, t_ns, where)
        if plan.role == "tf":
            return [(plan.targets[0], _transforms(msg, log_ns))]
        return []

    def _calibration(self, msg: Any, name: str, t_ns: int, where: str) -> list[tuple[str, Any]]:
        from trackctl.ingest.calibration import to_foxglove_calibration

        self.calibrated.add(name)
        try:
            model = _camera_model(msg, name, t_ns, self.tree)
        except ValueError as err:
            raise InputError(f"{where}: field k/width/height: {err}") from err
        return [
            (topics.calibration(name), to_foxglove_calibration(model)),
            (topics.camera_model(name), model),
        ]


def read_ros2(bag: Path, plans: Sequence[TopicPlan], order: int = 0) -> Iterator[Stamped]:
    """The bag's mapped messages as ``(log time, order, trackctl topic, message)`` in the bag's
    order. Camera calibrations are written once per camera (the first CameraInfo), with the pose
    ``/tf_static`` gives the camera's frame.

    Raises:
        InputError: a message cannot be converted (names the bag, topic and field).
    """
    by_topic = {p.ros_topic: p for p in plans if p.role != "ignore"}
    if not by_topic:
        return
    reader = _open(bag)
    try:
        converter = _Converter(_static_tree(reader))
        wanted = [c for c in reader.connections if c.topic in by_topic]
        if not wanted:
            return
        for conn, log_ns, raw in reader.messages(connections=wanted):
            plan = by_topic[conn.topic]
            where = f"{bag}: {conn.topic} at {log_ns} ns"
            msg = _deserialize(reader, conn.msgtype, raw, where)
            for topic, out in converter.convert(plan, conn.msgtype, msg, log_ns, where):
                yield (log_ns, order, topic, out)
    finally:
        reader.close()
