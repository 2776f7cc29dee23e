"""Write ROS 2 bags with rosbags (as a robot would record them) from trackctl logs, for tests."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from trackctl.geometry.odometry import DiffDrive
from trackctl.logs import LogReader
from trackctl.logs.messages import CameraModel, WheelOdometry

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types


def _time(ns: int) -> Any:
    return T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _header(ns: int, frame: str) -> Any:
    return T["std_msgs/msg/Header"](stamp=_time(ns), frame_id=frame)


def _vec(x: float, y: float, z: float) -> Any:
    return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def _quat(x: float, y: float, z: float, w: float) -> Any:
    return T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def _yaw_quat(yaw: float) -> Any:
    return _quat(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def _camera_info(model: CameraModel, frame: str) -> Any:
    k = np.array([model.fx_px, 0, model.cx_px, 0, model.fy_px, model.cy_px, 0, 0, 1], float)
    p = np.array(
        [model.fx_px, 0, model.cx_px, 0, 0, model.fy_px, model.cy_px, 0, 0, 0, 1, 0], float
    )
    d = np.array(model.distortion or (0.0,) * 5, float)
    roi = T["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return T["sensor_msgs/msg/CameraInfo"](
        header=_header(model.t_ns, frame),
        height=model.height_px,
        width=model.width_px,
        distortion_model="plumb_bob",
        d=d,
        k=k,
        r=np.eye(3).ravel(),
        p=p,
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


def _static_tf(model: CameraModel, frame: str) -> Any:
    pose = model.world_from_camera
    assert pose is not None
    tr, q = pose.translation, pose.rotation
    tf = T["geometry_msgs/msg/TransformStamped"](
        header=_header(0, "world"),
        child_frame_id=frame,
        transform=T["geometry_msgs/msg/Transform"](
            translation=_vec(tr.x, tr.y, tr.z), rotation=_quat(q.x, q.y, q.z, q.w)
        ),
    )
    return T["tf2_msgs/msg/TFMessage"](transforms=[tf])


def twist_from_ticks(odos: list[WheelOdometry], drive: DiffDrive) -> dict[int, tuple[float, float]]:
    """(v, omega) at each sample's time that reproduce the ticks of the interval after it (the
    last sample: standing still)."""
    out = {o.t_ns: (0.0, 0.0) for o in odos}
    for a, b in zip(odos, odos[1:], strict=False):
        ds, dyaw = drive.motion_from_ticks(
            b.left_ticks - a.left_ticks, b.right_ticks - a.right_ticks
        )
        dt = (b.t_ns - a.t_ns) / 1e9
        out[a.t_ns] = (ds / dt, dyaw / dt)
    return out


def smirror_log_to_bag(log: Path, bag: Path, storage: StoragePlugin = StoragePlugin.MCAP) -> None:
    """A ROS 2 bag of an S-Mirror log's robot and nodes: ``/r1/odom`` (nav_msgs/Odometry: the
    velocities that reproduce the wheel ticks over each interval, and the integrated pose),
    ``/r1/imu``, ``/NODE/image/compressed``, ``/NODE/camera_info`` and ``/tf_static`` (world to
    each camera's optical frame)."""
    reader = LogReader(log)
    md = reader.metadata().get("robot/r1", {})
    drive = DiffDrive(float(md.get("ticks_per_m", 2000)), float(md.get("wheel_base_m", 0.3)))
    odo: list[tuple[int, WheelOdometry]] = [
        (m.log_time_ns, m.message) for m in reader.messages(["/robot/r1/odom"])
    ]
    nodes = sorted(t.split("/")[1] for t in reader.topics() if t.endswith("/camera_model"))
    with Writer(bag, version=8, storage_plugin=storage) as w:
        c_odom = w.add_connection("/r1/odom", "nav_msgs/msg/Odometry", typestore=TS)
        c_imu = w.add_connection("/r1/imu", "sensor_msgs/msg/Imu", typestore=TS)
        c_tf = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=TS)
        c_img = {
            n: w.add_connection(
                f"/{n}/image/compressed", "sensor_msgs/msg/CompressedImage", typestore=TS
            )
            for n in nodes
        }
        c_info = {
            n: w.add_connection(f"/{n}/camera_info", "sensor_msgs/msg/CameraInfo", typestore=TS)
            for n in nodes
        }
        for m in reader.messages([f"/{n}/camera_model" for n in nodes]):
            name = m.message.camera
            frame = f"{name}_optical"
            w.write(
                c_tf, m.log_time_ns, TS.serialize_cdr(_static_tf(m.message, frame), c_tf.msgtype)
            )
            info = _camera_info(m.message, frame)
            w.write(c_info[name], m.log_time_ns, TS.serialize_cdr(info, c_info[name].msgtype))
        frames = iter(reader.messages([f"/{n}/image" for n in nodes]))
        pending = next(frames, None)
        x = y = yaw = 0.0
        zero36 = np.zeros(36)
        twist = twist_from_ticks([o for _, o in odo], drive)
        for i, (t_ns, o) in enumerate(odo):
            while pending is not None and pending.log_time_ns <= t_ns:
                name = pending.topic.split("/")[1]
                img = T["sensor_msgs/msg/CompressedImage"](
                    header=_header(pending.log_time_ns, f"{name}_optical"),
                    format="jpeg",
                    data=np.frombuffer(pending.message.data, np.uint8),
                )
                w.write(
                    c_img[name], pending.log_time_ns, TS.serialize_cdr(img, c_img[name].msgtype)
                )
                pending = next(frames, None)
            v, omega = twist[o.t_ns]
            msg = T["nav_msgs/msg/Odometry"](
                header=_header(t_ns, "odom"),
                child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=T["geometry_msgs/msg/Pose"](
                        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                        orientation=_yaw_quat(yaw),
                    ),
                    covariance=zero36,
                ),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](
                        linear=_vec(v, 0.0, 0.0), angular=_vec(0.0, 0.0, omega)
                    ),
                    covariance=zero36,
                ),
            )
            w.write(c_odom, t_ns, TS.serialize_cdr(msg, c_odom.msgtype))
            imu = T["sensor_msgs/msg/Imu"](
                header=_header(t_ns, "imu_link"),
                orientation=_yaw_quat(yaw),
                orientation_covariance=np.zeros(9),
                angular_velocity=_vec(0.0, 0.0, omega),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=_vec(0.0, 0.0, 9.81),
                linear_acceleration_covariance=np.zeros(9),
            )
            w.write(c_imu, t_ns, TS.serialize_cdr(imu, c_imu.msgtype))
            if i + 1 < len(odo):
                dt = (odo[i + 1][0] - t_ns) / 1e9
                x += v * dt * math.cos(yaw + omega * dt / 2)
                y += v * dt * math.sin(yaw + omega * dt / 2)
                yaw += omega * dt


