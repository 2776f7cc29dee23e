"""The site of an S-Mirror run, read from the log: node cameras, the robot, its LEDs and wheels,
the floor plan, and which node covers a ground point."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from trackctl.errors import InputError, MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.geometry.floorplan import FloorPlan, line_of_sight
from trackctl.geometry.odometry import DiffDrive
from trackctl.ingest.site import warn_site_defaults
from trackctl.logs import topics
from trackctl.logs.messages import CameraModel, WheelOdometry
from trackctl.logs.reader import LogReader
from trackctl.smirror.config import Mode, SmirrorConfig
from trackctl.smirror.node import MirrorNode
from trackctl.smirror.robot import LedConfig

__all__ = ["Coverage", "Site", "load_site", "camera_models", "robot_name", "floorplan"]


class Coverage:
    """Which node sees a ground point (calibrated camera, image bounds, range, walls)."""

    def __init__(
        self, cams: dict[str, PinholeCamera], plan: FloorPlan | None, cfg: SmirrorConfig, z: float
    ) -> None:
        self.cams, self.plan, self.cfg, self.z = cams, plan, cfg, z

    def covering(self, xy: Iterable[float], only: str | None = None) -> tuple[str, float] | None:
        """(node, ground range) of the nearest node covering ``xy``, or None."""
        x, y = xy
        best: tuple[str, float] | None = None
        for name, cam in self.cams.items():
            if only is not None and name != only:
                continue
            rng = math.hypot(x - cam.position[0], y - cam.position[1])
            if rng > self.cfg.max_range_m or (best is not None and rng >= best[1]):
                continue
            px, front = cam.project(np.array([[x, y, self.z]]))
            m, (u, v) = self.cfg.margin_px, px[0]
            mod = cam.model
            if not (front[0] and m <= u < mod.width_px - m and m <= v < mod.height_px - m):
                continue
            if self.plan is not None and not line_of_sight(
                cam.position[:2], np.array([x, y]), self.plan.walls
            ):
                continue
            best = (name, rng)
        return best


def camera_models(reader: LogReader) -> dict[str, CameraModel]:
    present = reader.topics()
    names = sorted(
        t.split("/")[1]
        for t, info in present.items()
        if info.schema_name == CameraModel.SCHEMA and t.endswith("/camera_model")
    )
    out: dict[str, CameraModel] = {}
    for name in names:
        if topics.image(name) not in present:
            continue
        for m in reader.messages([topics.camera_model(name)]):
            if m.message.world_from_camera is not None:
                out[name] = m.message
            break
    if not out:
        raise MissingTopicError(
            f"{reader.path}: no node camera (/<node>/image with a /<node>/camera_model holding "
            "its world pose); smirror needs the nodes' frames and calibrated cameras"
        )
    return out


def robot_name(reader: LogReader, cfg: SmirrorConfig) -> str:
    if cfg.robot:
        return cfg.robot
    records = {**reader.metadata(), **cfg.site}
    names = sorted(k.split("/", 1)[1] for k in records if k.startswith("robot/"))
    if not names:
        names = sorted(
            t.split("/")[2]
            for t, info in reader.topics().items()
            if info.schema_name == WheelOdometry.SCHEMA and t.startswith("/robot/")
        )
    if not names:
        raise MissingTopicError(
            f"{reader.path}: no robot: neither robot/<NAME> metadata nor a {topics.odom('<NAME>')} "
            "topic; smirror localizes a robot carrying two LEDs"
        )
    if len(names) > 1:
        raise InputError(
            f"{reader.path}: several robots ({', '.join(names)}); choose one with --robot"
        )
    return names[0]


def floorplan(reader: LogReader, metadata: Mapping[str, Mapping[str, str]]) -> FloorPlan | None:
    md = metadata.get("smirror/floorplan")
    if not md or "plan" not in md:
        return None
    try:
        return FloorPlan.from_json(json.loads(md["plan"]))
    except (ValueError, KeyError, TypeError) as err:
        raise InputError(f"{reader.path}: metadata smirror/floorplan is malformed: {err}") from err


_ROBOT_KEYS = ("led_height_m", "led_front_m", "led_back_m", "ticks_per_m", "wheel_base_m")


def _warn_defaults(
    reader: LogReader,
    robot: str,
    rmd: Mapping[str, str],
    led: LedConfig,
    drive: DiffDrive,
    plan: FloorPlan | None,
) -> None:
    """One warning naming every site value the log does not give and the default used."""
    values = {
        "led_height_m": led.led_height_m,
        "led_front_m": led.led_front_m,
        "led_back_m": led.led_back_m,
        "ticks_per_m": drive.ticks_per_m,
        "wheel_base_m": drive.wheel_base_m,
    }
    missing = [f"{k}={values[k]:g}" for k in _ROBOT_KEYS if k not in rmd]
    parts = []
    if missing:
        parts.append(f"robot/{robot} {', '.join(missing)}")
    if plan is None:
        parts.append("no smirror/floorplan (walls do not block the nodes' views)")
    warn_site_defaults(reader.path, parts)


def metadata_float(values: Mapping[str, str], key: str, default: float, where: str) -> float:
    """A finite number from a metadata record, ``default`` when the key is absent."""
    if key not in values:
        return default
    try:
        value = float(values[key])
    except ValueError:
        raise InputError(f"{where}: {key}={values[key]!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: {key}={values[key]!r} is not finite")
    return value


@dataclass
class Site:
    """Everything a run needs to know about the log's site before the first message."""

    models: dict[str, CameraModel]
    robot: str
    odom_topic: str
    use_odom: bool
    led: LedConfig
    drive: DiffDrive
    requesters: int
    cams: dict[str, PinholeCamera]
    nodes: dict[str, MirrorNode]
    cover: Coverage
    start: tuple[float, float, float] | None
    """The robot's known start pose (``--start``, a dock); None: unknown, found by the nodes."""

    @property
    def image_topics(self) -> list[str]:
        """The nodes' image topics."""
        return [topics.image(n) for n in self.models]


