"""Topic naming conventions (the contract other tools and pipelines rely on)."""

from __future__ import annotations

__all__ = [
    "RSSI",
    "GROUND_TRUTH",
    "imu",
    "odom",
    "image",
    "calibration",
    "camera_model",
    "detections",
    "overlay",
    "transforms",
    "metrics",
    "EV_E",
    "EV_GROUND_TRUTH",
    "EV_MATCHES",
    "EV_V_PREFIX",
    "ev_v",
]

RSSI = "/rssi"
GROUND_TRUTH = "/ground_truth"


def imu(phone: str) -> str:
    """IMU of a phone: ``/phone/NAME/imu`` (trackctl.Imu)."""
    return f"/phone/{phone}/imu"


def robot_imu(robot: str) -> str:
    """IMU of a robot: ``/robot/NAME/imu`` (trackctl.Imu)."""
    return f"/robot/{robot}/imu"


TF = "/tf"
TF_STATIC = "/tf_static"
"""Transforms (foxglove.FrameTransforms), dynamic and static, as ROS names them."""


def odom(robot: str) -> str:
    """Wheel odometry of a robot: ``/robot/NAME/odom`` (trackctl.WheelOdometry)."""
    return f"/robot/{robot}/odom"


def image(camera: str) -> str:
    """Frames of a camera: ``/NAME/image`` (foxglove.CompressedImage)."""
    return f"/{camera}/image"


def calibration(camera: str) -> str:
    """Intrinsics of a camera: ``/NAME/calibration`` (foxglove.CameraCalibration)."""
    return f"/{camera}/calibration"


def camera_model(camera: str) -> str:
    """Intrinsics + world pose of a camera: ``/NAME/camera_model`` (trackctl.CameraModel)."""
    return f"/{camera}/camera_model"


def detections(camera: str) -> str:
    """Detections of a camera: ``/NAME/detections`` (trackctl.Detections)."""
    return f"/{camera}/detections"


def overlay(source_topic: str) -> str:
    """Image overlay of a per-camera topic: ``SOURCE/annotations`` (foxglove.ImageAnnotations),
    e.g. ``/NAME/detections/annotations``; stamped as the camera's images are."""
    return f"{source_topic}/annotations"


def transforms(prefix: str) -> str:
    """A processor's robot frame tree: ``PREFIX/tf`` (foxglove.FrameTransform, one transform a
    message), e.g. ``/robot/NAME/dead_reckoning/tf``, ``/smirror/NAME/tf``, ``/bridgeloc/tf``."""
    return f"{prefix}/tf"


def metrics(processor: str) -> str:
    """Metric report of a processor: ``/metrics/NAME`` (trackctl.MetricReport)."""
    return f"/metrics/{processor}"


# -- EV-Matching (§3.2) ---------------------------------------------------------------------------
EV_E = "/ev/e"
"""E-scenarios: one trackctl.EObservations per cell per time window."""
EV_GROUND_TRUTH = "/ev/ground_truth"
"""EID <-> VID ground truth (trackctl.GroundTruth, one message)."""
EV_MATCHES = "/evmatch/matches"
"""EV-Matching output (trackctl.EvMatches)."""
EV_V_PREFIX = "/ev/cell/"


def ev_v(cell: str) -> str:
    """V-scenarios of one camera cell: ``/ev/cell/<i>_<j>/v`` (trackctl.VScenario per window)."""
    return f"{EV_V_PREFIX}{cell}/v"