# Hostile bags: one small bag per way a robot's recording goes wrong (tests/fuzz, benchmarks/
# hostile_inputs.py). Each holds one good odometry message beside the bad one.

HOSTILE_BAGS = (
    "nan_odometry",
    "nan_imu",
    "nan_camera_info",
    "zero_quaternion",
    "short_image",
    "lying_schema",
    "forged_length",
    "damaged_zstd",
)


def _odom_msg(t_ns: int, v: float = 0.5) -> Any:
    zero36 = np.zeros(36)
    return T["nav_msgs/msg/Odometry"](
        header=_header(t_ns, "odom"),
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                orientation=_yaw_quat(0.0),
            ),
            covariance=zero36,
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=_vec(v, 0.0, 0.0), angular=_vec(0, 0, 0)),
            covariance=zero36,
        ),
    )


def _imu_msg(t_ns: int, az: float) -> Any:
    return T["sensor_msgs/msg/Imu"](
        header=_header(t_ns, "imu_link"),
        orientation=_yaw_quat(0.0),
        orientation_covariance=np.zeros(9),
        angular_velocity=_vec(0.0, 0.0, 0.0),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=_vec(0.0, 0.0, az),
        linear_acceleration_covariance=np.zeros(9),
    )


def _model(fx: float) -> CameraModel:
    from trackctl.logs.messages import Quat, Transform, Vec3

    return CameraModel(
        t_ns=1_000_000_000,
        camera="cam",
        width_px=64,
        height_px=48,
        fx_px=fx,
        fy_px=60.0,
        cx_px=32.0,
        cy_px=24.0,
        world_from_camera=Transform(Vec3(0.0, 0.0, 2.0), Quat(1.0, 0.0, 0.0, 0.0)),
    )


