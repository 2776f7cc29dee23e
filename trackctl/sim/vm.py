"""VM-Tracking scenarios: people walking under calibrated cameras, some carrying phones.

Sensor models (documented in docs/vmtrack.md):

* cameras at ``fps`` (3): pinhole 640x480, mounted 3.5 m high on a grid over the field with small
  overlaps; a person is detected when foot and head are in the image, unless a nearer person's
  box covers more than half of theirs (occlusion) or the detector misses (``miss_rate``); the
  ground point carries a 2-D Gaussian error whose mean length is ``det_noise_m`` (0.35 m, the
  paper's visual noise); false positives appear with probability ``fp_rate`` per camera frame;
* phones at ``imu_hz`` (5): specific force in a device frame that yaws with the walking direction
  (gravity + horizontal acceleration + a vertical step bounce at cadence speed / 0.7 m), gyro with
  bias, and a rotation-vector orientation whose yaw drifts as a random walk; white noise on all;
* check-point APs at the entries: RSSI of every phone at 1 Hz, log-distance path loss
  (-40 dBm at 1 m, exponent 2.5) with 3 dB shadowing;
* ground truth at every frame time: position and the phone MAC (EID) of each person.

That is the ``paper`` preset: the dissertation's assumptions (phones report only in view, their
yaw is the walking direction, clocks agree, 0.7 m steps), kept for its tables. The default
``realistic`` preset replaces the phones by :mod:`trackctl.sim.phones` (carry, heading offsets,
gait, always-on phones, clock offsets, sample rates) and the detector and APs by
:class:`VmRealism`'s models; each draws from its own random stream.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import cv2
import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.spatial.transform import Rotation

from trackctl.errors import InputError
from trackctl.geometry.camera import PinholeCamera, ideal_camera, look_at
from trackctl.ingest.calibration import to_foxglove_calibration
from trackctl.ingest.video import make_compressed_image
from trackctl.logs import topics
from trackctl.logs.messages import (
    BBox,
    CameraModel,
    Detection,
    Detections,
    GroundTruth,
    GroundTruthEntity,
    Imu,
    Quat,
    RssiReading,
    RssiScan,
    Vec3,
)
from trackctl.logs.writer import LogWriter
from trackctl.sim.phones import PhoneRealism, PhoneTruth, realistic_imu
from trackctl.sim.render import PersonLook, floor_image, render_frame
from trackctl.sim.walkers import (
    SocialForce,
    Trajectory,
    load_trajectories_csv,
    longest_walkers,
    random_waypoint,
    random_waypoint_crowd,
)

__all__ = ["VmScenario", "VmRealism", "PRESETS", "simulate_vm", "FIELDS", "mac_of"]

G = 9.80665
S = 1_000_000_000
STEP_LENGTH_M = 0.7
PERSON_HEIGHT_M = 1.7
PERSON_WIDTH_M = 0.5

FIELDS = {"lobby": ((20.0, 15.0), (3, 2)), "office": ((6.0, 5.0), (2, 1))}
_MOUNT = {"lobby": (6.0, 0.5, 1.5), "office": (4.0, 1.5, 1.5)}


def mac_of(i: int) -> str:
    """The phone MAC of user ``i``."""
    return f"02:00:00:00:00:{i + 1:02x}"


@dataclass(frozen=True, slots=True)
class VmRealism:
    """What the ``realistic`` preset adds to the paper's detector and APs (``paper``: all off).

    * ``phones``: the phone models of :mod:`trackctl.sim.phones` (None: the paper's phones).
    * ``calib_bias_m``: each camera's ground points are off by a fixed N(0, this) per axis (a
      floor-point calibration at 1-2 px puts feet 0.1-0.2 m off at 10 m; measured with
      ``trackctl calib ground`` on the PETS view: up to 0.2 m at the far edge).
    * ``merge_m``: two people closer than this in one camera make one detection at their
      middle (non-maximum suppression of overlapping boxes merges people walking together).
    * ``miss_rate`` / ``miss_episode_s``: misses come in episodes (a person behind a pillar or
      in a dark spot for a while), a two-state Markov chain per camera and person with this
      stationary rate and mean episode length.
    * ``static_fps`` / ``static_fp_rate``: fixed places per camera (a poster, a plant) that the
      detector reports as a person in this share of frames.
    * ``avoid``: random-waypoint walkers avoid each other (:class:`~trackctl.sim.walkers.
      SocialForce`, Helbing and Molnar 1995); None: they walk through each other (the paper's
      simulation-style independent walkers).
    * ``rssi_at_1m_dbm``, ``path_loss_exponent``, ``shadowing_db``: each AP's path loss drawn
      from these ranges (indoor 2.0-3.5, Rappaport; per-device offsets of +-7 dB at 1 m), so
      the pipeline's default model is not the simulator's.
    * ``outside_wall_db``: an always-on phone whose carrier is out of view is still heard, from
      where their out-of-view walk took them, through the site's walls at this loss (COST 231
      multi-wall model: 3.4 dB a light wall, 6.9 dB a heavy one; 10 dB: two to three walls).
    """

    phones: PhoneRealism | None = None
    calib_bias_m: float = 0.0
    merge_m: float = 0.0
    miss_rate: float = 0.0
    miss_episode_s: float = 0.0
    static_fps: int = 0
    static_fp_rate: float = 0.0
    avoid: SocialForce | None = None
    rssi_at_1m_dbm: tuple[float, float] = (-40.0, -40.0)
    path_loss_exponent: tuple[float, float] = (2.5, 2.5)
    shadowing_db: float = 3.0
    outside_wall_db: float = 0.0


PRESETS: dict[str, VmRealism] = {
    "paper": VmRealism(),
    "realistic": VmRealism(
        phones=PhoneRealism(),
        calib_bias_m=0.15,
        merge_m=0.6,
        miss_rate=0.1,
        miss_episode_s=1.5,
        static_fps=1,
        static_fp_rate=0.3,
        avoid=SocialForce(),
        rssi_at_1m_dbm=(-47.0, -33.0),
        path_loss_exponent=(2.0, 3.5),
        shadowing_db=5.0,
        outside_wall_db=10.0,
    ),
}
"""``paper``: the dissertation's idealised setting, kept for its tables; ``realistic`` (the
default): the models of :class:`VmRealism` and :mod:`trackctl.sim.phones`."""


@dataclass(frozen=True, slots=True)
class VmScenario:
    """Parameters of a VM-Tracking scenario."""

    field: str = "lobby"
    users: int = 5
    nonusers: int = 2
    duration_s: float = 60.0
    speed_mps: tuple[float, float] = (0.5, 1.5)
    seed: int = 0
    fps: float = 3.0
    imu_hz: float = 5.0
    det_noise_m: float = 0.35
    miss_rate: float = 0.05
    fp_rate: float = 0.02
    heading_drift_deg_per_sqrt_s: float = 0.5
    trajectories: str | None = None
    phones: tuple[str, ...] = ()
    size_m: tuple[float, float] | None = None
    cameras_grid: tuple[int, int] | None = None
    frames: bool = False
    """Render JPEG frames (/camN/image) instead of writing simulated detections."""
    jpeg_quality: int = 60
    light_drop: float = 0.0
    """Rendered frames: the scene gets this much darker (0.25: 25%) from ``light_drop_at_s``."""
    light_drop_at_s: float = 60.0
    flicker: float = 0.0
    """Rendered frames: exposure gain of each frame uniform in 1 +- ``flicker``."""
    shadows: bool = False
    """Rendered frames: each person casts a shadow on the floor (a lamp at 50 deg elevation)."""
    standing_s: float = 0.0
    """An extra person (non-user ``s0``) walks in, stands still this long, and walks out."""
    preset: str = "realistic"
    """``realistic`` (default) or ``paper``: see :class:`VmRealism` and :data:`PRESETS`."""
    carry_yaw_deg: float | None = None
    """Realistic preset: every phone's device-to-walk yaw fixed to this (None: per carry)."""
    clock_offset_s: float | None = None
    """Realistic preset: phone clock offsets uniform in +- this (None: the preset's 2 s)."""

    @property
    def realism(self) -> VmRealism:
        """The preset's models with this scenario's overrides."""
        base = PRESETS[self.preset]
        if base.phones is None:
            return base
        phones = base.phones
        if self.carry_yaw_deg is not None:
            phones = replace(phones, carry_yaw_deg=self.carry_yaw_deg)
        if self.clock_offset_s is not None:
            phones = replace(phones, clock_offset_s=self.clock_offset_s)
        return replace(base, phones=phones)

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise InputError(f"--preset {self.preset!r}: expected one of {', '.join(PRESETS)}")
        if self.preset == "paper" and (
            self.carry_yaw_deg is not None or self.clock_offset_s is not None
        ):
            raise InputError(
                "--carry-yaw and --clock-offset model real phones: use --preset realistic"
            )
        if self.field not in FIELDS:
            raise InputError(f"--field {self.field!r}: expected one of {', '.join(FIELDS)}")
        if self.users < 0 or self.nonusers < 0:
            raise InputError("--users and --nonusers must be >= 0")
        if self.duration_s <= 0:
            raise InputError(f"--duration must be positive, got {self.duration_s}")
        if not 0 <= self.light_drop < 1:
            raise InputError(f"--light-drop must be in [0, 1), got {self.light_drop}")
        if not 0 <= self.flicker < 1:
            raise InputError(f"--flicker must be in [0, 1), got {self.flicker}")
        if self.standing_s < 0 or self.standing_s > self.duration_s:
            raise InputError(
                f"--standing {self.standing_s}: must be between 0 and --duration {self.duration_s}"
            )


