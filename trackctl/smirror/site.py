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
from trackctl.ingest.site import SITE_RANGES, floorplan_from_json, record_number, warn_site_defaults
from trackctl.logs import topics
from trackctl.logs.messages import CameraModel, WheelOdometry
from trackctl.logs.reader import LogReader
from trackctl.smirror.config import Mode, SmirrorConfig
from trackctl.smirror.node import MirrorNode
from trackctl.smirror.robot import LedConfig

__all__ = [
    "Coverage",
    "RobotSite",
    "Site",
    "load_site",
    "camera_models",
    "robot_names",
    "floorplan",
]


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
                cam.position[:2], np.array([x, y]), self.plan.wall_array
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


def robot_names(reader: LogReader, cfg: SmirrorConfig) -> list[str]:
    """The robots to localize: ``cfg.robot``, else every ``robot/<NAME>`` record (or, without
    any, every robot odometry topic)."""
    if cfg.robot:
        return [cfg.robot]
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
    return names


def floorplan(reader: LogReader, metadata: Mapping[str, Mapping[str, str]]) -> FloorPlan | None:
    md = metadata.get("smirror/floorplan")
    if not md or "plan" not in md:
        return None
    where = f"{reader.path}: metadata smirror/floorplan"
    try:
        obj = json.loads(md["plan"])
    except (ValueError, RecursionError) as err:
        raise InputError(f"{where}: plan is not JSON ({err})") from None
    return floorplan_from_json(obj, f"{where} plan")


_ROBOT_KEYS = ("led_height_m", "led_front_m", "led_back_m", "ticks_per_m", "wheel_base_m")


def _hue(
    values: Mapping[str, str], key: str, default: tuple[int, int], where: str
) -> tuple[int, int]:
    """An OpenCV hue range ``LO-HI`` (0..180) from a robot record, ``default`` when absent."""
    if key not in values:
        return default
    try:
        lo, hi = (int(v) for v in str(values[key]).split("-"))
    except ValueError:
        raise InputError(
            f"{where}: {key}={values[key]!r} is not a hue range LO-HI (OpenCV hue, 0..180)"
        ) from None
    if not 0 <= lo <= hi <= 180:
        raise InputError(f"{where}: {key}={values[key]!r}: need 0 <= LO <= HI <= 180")
    return lo, hi


def _warn_defaults(
    reader: LogReader,
    robots: list[tuple[str, Mapping[str, str], LedConfig, DiffDrive]],
    plan: FloorPlan | None,
) -> None:
    """One warning naming every site value the log does not give and the default used."""
    parts = []
    for robot, rmd, led, drive in robots:
        values = {
            "led_height_m": led.led_height_m,
            "led_front_m": led.led_front_m,
            "led_back_m": led.led_back_m,
            "ticks_per_m": drive.ticks_per_m,
            "wheel_base_m": drive.wheel_base_m,
        }
        missing = [f"{k}={values[k]:g}" for k in _ROBOT_KEYS if k not in rmd]
        if missing:
            parts.append(f"robot/{robot} {', '.join(missing)}")
    colours: dict[tuple[tuple[int, int], tuple[int, int]], list[str]] = {}
    for robot, _, led, _ in robots:
        colours.setdefault((led.front_hue, led.back_hue), []).append(robot)
    for same in colours.values():
        if len(same) > 1:
            parts.append(
                f"robots {', '.join(same)} carry the same LED colours (front_hue/back_hue): each "
                "tells its LEDs from the others' only by its own predicted position"
            )
    if plan is None:
        parts.append("no smirror/floorplan (walls do not block the nodes' views)")
    warn_site_defaults(reader.path, parts)


def metadata_float(values: Mapping[str, str], key: str, default: float, where: str) -> float:
    """A finite number from a metadata record, ``default`` when the key is absent (a site key is
    checked against its range, :data:`trackctl.ingest.site.SITE_RANGES`)."""
    if key in SITE_RANGES:
        return record_number(values, key, default, where)
    if key not in values:
        return default
    try:
        value = float(values[key])
    except ValueError:
        raise InputError(f"{where}: {key}={values[key]!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: {key}={values[key]!r} is not finite")
    return value


