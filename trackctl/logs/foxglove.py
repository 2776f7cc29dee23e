"""Builders of Foxglove well-known messages (protobuf) from trackctl's plain values.

Image annotations use Foxglove's pixel convention, which is trackctl's: the origin is the
top-left corner of the top-left pixel, x right, y down. Planar poses are a yaw about +z.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable
from dataclasses import dataclass

from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation

from trackctl.logs.messages import Detections

__all__ = [
    "MAP_FRAME",
    "Rgba",
    "ImageBox",
    "pose_in_frame",
    "frame_transform",
    "odom_frame",
    "base_frame",
    "odom_base_transform",
    "map_odom_transform",
    "map_base_transform",
    "image_annotations",
    "detection_annotations",
    "label_color",
]

MAP_FRAME = "map"
"""The site's (world) frame of the localizers' FrameTransform trees (REP 105's ``map``)."""

Rgba = tuple[float, float, float, float]
"""A colour, each channel 0..1."""

DETECTION_COLOR: Rgba = (0.1, 1.0, 0.1, 1.0)


def odom_frame(robot: str) -> str:
    """A robot's odometry frame: ``<NAME>/odom`` (where its dead reckoning starts, REP 105)."""
    return f"{robot}/odom"


def base_frame(robot: str) -> str:
    """A robot's body frame: ``<NAME>/base_link`` (x forward, z up, REP 105)."""
    return f"{robot}/base_link"


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


def frame_transform(
    t_ns: int, parent: str, child: str, x_m: float, y_m: float, yaw_rad: float, z_m: float = 0.0
) -> FrameTransform:
    """A planar transform parent <- child (the child's origin and heading in the parent) as a
    foxglove.FrameTransform."""
    msg = FrameTransform(parent_frame_id=parent, child_frame_id=child)
    msg.timestamp.FromNanoseconds(int(t_ns))
    msg.translation.x, msg.translation.y, msg.translation.z = x_m, y_m, z_m
    msg.rotation.z = math.sin(yaw_rad / 2.0)
    msg.rotation.w = math.cos(yaw_rad / 2.0)
    return msg


def odom_base_transform(
    t_ns: int, robot: str, x_m: float, y_m: float, yaw_rad: float
) -> FrameTransform:
    """``<NAME>/odom -> <NAME>/base_link``: the robot's dead-reckoned pose in its odometry
    frame."""
    return frame_transform(t_ns, odom_frame(robot), base_frame(robot), x_m, y_m, yaw_rad)


def map_odom_transform(
    t_ns: int,
    robot: str,
    map_pose: tuple[float, float, float],
    odom_pose: tuple[float, float, float],
) -> FrameTransform:
    """``map -> <NAME>/odom``: the odometry frame's pose in the map that puts the robot at
    ``map_pose`` (x, y, yaw; the localizer's estimate) when its odometry says ``odom_pose``
    (what ROS localizers publish: map_T_odom = map_T_base * inverse(odom_T_base))."""
    (xm, ym, yaw_m), (xo, yo, yaw_o) = map_pose, odom_pose
    yaw = yaw_m - yaw_o
    c, s = math.cos(yaw), math.sin(yaw)
    x, y = xm - (c * xo - s * yo), ym - (s * xo + c * yo)
    yaw = math.atan2(math.sin(yaw), math.cos(yaw))
    return frame_transform(t_ns, MAP_FRAME, odom_frame(robot), x, y, yaw)


def map_base_transform(
    t_ns: int, robot: str, x_m: float, y_m: float, yaw_rad: float
) -> FrameTransform:
    """``map -> <NAME>/base_link``: a pose estimated without odometry (vision-only fixes)."""
    return frame_transform(t_ns, MAP_FRAME, base_frame(robot), x_m, y_m, yaw_rad)


@dataclass(frozen=True, slots=True)
class ImageBox:
    """One labelled box on an image, in pixels (top-left corner and size)."""

    x_px: float
    y_px: float
    w_px: float
    h_px: float
    label: str = ""
    color: Rgba = DETECTION_COLOR
    thickness_px: float = 2.0
    label_below: bool = False
    """Write the label under the box (so two overlays of one image keep their labels apart)."""


def label_color(label: str) -> Rgba:
    """A bright colour that stays the same for a label across frames and runs (crc32 hue)."""
    hue = (zlib.crc32(label.encode()) % 360) / 60.0
    x = 1.0 - abs(hue % 2.0 - 1.0)
    r, g, b = [(1, x, 0), (x, 1, 0), (0, 1, x), (0, x, 1), (x, 0, 1), (1, 0, x)][int(hue) % 6]
    return (float(r), float(g), float(b), 1.0)


def image_annotations(
    t_ns: int, boxes: Iterable[ImageBox], font_px: float = 12.0
) -> ImageAnnotations:
    """Boxes (closed outlines) and their labels above them as a foxglove.ImageAnnotations; every
    annotation is stamped ``t_ns``, which must be the image's own timestamp for the Image panel
    to overlay it."""
    msg = ImageAnnotations()
    for box in boxes:
        outline = PointsAnnotation(type=PointsAnnotation.Type.LINE_LOOP, thickness=box.thickness_px)
        outline.timestamp.FromNanoseconds(int(t_ns))
        x0, y0, x1, y1 = box.x_px, box.y_px, box.x_px + box.w_px, box.y_px + box.h_px
        for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1)):
            p = outline.points.add()
            p.x, p.y = float(x), float(y)
        c = outline.outline_color
        c.r, c.g, c.b, c.a = box.color
        msg.points.append(outline)
        if not box.label:
            continue
        text = TextAnnotation(text=box.label, font_size=font_px)
        text.timestamp.FromNanoseconds(int(t_ns))
        # above the box (inside its top edge when the box touches the image's top), or under it
        text.position.x = float(x0)
        if box.label_below:
            text.position.y = float(y1 + font_px)
        else:
            text.position.y = float(y0 - 2.0) if y0 >= font_px + 2.0 else float(y0 + font_px)
        text.text_color.r, text.text_color.g, text.text_color.b, text.text_color.a = box.color
        bg = text.background_color
        bg.r, bg.g, bg.b, bg.a = 0.0, 0.0, 0.0, 0.6
        msg.texts.append(text)
    return msg


def detection_annotations(dets: Detections, stamp_ns: int | None = None) -> ImageAnnotations:
    """A detections message as image annotations: one green box per detection labelled with its
    class and score (``person 0.87``), stamped ``stamp_ns`` (default: the detections' time)."""
    boxes = (
        ImageBox(d.box.x_px, d.box.y_px, d.box.w_px, d.box.h_px, f"{d.label} {d.score:.2f}")
        for d in dets.detections
    )
    return image_annotations(dets.t_ns if stamp_ns is None else stamp_ns, boxes)