@dataclass(frozen=True, slots=True)
class _Frame:
    """A camera frame to render when it is written."""

    cam: PinholeCamera
    t_s: float


def _cameras(
    size: tuple[float, float],
    grid: tuple[int, int],
    height_m: float = 6.0,
    back_m: float = 0.5,
    zoom_out: float = 1.5,
    width: int = 640,
    height: int = 480,
) -> list[CameraModel]:
    """One camera per grid tile, mounted ``back_m`` outside the field edge nearest its tile at
    ``height_m``, looking at the tile centre; the field of view spans ``zoom_out`` tiles, which
    covers the field with small overlaps (lobby: full coverage, about a third seen twice)."""
    nx, ny = grid
    tw, th = size[0] / nx, size[1] / ny
    out: list[Any] = []
    for j in range(ny):
        for i in range(nx):
            cx, cy = (i + 0.5) * tw, (j + 0.5) * th
            edge_y = -back_m if (j == 0 or ny == 1) else size[1] + back_m
            eye = np.array([cx, edge_y, height_m])
            target = np.array([cx, cy, 0.0])
            depth = float(np.linalg.norm(target - eye))
            f = 0.5 * width * depth / (0.5 * max(tw, 0.9 * th) * zoom_out)
            out.append(ideal_camera(f"cam{len(out)}", width, height, look_at(eye, target), f_px=f))
    return out