def load_site(reader: LogReader, cfg: SmirrorConfig) -> Site:
    """The site of ``reader``'s log.

    Raises:
        MissingTopicError: no node camera, no robot, or (mirror+odom) no odometry for the robot.
        InputError: malformed robot metadata or floor plan.
    """
    models = camera_models(reader)
    robot = robot_name(reader, cfg)
    present = reader.topics()
    odom_topic = topics.odom(robot)
    use_odom = cfg.mode is Mode.MIRROR_ODOM
    if use_odom and odom_topic not in present:
        raise MissingTopicError(
            f"{reader.path}: {odom_topic} is missing: smirror --mode mirror+odom dead-reckons "
            f"robot {robot!r} with its wheel odometry (use --mode centralized for vision only)"
        )
    metadata = {**reader.metadata(), **cfg.site}
    rmd = metadata.get(f"robot/{robot}", {})
    where = f"{reader.path}: metadata robot/{robot}"
    led_default, drive_default = LedConfig(), DiffDrive()
    led = LedConfig(
        led_height_m=metadata_float(rmd, "led_height_m", led_default.led_height_m, where),
        led_front_m=metadata_float(rmd, "led_front_m", led_default.led_front_m, where),
        led_back_m=metadata_float(rmd, "led_back_m", led_default.led_back_m, where),
    )
    drive = DiffDrive(
        metadata_float(rmd, "ticks_per_m", drive_default.ticks_per_m, where),
        metadata_float(rmd, "wheel_base_m", drive_default.wheel_base_m, where),
    )
    n_req = cfg.requesters or int(metadata.get("smirror/requesters", {}).get("count", 1))
    plan = floorplan(reader, metadata)
    _warn_defaults(reader, robot, rmd, led, drive, plan)
    cams = {n: PinholeCamera(m) for n, m in models.items()}
    nodes = {n: MirrorNode(m, cfg.node) for n, m in models.items()}
    return Site(
        models=models,
        robot=robot,
        odom_topic=odom_topic,
        use_odom=use_odom,
        led=led,
        drive=drive,
        requesters=n_req,
        cams=cams,
        nodes=nodes,
        cover=Coverage(cams, plan, cfg, led.led_height_m),
        start=cfg.start,
    )
