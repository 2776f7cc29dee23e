"""S-Mirror scenarios (dissertation §4.1.3): three rooms, three node cameras, patrolling robots.

A differential-drive robot with wheel encoders (per-wheel scale error and slip) and two LEDs
(front green, back magenta) patrols predefined ~40 m loops from a home point in the middle room,
with segments inside and outside the nodes' views; people walk in the rooms (random waypoint) and
may occlude it. Each node camera's frames are rendered (real pixels, JPEG) at the node rate; the
nodes publish their *calibrated* camera model, which differs from the true pose by a small
calibration error, as a real calibration would. Same seed, same bytes.

Topics: ``/<node>/image`` (foxglove.CompressedImage), ``/<node>/camera_model``,
``/<node>/calibration``, ``/robot/rK/odom`` (trackctl.WheelOdometry, 25 Hz, one per robot of
the fleet: r1, r2, r3), ``/ground_truth`` (12.5 Hz). Metadata: ``scenario``, ``robot/rK``
(wheels and LEDs),
``smirror/floorplan`` (walls), ``smirror/requesters`` (how many robots request node images).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from trackctl.geometry.camera import PinholeCamera, ideal_camera, look_at
from trackctl.ingest.calibration import to_foxglove_calibration
from trackctl.ingest.video import make_compressed_image
from trackctl.logs import topics
from trackctl.logs.messages import (
    CameraModel,
    GroundTruth,
    GroundTruthEntity,
    Quat,
    Transform,
    Vec3,
    WheelOdometry,
)
from trackctl.logs.writer import LogWriter
from trackctl.sim.lens import LensDistortion
from trackctl.sim.smirror_render import FloorPlan, NodeRenderer, RobotShape, three_rooms
from trackctl.sim.walkers import Trajectory, random_waypoint

__all__ = ["SmirrorScenario", "simulate_smirror", "PATHS", "HOME", "NODES", "path_length_m"]

S = 1_000_000_000
HOME = (13.5, 4.0)
"""The robot's dock in the middle room; every patrol path starts and ends here."""

PATHS: tuple[tuple[tuple[float, float], ...], ...] = (
    # B -> A: along the bottom of B, through the door, a loop in A, back
    (
        (16.0, 4.0),
        (16.0, 1.3),
        (11.0, 1.3),
        (11.0, 4.0),
        (5.0, 4.0),
        (5.0, 1.5),
        (1.5, 1.5),
        (1.5, 4.0),
        HOME,
    ),
    # B -> C: top of B, through both doors, a loop in C, back
    (
        (13.5, 6.6),
        (11.0, 6.6),
        (11.0, 4.0),
        (21.5, 4.0),
        (21.5, 1.5),
        (24.0, 1.5),
        (24.0, 6.3),
        (21.0, 6.3),
        (21.0, 4.0),
        HOME,
    ),
    # a figure through A's far side and B's corners
    (
        (10.5, 4.0),
        (10.5, 7.0),
        (15.5, 7.0),
        (15.5, 4.0),
        (7.5, 4.0),
        (7.5, 6.8),
        (3.0, 6.8),
        (3.0, 4.0),
        HOME,
    ),
    # C's near corner and B's bottom
    (
        (19.5, 4.0),
        (19.5, 1.2),
        (25.0, 1.2),
        (25.0, 4.0),
        (16.8, 4.0),
        (16.8, 1.8),
        (10.2, 1.8),
        (10.2, 4.0),
        HOME,
    ),
)
"""Four ~40 m patrol loops (waypoints after HOME)."""

NODES: tuple[tuple[str, tuple[float, float, float], tuple[float, float, float]], ...] = (
    ("node0", (0.15, 0.15, 3.0), (6.2, 5.0, 0.0)),
    ("node1", (9.15, 7.85, 3.0), (15.2, 2.6, 0.0)),
    ("node2", (26.85, 0.15, 3.0), (20.8, 5.0, 0.0)),
)
"""Node cameras: name, eye (m), look-at target (m). Corner mounts at 3 m, one per room."""


class FleetRobot(NamedTuple):
    """One robot of the simulated fleet: dock (m), LED colours (BGR) and hue ranges (LO-HI)."""

    dock: tuple[float, float]
    front_bgr: tuple[int, int, int]
    front_hue: str
    back_bgr: tuple[int, int, int]
    back_hue: str