def _person_box(cam: PinholeCamera, xy: np.ndarray) -> tuple[BBox, float] | None:
    """Image box of a person standing at ``xy`` and its depth, or None when not fully visible."""
    foot = np.array([xy[0], xy[1], 0.0])
    head = np.array([xy[0], xy[1], PERSON_HEIGHT_M])
    px, front = cam.project(np.stack([foot, head]))
    if not front.all():
        return None
    (fx, fy), (hx, hy) = px
    depth = float(cam.to_camera(foot[None])[0, 2])
    h = fy - hy
    w = h * PERSON_WIDTH_M / PERSON_HEIGHT_M
    box = BBox(float(fx - w / 2), float(hy), float(w), float(h))
    m = cam.model
    if box.x_px < 0 or box.y_px < 0 or box.x_px + box.w_px > m.width_px or fy > m.height_px:
        return None
    return box, depth


def _overlap(a: BBox, b: BBox) -> float:
    """Share of ``a``'s area covered by ``b``."""
    ix = max(0.0, min(a.x_px + a.w_px, b.x_px + b.w_px) - max(a.x_px, b.x_px))
    iy = max(0.0, min(a.y_px + a.h_px, b.y_px + b.h_px) - max(a.y_px, b.y_px))
    return ix * iy / max(a.w_px * a.h_px, 1e-9)


def _people(
    cfg: VmScenario, rng: np.random.Generator, size: tuple[float, float]
) -> tuple[list[Trajectory], dict[str, str]]:
    if cfg.trajectories:
        trajs = load_trajectories_csv(cfg.trajectories)  # times from the first annotation
        known = {t.person for t in trajs}
        for p in cfg.phones:
            if p not in known:
                raise InputError(f"--phones: no trajectory with id {p!r} in {cfg.trajectories}")
        carriers = cfg.phones
        if not carriers:  # the ``users`` who walk farthest in the log carry phones
            t_end = max(float(t.t_s[-1]) for t in trajs)
            carriers = longest_walkers(trajs, min(cfg.duration_s, t_end), cfg.users)
        phones = {p: mac_of(i) for i, p in enumerate(carriers)}
        return trajs, phones
    names = [
        f"u{i}" if i < cfg.users else f"n{i - cfg.users}" for i in range(cfg.users + cfg.nonusers)
    ]
    phones = {name: mac_of(i) for i, name in enumerate(names[: cfg.users])}
    avoid = cfg.realism.avoid
    if avoid is not None:
        crowd = random_waypoint_crowd(
            names, rng, size, cfg.duration_s, speed_range=cfg.speed_mps, force=avoid
        )
        return crowd, phones
    trajs = [
        random_waypoint(name, rng, size, cfg.duration_s, speed_range=cfg.speed_mps)
        for name in names
    ]
    return trajs, phones