@dataclass(frozen=True)
class RobotSite:
    """One robot of the site: its name, odometry topic, LEDs and wheels."""

    name: str
    odom_topic: str
    led: LedConfig
    drive: DiffDrive


@dataclass
class Site:
    """Everything a run needs to know about the log's site before the first message."""

    models: dict[str, CameraModel]
    robots: list[RobotSite]
    """The robots this run localizes (each asks the nodes for images)."""
    use_odom: bool
    requesters: int
    """Robots requesting images: ours plus others that are traffic only (at least ours)."""
    cams: dict[str, PinholeCamera]
    nodes: dict[str, MirrorNode]
    cover: Coverage
    start: tuple[float, float, float] | None
    """The robot's known start pose (``--start``, a dock); None: unknown, found by the nodes."""

    @property
    def image_topics(self) -> list[str]:
        """The nodes' image topics."""
        return [topics.image(n) for n in self.models]


def _robot(
    reader: LogReader, metadata: Mapping[str, Mapping[str, str]], robot: str
) -> tuple[RobotSite, Mapping[str, str]]:
    rmd = metadata.get(f"robot/{robot}", {})
    where = f"{reader.path}: metadata robot/{robot}"
    led_default, drive_default = LedConfig(), DiffDrive()
    led = LedConfig(
        led_height_m=metadata_float(rmd, "led_height_m", led_default.led_height_m, where),
        led_front_m=metadata_float(rmd, "led_front_m", led_default.led_front_m, where),
        led_back_m=metadata_float(rmd, "led_back_m", led_default.led_back_m, where),
        front_hue=_hue(rmd, "front_hue", led_default.front_hue, where),
        back_hue=_hue(rmd, "back_hue", led_default.back_hue, where),
    )
    drive = DiffDrive(
        metadata_float(rmd, "ticks_per_m", drive_default.ticks_per_m, where),
        metadata_float(rmd, "wheel_base_m", drive_default.wheel_base_m, where),
    )
    return RobotSite(robot, topics.odom(robot), led, drive), rmd


def load_site(reader: LogReader, cfg: SmirrorConfig) -> Site:
    """The site of ``reader``'s log.

    Raises:
        MissingTopicError: no node camera, no robot, or (mirror+odom) no odometry for a robot.
        InputError: malformed robot metadata or floor plan; ``--start`` with several robots.
    """
    models = camera_models(reader)
    names = robot_names(reader, cfg)
    present = reader.topics()
    use_odom = cfg.mode is Mode.MIRROR_ODOM
    metadata = {**reader.metadata(), **cfg.site}
    robots = [_robot(reader, metadata, name) for name in names]
    if use_odom:
        for robot, _ in robots:
            if robot.odom_topic not in present:
                raise MissingTopicError(
                    f"{reader.path}: {robot.odom_topic} is missing: smirror --mode mirror+odom "
                    f"dead-reckons robot {robot.name!r} with its wheel odometry (use --mode "
                    "centralized for vision only, or --robot to choose another robot)"
                )
    if cfg.start is not None and len(robots) > 1:
        raise InputError(
            f"{reader.path}: --start gives one robot's start pose, but the log has robots "
            f"{', '.join(names)}; choose one with --robot"
        )
    n_req = cfg.requesters or int(
        record_number(
            {"requesters": v} if (v := metadata.get("smirror/requesters", {}).get("count")) else {},
            "requesters",
            1,
            f"{reader.path}: metadata smirror/requesters",
        )
    )
    plan = floorplan(reader, metadata)
    _warn_defaults(reader, [(r.name, rmd, r.led, r.drive) for r, rmd in robots], plan)
    cams = {n: PinholeCamera(m) for n, m in models.items()}
    nodes = {n: MirrorNode(m, cfg.node) for n, m in models.items()}
    return Site(
        models=models,
        robots=[r for r, _ in robots],
        use_odom=use_odom,
        requesters=max(n_req, len(robots)),
        cams=cams,
        nodes=nodes,
        cover=Coverage(cams, plan, cfg, robots[0][0].led.led_height_m),
        start=cfg.start,
    )