FLEET = (
    FleetRobot((13.5, 4.0), (60, 255, 60), "45-80", (255, 60, 255), "135-170"),
    FleetRobot((13.5, 5.6), (40, 230, 255), "20-34", (255, 110, 30), "100-125"),
    FleetRobot((13.5, 2.4), (255, 255, 40), "84-98", (40, 40, 255), "0-8"),
)
"""The robots of a fleet: dock (m), front LED colour (BGR) and hue range (OpenCV 0..180), back
LED colour and hue range. r1 is the paper's robot (green front, magenta back); the others carry
other colour pairs so that each robot tells its own LEDs from the others' (yellow/blue,
cyan/red)."""


def path_length_m(k: int) -> float:
    """Length of patrol loop ``k`` (metres)."""
    pts = [HOME, *PATHS[k]]
    return float(sum(math.dist(a, b) for a, b in zip(pts[:-1], pts[1:], strict=True)))


@dataclass(frozen=True, slots=True)
class SmirrorScenario:
    """Parameters of an S-Mirror scenario."""

    paths: int = 4
    people: int = 6
    requesters: int = 1
    """Robots requesting node images: the fleet's robots plus others (traffic only)."""
    robots: int = 1
    """Robots that patrol, are rendered and log odometry (1..3, :data:`FLEET`); robot k starts
    10 s after robot k-1, from its own dock, on the loops in turn from loop k."""
    seed: int = 0
    fps: float = 5.0
    width_px: int = 640
    height_px: int = 480
    hfov_deg: float = 50.0
    jpeg_quality: int = 80
    noise_sigma: float = 2.0
    odom_hz: float = 25.0
    speed_mps: float = 0.5
    turn_rps: float = 0.8
    ticks_per_m: float = 2000.0
    wheel_base_m: float = 0.30
    wheel_scale: tuple[float, float] = (1.004, 0.997)
    """Systematic scale of the left/right encoder (wheel radius error)."""
    slip_sigma: float = 0.03
    """Relative random slip of each wheel increment."""
    turn_slip: float = 0.03
    """Wheels slip on turns in place: the true rotation falls short of the encoders by this."""
    calib_rot_deg: float = 0.15
    calib_pos_m: float = 0.02
    distortion_k1: float = 0.0
    """Radial lens distortion of the node cameras (OpenCV k1; -0.2 is a wide-angle webcam):
    frames are rendered through it and the logged calibration carries it."""
    led_clothes: float = 0.0
    """Share of people dressed in the LEDs' colours (green or magenta shirts): clutter that the
    LED detector can mistake for the robot."""
    dock_s: float = 3.0
    duration_s: float | None = None
    """Cut the patrol after this many seconds (short logs for tests); None: all of it."""

    def __post_init__(self) -> None:
        if not 1 <= self.paths <= len(PATHS):
            raise ValueError(f"paths must be 1..{len(PATHS)}, got {self.paths}")
        if self.people < 0 or self.requesters < 1:
            raise ValueError("people must be >= 0 and requesters >= 1")
        if not 1 <= self.robots <= len(FLEET):
            raise ValueError(f"robots must be 1..{len(FLEET)}, got {self.robots}")
        if self.fps <= 0 or self.fps > self.odom_hz:
            raise ValueError(f"fps must be in (0, {self.odom_hz}], got {self.fps}")


def _drive(cfg: SmirrorScenario, robot: int = 0) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """True poses (n, 3) and true wheel increments (n, 2) on the odometry grid, path start times,
    of robot ``robot`` of the fleet."""
    dt = 1.0 / cfg.odom_hz
    half_b = cfg.wheel_base_m / 2
    dock = FLEET[robot].dock
    poses = [(dock[0], dock[1], 0.0)]
    incs = [(0.0, 0.0)]
    starts: list[float] = []

    def stay(seconds: float) -> None:
        for _ in range(int(round(seconds / dt))):
            poses.append(poses[-1])
            incs.append((0.0, 0.0))

    stay(cfg.dock_s + 10.0 * robot)
    for j in range(cfg.paths):
        k = (j + robot) % len(PATHS)
        starts.append(len(poses) * dt)
        for wx, wy in PATHS[k]:
            x, y, yaw = poses[-1]
            target = math.atan2(wy - y, wx - x)
            turn = (target - yaw + math.pi) % (2 * math.pi) - math.pi
            steps = int(math.ceil(abs(turn) / (cfg.turn_rps * dt)))
            for _ in range(steps):
                d = turn / steps
                x, y, yaw = poses[-1]
                poses.append((x, y, yaw + d))
                incs.append((-d * half_b, d * half_b))
            x, y, yaw = poses[-1]
            dist = math.hypot(wx - x, wy - y)
            steps = int(math.ceil(dist / (cfg.speed_mps * dt)))
            for i in range(1, steps + 1):
                poses.append((x + (wx - x) * i / steps, y + (wy - y) * i / steps, yaw))
                incs.append((dist / steps, dist / steps))
        stay(1.0)
    return np.array(poses), np.array(incs), starts