def _imu_samples(
    traj: Trajectory, mac: str, t_grid: np.ndarray, rng: np.random.Generator, cfg: VmScenario
) -> list[Imu]:
    """IMU of the phone carried along ``traj`` at times ``t_grid`` (inside the trajectory)."""
    vel = traj.velocity()
    acc = np.gradient(vel, traj.dt_s, axis=0)
    speed = np.linalg.norm(vel, axis=1)
    heading = np.arctan2(vel[:, 1], vel[:, 0])
    # keep the last heading while standing still
    moving = speed > 0.1
    for k in range(1, len(heading)):
        if not moving[k]:
            heading[k] = heading[k - 1]
    heading = np.unwrap(heading)
    yaw_rate = np.gradient(heading, traj.dt_s)
    # step phase: cadence = speed / step length
    phase = 2 * math.pi * np.cumsum(speed / STEP_LENGTH_M) * traj.dt_s
    idx = np.clip(np.round((t_grid - traj.t0_s) / traj.dt_s).astype(int), 0, len(traj.xy) - 1)
    drift_sigma = math.radians(cfg.heading_drift_deg_per_sqrt_s) * math.sqrt(1.0 / cfg.imu_hz)
    drift = np.cumsum(rng.normal(0, drift_sigma, len(t_grid)))
    gyro_bias = rng.normal(0, 0.01, 3)
    out = []
    frame = f"phone/{mac}"
    for k, i in enumerate(idx):
        yaw_dev = heading[i] + drift[k]
        rot = Rotation.from_euler("z", yaw_dev)
        bounce = 1.5 * min(speed[i], 1.5) * math.sin(phase[i])
        f_world = np.array([acc[i, 0], acc[i, 1], G + bounce])
        f_dev = rot.inv().apply(f_world) + rng.normal(0, 0.15, 3)
        gyro = np.array([0.0, 0.0, yaw_rate[i]]) + gyro_bias + rng.normal(0, 0.02, 3)
        q = rot.as_quat()
        t_ns = int(round(t_grid[k] * S))
        out.append(
            Imu(
                t_ns, frame, Vec3(*map(float, f_dev)), Vec3(*map(float, gyro)), Quat(*map(float, q))
            )
        )
    return out


def _entries(trajs: list[Trajectory], size: tuple[float, float], k: int = 2) -> list[np.ndarray]:
    """Where people enter the scene: the ``k`` densest spots among the trajectories' first
    points (the paper puts its check-point APs at the entries), by deterministic k-means."""
    first = np.array([t.xy[0] for t in trajs])
    if len(first) <= k:
        return [np.clip(p, 0.3, np.array(size) - 0.3) for p in first]
    # farthest-point initialisation from the first point keeps k-means deterministic
    centres = [first[0]]
    for _ in range(1, k):
        d = np.min([np.linalg.norm(first - c, axis=1) for c in centres], axis=0)
        centres.append(first[int(np.argmax(d))])
    cent, _ = kmeans2(first, np.array(centres), iter=20, minit="matrix")
    return [np.clip(c, 0.3, np.array(size) - 0.3) for c in cent]


Event = tuple[int, int, str, object]  # (t_ns, order among equal times, topic, message)


@dataclass
class _Site:
    """Field size, camera grid, people, phones, cameras and check-point APs of a scenario."""

    size: tuple[float, float]
    trajs: list[Trajectory]
    phones: dict[str, str]
    duration: float
    models: list[CameraModel]
    cams: list[PinholeCamera]
    aps: list[tuple[str, np.ndarray]]