def _hostile_messages(case: str) -> list[tuple[str, str, Any]]:
    """(topic, type, message) of the bad message(s) of ``case`` (message-level cases)."""
    t = 2_000_000_000
    if case == "nan_odometry":
        return [("/r1/odom", "nav_msgs/msg/Odometry", _odom_msg(t, float("nan")))]
    if case == "nan_imu":
        return [("/r1/imu", "sensor_msgs/msg/Imu", _imu_msg(t, float("inf")))]
    if case == "nan_camera_info":
        return [
            (
                "/cam/camera_info",
                "sensor_msgs/msg/CameraInfo",
                _camera_info(_model(float("nan")), "cam_optical"),
            )
        ]
    if case == "zero_quaternion":
        tf = _static_tf(_model(60.0), "cam_optical")
        tf.transforms[0].transform.rotation = _quat(0.0, 0.0, 0.0, 0.0)
        return [
            ("/tf_static", "tf2_msgs/msg/TFMessage", tf),
            (
                "/cam/camera_info",
                "sensor_msgs/msg/CameraInfo",
                _camera_info(_model(60.0), "cam_optical"),
            ),
        ]
    if case == "short_image":
        img = T["sensor_msgs/msg/Image"](
            header=_header(t, "cam_optical"),
            height=48,
            width=64,
            encoding="rgb8",
            is_bigendian=0,
            step=64 * 3,
            data=np.zeros(100, np.uint8),
        )
        return [("/cam/image_raw", "sensor_msgs/msg/Image", img)]
    raise ValueError(case)


def hostile_bag(path: Path, case: str) -> Path:
    """A small ROS 2 bag (``path``: a rosbag2 folder, or a bare ``.mcap`` for the chunk cases)
    with one good odometry message and the bad input ``case`` (one of :data:`HOSTILE_BAGS`)."""
    if case in ("forged_length", "damaged_zstd"):
        return _damaged_mcap_bag(path.with_suffix(".mcap"), case)
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        good = w.add_connection("/r1/odom", "nav_msgs/msg/Odometry", typestore=TS)
        w.write(good, 1_000_000_000, TS.serialize_cdr(_odom_msg(1_000_000_000), good.msgtype))
        if case == "lying_schema":
            # the topic says Odometry, the bytes are an Imu
            liar = w.add_connection("/r2/odom", "nav_msgs/msg/Odometry", typestore=TS)
            imu = TS.serialize_cdr(_imu_msg(2_000_000_000, 9.8), "sensor_msgs/msg/Imu")
            w.write(liar, 2_000_000_000, imu)
            return path
        conns: dict[str, Any] = {"/r1/odom": good}
        for i, (topic, msgtype, msg) in enumerate(_hostile_messages(case)):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=TS)
            w.write(conns[topic], 2_000_000_000 + i, TS.serialize_cdr(msg, msgtype))
    return path


def _damaged_mcap_bag(path: Path, case: str) -> Path:
    """A bare ROS 2 ``.mcap`` (ros2msg schemas, CDR) of 200 odometry messages whose second chunk
    is damaged: ``damaged_zstd`` (zstd chunks) has 16 bytes of its compressed data zeroed;
    ``forged_length`` (uncompressed chunks) has its first message record claim 2^40 bytes (the
    chunk's CRC cleared, so only the length gives it away)."""
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter

    zstd = case == "damaged_zstd"
    with path.open("wb") as f:
        kind = CompressionType.ZSTD if zstd else CompressionType.NONE
        w = McapWriter(f, chunk_size=2048, compression=kind)
        w.start(profile="ros2", library="tests")
        schema = w.register_schema(
            "nav_msgs/msg/Odometry", "ros2msg", _msgdef("nav_msgs/msg/Odometry").encode()
        )
        ch = w.register_channel("/r1/odom", "cdr", schema)
        for i in range(200):
            t = (i + 1) * 10_000_000
            data = TS.serialize_cdr(_odom_msg(t), "nav_msgs/msg/Odometry")
            w.add_message(ch, log_time=t, data=bytes(data), publish_time=t)
        w.finish()
    data = bytearray(path.read_bytes())
    chunk = _nth_chunk(bytes(data), 1)
    # chunk: opcode, length, start, end, uncompressed size, crc, compression string, records
    name_len = int.from_bytes(data[chunk + 37 : chunk + 41], "little")
    records = chunk + 41 + name_len + 8
    if zstd:
        data[records + 40 : records + 56] = bytes(16)
    else:
        data[chunk + 33 : chunk + 37] = bytes(4)
        data[records + 1 : records + 9] = (1 << 40).to_bytes(8, "little")
    path.write_bytes(bytes(data))
    return path


def _nth_chunk(data: bytes, n: int) -> int:
    """Offset of the ``n``-th (0-based) Chunk record of an MCAP file."""
    pos, seen = 8, 0
    while pos + 9 <= len(data):
        op, length = data[pos], int.from_bytes(data[pos + 1 : pos + 9], "little")
        if op == 0x06:
            if seen == n:
                return pos
            seen += 1
        pos += 9 + length
    raise ValueError(f"no chunk {n}")


def _msgdef(msgtype: str) -> str:
    text, _ = TS.generate_msgdef(msgtype, ros_version=2)
    return text