def _odometry(cfg: SmirrorScenario, incs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Cumulative encoder ticks (n, 2) as the wheels would count them."""
    meas = incs * np.array(cfg.wheel_scale)
    meas = meas * (1.0 + rng.normal(0.0, cfg.slip_sigma, meas.shape))
    turning = np.sign(incs[:, 0]) != np.sign(incs[:, 1])
    # on a turn in place the wheels scrub: encoders count more rotation than the body makes
    meas[turning] *= 1.0 + cfg.turn_slip
    return np.floor(np.cumsum(meas * cfg.ticks_per_m, axis=0)).astype(np.int64)


def _calibrated(true: CameraModel, rng: np.random.Generator, cfg: SmirrorScenario) -> CameraModel:
    """The model a real calibration would give: the true pose plus a small error."""
    pose = true.world_from_camera
    assert pose is not None
    err = Rotation.from_rotvec(rng.normal(0, math.radians(cfg.calib_rot_deg), 3))
    rot = err * Rotation.from_quat(list(pose.rotation))
    t = np.array(pose.translation) + rng.normal(0, cfg.calib_pos_m, 3)
    return replace(
        true,
        world_from_camera=Transform(Vec3(*map(float, t)), Quat(*map(float, rot.as_quat()))),
    )


def node_models(cfg: SmirrorScenario) -> list[CameraModel]:
    """True camera models of the three nodes."""
    return [
        ideal_camera(
            name,
            cfg.width_px,
            cfg.height_px,
            look_at(np.array(eye), np.array(target)),
            hfov_deg=cfg.hfov_deg,
            distortion=(cfg.distortion_k1, 0.0, 0.0, 0.0, 0.0),
        )
        for name, eye, target in NODES
    ]


_LED_CLOTHES = [(70, 200, 60), (200, 60, 200)]  # BGR: a bright green and a magenta shirt


def _clothes(cfg: SmirrorScenario) -> list[tuple[int, int, int]]:
    """Each person's shirt colour; ``led_clothes`` of them in the LEDs' colours."""
    n_led = int(round(cfg.led_clothes * cfg.people))
    return [
        _LED_CLOTHES[k % 2] if k < n_led else _CLOTHES[k % len(_CLOTHES)] for k in range(cfg.people)
    ]


def _people(cfg: SmirrorScenario, plan: FloorPlan, duration_s: float, rng: np.random.Generator):
    out = []
    for i in range(cfg.people):
        x0, y0, x1, y1 = plan.rooms[i % len(plan.rooms)]
        trj = random_waypoint(f"p{i}", rng, (x1 - x0, y1 - y0), duration_s + 1.0, dt_s=0.04)
        out.append((f"p{i}", trj, x0, y0))
    return out


_CLOTHES = [
    (60, 70, 140),
    (120, 90, 60),
    (70, 110, 80),
    (100, 100, 110),
    (40, 60, 90),
    (130, 120, 100),
]


def _fleet(
    cfg: SmirrorScenario, poses: np.ndarray, ticks: np.ndarray, rng: np.random.Generator
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(true poses, encoder ticks) of every robot on r1's clock: the others cut where r1's log
    ends, or parked at their end."""
    n = len(poses)
    fleet = [(poses, ticks)]
    for k in range(1, cfg.robots):
        p_k, inc_k, _ = _drive(cfg, k)
        t_k = _odometry(cfg, inc_k, rng)
        pad = max(0, n - len(p_k))
        fleet.append(
            (
                np.vstack([p_k, np.repeat(p_k[-1:], pad, axis=0)])[:n],
                np.vstack([t_k, np.repeat(t_k[-1:], pad, axis=0)])[:n],
            )
        )
    return fleet


class _CountingWriter:
    """A log writer that counts the messages it writes per topic."""

    def __init__(self, writer: LogWriter) -> None:
        self.writer = writer
        self.counts: dict[str, int] = {}

    def put(self, topic: str, msg: object, t_ns: int) -> None:
        self.writer.write(topic, msg, t_ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1


@dataclass(frozen=True, slots=True)
class _Patrol:
    """r1's true poses and encoder ticks on the odometry grid, and its path start times (s),
    cut to ``duration_s``."""

    poses: np.ndarray
    ticks: np.ndarray
    starts: list[float]


def _patrol(cfg: SmirrorScenario, rng: np.random.Generator) -> _Patrol:
    """Drive r1 and count its encoders, cut after ``duration_s`` (at least two steps)."""
    poses, incs, starts = _drive(cfg)
    ticks = _odometry(cfg, incs, rng)
    if cfg.duration_s is not None:
        dt = 1.0 / cfg.odom_hz
        keep = max(2, int(cfg.duration_s * cfg.odom_hz))
        poses, ticks = poses[:keep], ticks[:keep]
        starts = [s for s in starts if s < keep * dt]
    return _Patrol(poses, ticks, starts)


@dataclass(frozen=True, slots=True)
class _Scene:
    """Everything the time loop draws and logs: the fleet, the people, the node cameras."""

    dt: float
    """Odometry step (s)."""
    names: list[str]
    """Robot names, r1 first, by fleet index."""
    fleet: list[tuple[np.ndarray, np.ndarray]]
    """(true poses, encoder ticks) of every robot on the odometry grid."""
    shapes: list[RobotShape]
    walkers: list[tuple[str, Trajectory, float, float]]
    """(name, trajectory in its room, room origin x, y) of every person."""
    shirts: list[tuple[int, int, int]]
    true_models: list[CameraModel]
    calib_models: list[CameraModel]
    renderers: list[NodeRenderer]
    lenses: list[LensDistortion]

    @property
    def n(self) -> int:
        """Odometry steps in the log."""
        return len(self.fleet[0][0])

    def person_xy(self, k: int, t: float) -> np.ndarray:
        """Where person ``k`` is at ``t`` (site frame)."""
        _, trj, x0, y0 = self.walkers[k]
        return trj.at(t)[0] + (x0, y0)

    def robot_pose(self, k: int, t: float) -> np.ndarray:
        """Robot ``k``'s true pose at ``t``, interpolated between odometry steps."""
        n = self.n
        f = min(t / self.dt, n - 1.0)
        i = min(int(f), n - 2)
        a = f - i
        p_k = self.fleet[k][0]
        return p_k[i] * (1 - a) + p_k[i + 1] * a


def _scene(
    cfg: SmirrorScenario, patrol: _Patrol, plan: FloorPlan, rng: np.random.Generator
) -> _Scene:
    """The fleet, node calibrations, people and renderers, drawn from ``rng`` in that order."""
    dt = 1.0 / cfg.odom_hz
    duration_s = len(patrol.poses) * dt
    fleet = _fleet(cfg, patrol.poses, patrol.ticks, rng)
    names = [f"r{k + 1}" for k in range(cfg.robots)]
    shapes = [
        replace(RobotShape(), front_bgr=FLEET[k].front_bgr, back_bgr=FLEET[k].back_bgr)
        for k in range(cfg.robots)
    ]
    # calibration errors are drawn before the people, so logs with and without people differ in
    # nothing else (the occlusion experiment of Figs. 4.8-4.10)
    true_models = node_models(cfg)
    calib_models = [_calibrated(m, rng, cfg) for m in true_models]
    walkers = _people(cfg, plan, duration_s, rng)
    # drawn through an ideal pinhole, then warped by the lens
    renderers = [
        NodeRenderer(PinholeCamera(replace(m, distortion=(0.0,) * 5)), plan, rng, cfg.noise_sigma)
        for m in true_models
    ]
    lenses = [LensDistortion(m) for m in true_models]
    return _Scene(
        dt,
        names,
        fleet,
        shapes,
        walkers,
        _clothes(cfg),
        true_models,
        calib_models,
        renderers,
        lenses,
    )


def _write_header(
    log: _CountingWriter, cfg: SmirrorScenario, scene: _Scene, plan: FloorPlan, starts: list[float]
) -> None:
    """Scenario, robot, floor-plan and requester metadata; the nodes' calibrated models."""
    w = log.writer
    shape = scene.shapes[0]
    w.add_metadata(
        "scenario",
        {
            "generator": "trackctl simulate smirror",
            "seed": cfg.seed,
            "paths": cfg.paths,
            "people": cfg.people,
            "requesters": max(cfg.requesters, cfg.robots),
            "robots": cfg.robots,
            "fps": cfg.fps,
            "path_start_s": json.dumps([round(s, 3) for s in starts]),
            "path_length_m": json.dumps([round(path_length_m(k), 2) for k in range(cfg.paths)]),
        },
    )
    for k, name in enumerate(scene.names):
        robot_md: dict[str, object] = {
            "ticks_per_m": cfg.ticks_per_m,
            "wheel_base_m": cfg.wheel_base_m,
            "led_height_m": shape.led_height_m,
            "led_front_m": shape.led_front_m,
            "led_back_m": shape.led_back_m,
        }
        if k > 0:  # r1's colours are the defaults
            robot_md.update(front_hue=FLEET[k].front_hue, back_hue=FLEET[k].back_hue)
        w.add_metadata(f"robot/{name}", robot_md)
    w.add_metadata("smirror/floorplan", {"plan": json.dumps(plan.to_json())})
    w.add_metadata("smirror/requesters", {"count": max(cfg.requesters, cfg.robots)})
    for model in scene.calib_models:
        log.put(topics.calibration(model.camera), to_foxglove_calibration(model), 0)
        log.put(topics.camera_model(model.camera), model, 0)


def _write_frames(
    log: _CountingWriter,
    scene: _Scene,
    tf: float,
    rng: np.random.Generator,
    jpeg_quality: int,
) -> None:
    """Every node's JPEG frame at ``tf`` (s)."""
    tf_ns = int(round(tf * S))
    people = [(scene.person_xy(k, tf), scene.shirts[k]) for k in range(len(scene.walkers))]
    robots = [scene.robot_pose(k, tf) for k in range(len(scene.names))]
    for model, ren, lens in zip(scene.true_models, scene.renderers, scene.lenses, strict=True):
        img = lens.apply(ren.render(people, robots, scene.shapes, rng))
        ok, buf = cv2.imencode(".jpg", img, [int(cv2.IMWRITE_JPEG_QUALITY), jpeg_quality])
        assert ok
        log.put(
            topics.image(model.camera),
            make_compressed_image(tf_ns, model.camera, buf.tobytes(), "jpeg"),
            tf_ns,
        )


def _write_odometry(log: _CountingWriter, scene: _Scene, i: int, t_ns: int) -> None:
    """Every robot's encoder ticks at odometry step ``i``."""
    for name, (_, t_k) in zip(scene.names, scene.fleet, strict=True):
        log.put(
            topics.odom(name),
            WheelOdometry(t_ns, f"robot/{name}", int(t_k[i, 0]), int(t_k[i, 1])),
            t_ns,
        )


def _write_truth(log: _CountingWriter, scene: _Scene, i: int, t_ns: int) -> None:
    """The robots' true poses and the people's positions at odometry step ``i``."""
    ents = []
    for name, (p_k, _) in zip(scene.names, scene.fleet, strict=True):
        x, y, yaw = p_k[i]
        ents.append(GroundTruthEntity(name, Vec3(float(x), float(y), 0.0), float(yaw)))
    for k in range(len(scene.walkers)):
        p = scene.person_xy(k, i * scene.dt)
        ents.append(
            GroundTruthEntity(
                scene.walkers[k][0], Vec3(round(float(p[0]), 4), round(float(p[1]), 4), 0.0)
            )
        )
    log.put(topics.GROUND_TRUTH, GroundTruth(t_ns, tuple(ents)), t_ns)


def simulate_smirror(out: str, cfg: SmirrorScenario | None = None) -> dict[str, int]:
    """Write an S-Mirror scenario log to ``out``; returns message counts per topic."""
    cfg = cfg or SmirrorScenario()
    rng = np.random.default_rng(cfg.seed)
    plan = three_rooms()
    patrol = _patrol(cfg, rng)
    scene = _scene(cfg, patrol, plan, rng)
    n, dt = scene.n, scene.dt
    with LogWriter(out) as w:
        log = _CountingWriter(w)
        _write_header(log, cfg, scene, plan, patrol.starts)
        frame_dt = 1.0 / cfg.fps
        n_frames = int(n * dt / frame_dt)
        # One pass over time: odometry every step, truth every 2nd, frames at the node rate.
        step_ns = int(round(dt * S))
        next_frame = 0
        for i in range(n):
            t_ns = i * step_ns
            while next_frame < n_frames and int(round(next_frame * frame_dt * S)) <= t_ns:
                _write_frames(log, scene, next_frame * frame_dt, rng, cfg.jpeg_quality)
                next_frame += 1
            _write_odometry(log, scene, i, t_ns)
            if i % 2 == 0:
                _write_truth(log, scene, i, t_ns)
    return log.counts