def _site(cfg: VmScenario, rng: np.random.Generator) -> _Site:
    size, grid = FIELDS[cfg.field]
    if cfg.size_m is not None:
        size = cfg.size_m
    if cfg.cameras_grid is not None:
        grid = cfg.cameras_grid
    trajs, phones = _people(cfg, rng, size)
    if cfg.standing_s > 0:
        trajs.append(_stander(cfg, size))
    if cfg.trajectories:
        allxy = np.vstack([t.xy for t in trajs])
        lo, hi = allxy.min(axis=0) - 1.0, allxy.max(axis=0) + 1.0
        offset = -lo
        trajs = [replace(t, xy=t.xy + offset) for t in trajs]
        size = (float(hi[0] - lo[0]), float(hi[1] - lo[1]))
        grid = (max(1, round(size[0] / 7)), 2 if size[1] > 8 else 1)
    t_end = max(t.t0_s + t.dt_s * (len(t.xy) - 1) for t in trajs)
    duration = min(cfg.duration_s, t_end) if cfg.trajectories else cfg.duration_s
    models = _cameras(size, grid, *_MOUNT[cfg.field])
    aps = [
        ("ap-entry-0", np.array([0.3, size[1] / 2])),
        ("ap-entry-1", np.array([size[0] - 0.3, size[1] / 2])),
    ]
    if cfg.field == "office" and not cfg.trajectories:
        aps = aps[:1]
    if cfg.trajectories:
        aps = [(f"ap-entry-{k}", xy) for k, xy in enumerate(_entries(trajs, size))]
    cams = [PinholeCamera(m) for m in models]
    return _Site(size, trajs, phones, duration, models, cams, aps)


def _stander(cfg: VmScenario, size: tuple[float, float]) -> Trajectory:
    """A person who walks in from the field's left edge (1.2 m/s), stands still for
    ``standing_s`` in the field, and walks back out: a static person a background model must
    not absorb. Its own random stream keeps every other person and sensor unchanged."""
    rng = np.random.default_rng([cfg.seed, 7])
    dt = 0.05
    spot = np.array([rng.uniform(0.3, 0.7) * size[0], rng.uniform(0.3, 0.7) * size[1]])
    door = np.array([0.3, spot[1]])
    walk_s = float(np.linalg.norm(spot - door) / 1.2)
    start = max(0.0, (cfg.duration_s - cfg.standing_s) / 2 - walk_s)
    t = np.arange(0.0, cfg.duration_s + dt, dt)
    a = np.clip((t - start) / walk_s, 0, 1)[:, None]
    b = np.clip((t - start - walk_s - cfg.standing_s) / walk_s, 0, 1)[:, None]
    xy = door + (spot - door) * a - (spot - door) * b
    xy[(t < start) | (t > start + 2 * walk_s + cfg.standing_s)] = np.nan
    return Trajectory("s0", 0.0, dt, xy)


def _truth_event(t_ns: int, present: dict[str, np.ndarray], phones: dict[str, str]) -> Event:
    entities = tuple(
        GroundTruthEntity(
            p, Vec3(float(xy[0]), float(xy[1]), 0.0), electronic_id=phones.get(p), visual_id=p
        )
        for p, xy in sorted(present.items())
    )
    return (t_ns, 9, topics.GROUND_TRUTH, GroundTruth(t_ns, entities))


def _camera_detections(
    cam: PinholeCamera,
    present: dict[str, np.ndarray],
    rng: np.random.Generator,
    cfg: VmScenario,
    sigma: float,
) -> list[Detection]:
    """What a person detector reports in one camera: visible, unoccluded people (some missed)
    with ground-point noise, and now and then a false positive."""
    seen = []
    for p, xy in present.items():
        box = _person_box(cam, xy)
        if box is not None:
            seen.append((box[1], p, xy, box[0]))
    seen.sort()
    dets = []
    for k, (_, _p, xy, seen_box) in enumerate(seen):
        if any(_overlap(seen_box, seen[j][3]) > 0.5 for j in range(k)):
            continue  # occluded by a nearer person
        if rng.random() < cfg.miss_rate:
            continue
        err = rng.normal(0, sigma, 2)
        dets.append(
            Detection(
                seen_box,
                round(float(rng.uniform(0.5, 1.0)), 3),
                "person",
                Vec3(float(xy[0] + err[0]), float(xy[1] + err[1]), 0.0),
            )
        )
    if rng.random() < cfg.fp_rate:
        fx, fy = (
            rng.uniform(0.1, 0.9) * cam.model.width_px,
            rng.uniform(0.5, 0.95) * cam.model.height_px,
        )
        g = cam.ground_point(np.array([[fx, fy]]))[0]
        if not np.isnan(g).any():
            dets.append(
                Detection(
                    BBox(float(fx) - 10, float(fy) - 60, 20.0, 60.0),
                    round(float(rng.uniform(0.3, 0.6)), 3),
                    "person",
                    Vec3(float(g[0]), float(g[1]), 0.0),
                )
            )
    return dets


class _RealDetections:
    """The realistic preset's detector: calibration bias per camera, merged boxes of people
    walking together, misses in episodes, and persistent false positives (own random stream)."""

    def __init__(self, site: _Site, cfg: VmScenario) -> None:
        self.real = cfg.realism
        self.rng = np.random.default_rng([cfg.seed, 3])
        self.fps = cfg.fps
        self.bias = {
            cam.model.camera: self.rng.normal(0, self.real.calib_bias_m, 2) for cam in site.cams
        }
        self.missing: dict[tuple[str, str], bool] = {}
        self.statics: dict[str, list[np.ndarray]] = {}
        for cam in site.cams:
            spots = []
            for _ in range(self.real.static_fps):
                px = np.array(
                    [
                        [
                            self.rng.uniform(0.15, 0.85) * cam.model.width_px,
                            self.rng.uniform(0.55, 0.95) * cam.model.height_px,
                        ]
                    ]
                )
                g = cam.ground_point(px)[0]
                if not np.isnan(g).any():
                    spots.append(g[:2])
            self.statics[cam.model.camera] = spots

    def _missed(self, camera: str, person: str) -> bool:
        r = self.real
        if r.miss_episode_s <= 0:
            return bool(self.rng.random() < r.miss_rate)
        leave = 1.0 / max(1.0, r.miss_episode_s * self.fps)
        enter = leave * r.miss_rate / max(1e-9, 1 - r.miss_rate)
        state = self.missing.get((camera, person), False)
        state = bool(self.rng.random() >= leave) if state else bool(self.rng.random() < enter)
        self.missing[(camera, person)] = state
        return state

    def __call__(
        self, cam: PinholeCamera, present: dict[str, np.ndarray], sigma: float
    ) -> list[Detection]:
        camera = cam.model.camera
        seen = []
        for p, xy in present.items():
            placed = _person_box(cam, xy)
            if placed is not None:
                seen.append((placed[1], p, xy, placed[0]))
        seen.sort()
        kept: list[tuple[str, np.ndarray, BBox]] = []
        for k, (_, p, xy, box) in enumerate(seen):
            if any(_overlap(box, seen[j][3]) > 0.5 for j in range(k)):
                continue
            if self._missed(camera, p):
                continue
            kept.append((p, xy, box))
        # people walking together: one box at their middle
        points: list[tuple[np.ndarray, BBox]] = []
        used: set[int] = set()
        for a in range(len(kept)):
            if a in used:
                continue
            xy, box = kept[a][1], kept[a][2]
            for b in range(a + 1, len(kept)):
                if b not in used and np.linalg.norm(kept[b][1] - xy) < self.real.merge_m:
                    used.add(b)
                    xy = (xy + kept[b][1]) / 2
            points.append((xy, box))
        dets = []
        bias = self.bias[camera]
        for xy, box in points:
            g = xy + bias + self.rng.normal(0, sigma, 2)
            score = round(float(self.rng.uniform(0.5, 1.0)), 3)
            dets.append(Detection(box, score, "person", Vec3(float(g[0]), float(g[1]), 0.0)))
        for spot in self.statics[camera]:
            if self.rng.random() < self.real.static_fp_rate:
                g = spot + self.rng.normal(0, 0.1, 2)
                dets.append(
                    Detection(
                        BBox(0.0, 0.0, 20.0, 60.0),
                        0.5,
                        "person",
                        Vec3(float(g[0]), float(g[1]), 0.0),
                    )
                )
        return dets


def _camera_events(site: _Site, cfg: VmScenario, rng: np.random.Generator) -> list[Event]:
    """Ground truth and every camera's detections (or frames to render) at each instant."""
    events: list[Event] = []
    sigma = cfg.det_noise_m / math.sqrt(math.pi / 2)
    real = _RealDetections(site, cfg) if cfg.preset != "paper" else None
    for t in np.arange(0.0, site.duration, 1.0 / cfg.fps):
        t_ns = int(round(t * S))
        pos = {tr.person: tr.at(t)[0] for tr in site.trajs}
        present = {p: xy for p, xy in pos.items() if not np.isnan(xy).any()}
        events.append(_truth_event(t_ns, present, site.phones))
        for cam in site.cams:
            dets = _camera_detections(cam, present, rng, cfg, sigma)
            if cfg.frames:
                # the detector finds people in the pixels; the simulated detections above only
                # keep the random stream (and so every other topic) identical to a --no-frames log
                events.append((t_ns, 5, topics.image(cam.model.camera), _Frame(cam, t)))
                continue
            if real is not None:
                dets = real(cam, present, sigma)
            detections = Detections(t_ns, cam.model.camera, tuple(dets))
            events.append((t_ns, 5, topics.detections(cam.model.camera), detections))
    return events


def _imu_events(
    site: _Site, cfg: VmScenario, rng: np.random.Generator
) -> tuple[list[Event], dict[str, PhoneTruth], dict[str, np.ndarray]]:
    """Every phone's IMU samples, its truth, and (realistic phones) its carrier's whereabouts
    over the whole log, in view or not (t_s, x, y)."""
    events: list[Event] = []
    truths: dict[str, PhoneTruth] = {}
    where: dict[str, np.ndarray] = {}
    phones = cfg.realism.phones
    real_rng = np.random.default_rng([cfg.seed, 4])
    site_yaw = 0.0
    if phones is not None:
        site_yaw = (
            math.radians(phones.site_yaw_deg)
            if phones.site_yaw_deg is not None
            else float(real_rng.uniform(-math.pi, math.pi))
        )
    for tr in site.trajs:
        mac = site.phones.get(tr.person)
        if mac is None:
            continue
        topic = topics.imu(mac.replace(":", ""))
        if phones is not None:
            samples, truths[mac], where[mac] = realistic_imu(
                tr, mac, site.duration, real_rng, phones, site_yaw
            )
            events.extend((imu.t_ns, 1, topic, imu) for imu in samples)
            continue
        t0 = max(tr.t0_s, 0.0)
        t1 = min(tr.t0_s + tr.dt_s * (len(tr.xy) - 1), site.duration)
        grid_t = np.arange(math.ceil(t0 * cfg.imu_hz) / cfg.imu_hz, t1, 1.0 / cfg.imu_hz)
        for imu in _imu_samples(tr, mac, grid_t, rng, cfg):
            events.append((imu.t_ns, 1, topic, imu))
    return events, truths, where


def _rssi_events(
    site: _Site, rng: np.random.Generator, cfg: VmScenario, where: dict[str, np.ndarray]
) -> list[Event]:
    """Each AP's scan once a second: log-distance path loss + shadowing (paper: -40 dBm at 1 m,
    exponent 2.5, 3 dB; realistic: per-AP draws from :class:`VmRealism`'s ranges). A phone is
    heard where its carrier is: in view, and (always-on phones, ``where``) out of view too,
    behind the walls of the site (``outside_wall_db``), until it falls below -90 dBm."""
    events: list[Event] = []
    real = cfg.realism
    model = {ap: (-40.0, 2.5, 3.0) for ap, _ in site.aps}
    if cfg.preset != "paper":
        rng = np.random.default_rng([cfg.seed, 5])
        model = {
            ap: (
                float(rng.uniform(*real.rssi_at_1m_dbm)),
                float(rng.uniform(*real.path_loss_exponent)),
                real.shadowing_db,
            )
            for ap, _ in site.aps
        }
    for t in np.arange(0.0, site.duration, 1.0):
        t_ns = int(round(t * S))
        for ap, ap_xy in site.aps:
            readings = []
            for tr in site.trajs:
                mac = site.phones.get(tr.person)
                if mac is None:
                    continue
                xy, wall = tr.at(t)[0], 0.0
                path = where.get(mac)
                if np.isnan(xy).any() and path is not None and len(path):
                    k = min(int(np.searchsorted(path[:, 0], t)), len(path) - 1)
                    xy, wall = path[k, 1:], real.outside_wall_db
                if np.isnan(xy).any():
                    continue
                d = max(0.3, float(np.hypot(*(xy - ap_xy))))
                at1, exponent, shadow = model[ap]
                rssi = at1 - 10 * exponent * math.log10(d) - wall + rng.normal(0, shadow)
                if rssi > -90:
                    readings.append(RssiReading(mac, round(rssi, 1)))
            observer_m = Vec3(float(ap_xy[0]), float(ap_xy[1]), 2.0)
            events.append((t_ns, 2, topics.RSSI, RssiScan(t_ns, ap, tuple(readings), observer_m)))
    return events


class _Renderer:
    """Renders a camera frame when it is written (frames never pile up in memory)."""

    def __init__(self, site: _Site, cfg: VmScenario) -> None:
        self.site, self.cfg = site, cfg
        self.rng = np.random.default_rng([cfg.seed, 1])
        self.light_rng = np.random.default_rng([cfg.seed, 2])  # options keep other draws
        self.looks = {tr.person: PersonLook.random(self.rng) for tr in site.trajs}
        self.floors = (
            {id(cam): floor_image(cam, self.rng) for cam in site.cams} if cfg.frames else {}
        )

    def __call__(self, frame: _Frame) -> object:
        people = []
        for tr in self.site.trajs:
            xy = tr.at(frame.t_s)[0]
            if not np.isnan(xy).any():
                people.append((xy, self.looks[tr.person]))
        img = render_frame(
            frame.cam, self.floors[id(frame.cam)], people, self.rng, shadows=self.cfg.shadows
        )
        gain = 1.0 - (self.cfg.light_drop if frame.t_s >= self.cfg.light_drop_at_s else 0.0)
        if self.cfg.flicker > 0:
            gain *= 1.0 + self.light_rng.uniform(-self.cfg.flicker, self.cfg.flicker)
        if gain != 1.0:
            img = np.clip(img.astype(np.float32) * gain, 0, 255).astype(np.uint8)
        quality = [cv2.IMWRITE_JPEG_QUALITY, self.cfg.jpeg_quality]
        ok, buf = cv2.imencode(".jpg", img, quality)
        if not ok:  # pragma: no cover - OpenCV always encodes a uint8 BGR image
            raise RuntimeError("JPEG encoding failed")
        t_ns = int(round(frame.t_s * S))
        return make_compressed_image(t_ns, frame.cam.model.camera, buf.tobytes(), "jpeg")


def simulate_vm(out: str, cfg: VmScenario) -> dict[str, int]:
    """Write a VM-Tracking scenario log to ``out``; returns message counts per topic."""
    rng = np.random.default_rng(cfg.seed)
    site = _site(cfg, rng)
    events = _camera_events(site, cfg, rng)
    imu_events, truths, where = _imu_events(site, cfg, rng)
    events += imu_events
    events += _rssi_events(site, rng, cfg, where)
    events.sort(key=lambda e: (e[0], e[1], e[2]))
    render = _Renderer(site, cfg)
    counts: dict[str, int] = {}
    with LogWriter(out) as w:
        w.add_metadata("scenario", _scenario_metadata(site, cfg))
        w.add_metadata("phones", {mac: person for person, mac in site.phones.items()})
        if truths:
            # what the simulator chose per phone: for the metrics only, never read by trackers
            w.add_metadata(
                "phone_truth",
                {f"{mac}/{k}": v for mac, tr in truths.items() for k, v in asdict(tr).items()},
            )
        for m in site.models:
            w.write(topics.calibration(m.camera), to_foxglove_calibration(m), 0)
            w.write(topics.camera_model(m.camera), m)
            counts[topics.calibration(m.camera)] = 1
            counts[topics.camera_model(m.camera)] = 1
        for t_ns, _, topic, msg in events:
            if isinstance(msg, _Frame):
                msg = render(msg)
            w.write(topic, msg, t_ns)
            counts[topic] = counts.get(topic, 0) + 1
    return counts


def _scenario_metadata(site: _Site, cfg: VmScenario) -> dict[str, object]:
    return {
        "generator": "trackctl simulate vm",
        "field": cfg.field,
        "seed": cfg.seed,
        "users": len(site.phones),
        "people": len(site.trajs),
        "duration_s": float(site.duration),
        "size_m": f"{site.size[0]:.2f}x{site.size[1]:.2f}",
        "det_noise_m": cfg.det_noise_m,
        "miss_rate": cfg.miss_rate,
        "fp_rate": cfg.fp_rate,
        "fps": cfg.fps,
        "imu_hz": cfg.imu_hz,
        "trajectories": cfg.trajectories or "random-waypoint",
        "frames": cfg.frames,
        "light_drop": cfg.light_drop,
        "light_drop_at_s": cfg.light_drop_at_s,
        "flicker": cfg.flicker,
        "shadows": cfg.shadows,
        "standing_s": cfg.standing_s,
        "preset": cfg.preset,
    }
