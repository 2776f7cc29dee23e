"""A small scenario touching every trackctl format: the shipped sample log.

An office of 6 x 5 m, one calibrated camera in a corner (rendered JPEG frames + detections with
ground error), two people (one carries a phone: IMU at 20 Hz; an AP at the door hears it), a
differential-drive robot with wheel encoders, and ground truth for all of them. Same seed, same
bytes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

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
    WheelOdometry,
)
from trackctl.logs.writer import LogWriter

__all__ = ["DemoConfig", "simulate_demo"]

G = 9.80665
S = 1_000_000_000


@dataclass(frozen=True, slots=True)
class DemoConfig:
    """Parameters of the demo scenario."""

    duration_s: float = 20.0
    seed: int = 0
    fps: float = 3.0
    imu_hz: float = 20.0
    odom_hz: float = 25.0
    det_noise_m: float = 0.35
    width_px: int = 320
    height_px: int = 240


def _ground(xy: Any) -> Vec3:
    """A ground-plane point (z = 0) from an (x, y) pair."""
    return Vec3(float(xy[0]), float(xy[1]), 0.0)


def _walker_path(
    t: np.ndarray,
    center: tuple[float, float],
    radii: tuple[float, float],
    period_s: float,
    phase: float,
) -> np.ndarray:
    ang = 2 * math.pi * t / period_s + phase
    return np.column_stack([center[0] + radii[0] * np.cos(ang), center[1] + radii[1] * np.sin(ang)])


def _camera(cfg: DemoConfig) -> CameraModel:
    pose = look_at(np.array([0.2, 0.2, 2.8]), np.array([3.2, 2.6, 0.0]))
    return ideal_camera("cam0", cfg.width_px, cfg.height_px, pose, hfov_deg=80)


def _render(
    cam: PinholeCamera,
    people: list[tuple[np.ndarray, tuple[int, int, int]]],
    rng: np.random.Generator,
    cfg: DemoConfig,
) -> tuple[bytes, list[BBox]]:
    img = np.full((cfg.height_px, cfg.width_px, 3), (120, 120, 110), np.uint8)
    # floor grid so the frame reads as a room
    for gx in np.arange(0, 6.01, 1.0):
        a, _ = cam.project(np.array([[gx, 0, 0], [gx, 5, 0]]))
        cv2.line(img, tuple(map(int, a[0])), tuple(map(int, a[1])), (90, 90, 80), 1)
    for gy in np.arange(0, 5.01, 1.0):
        a, _ = cam.project(np.array([[0, gy, 0], [6, gy, 0]]))
        cv2.line(img, tuple(map(int, a[0])), tuple(map(int, a[1])), (90, 90, 80), 1)
    boxes = []
    # far to near, so nearer people occlude farther ones
    order = sorted(people, key=lambda p: -np.linalg.norm(p[0] - cam.position[:2]))
    for xy, color in order:
        foot = np.array([xy[0], xy[1], 0.0])
        head = np.array([xy[0], xy[1], 1.7])
        side = np.array([xy[0], xy[1], 0.85]) + 0.25 * np.cross(
            np.array([0, 0, 1.0]),
            np.r_[xy - cam.position[:2], 0] / np.linalg.norm(xy - cam.position[:2]),
        )
        px, front = cam.project(np.stack([foot, head, side]))
        if not front.all():
            continue
        (fx, fy), (hx, hy), (sx, sy) = px
        half_w = max(2.0, abs(sx - (fx + hx) / 2))
        box = BBox(float(min(fx, hx) - half_w), float(hy), float(2 * half_w), float(fy - hy))
        cv2.ellipse(
            img,
            (int((fx + hx) / 2), int((fy + hy) / 2)),
            (int(half_w), int(abs(fy - hy) / 2)),
            0,
            0,
            360,
            color,
            -1,
        )
        boxes.append(box)
    noise = rng.normal(0, 4, img.shape)
    img = np.clip(img + noise, 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", img, [int(cv2.IMWRITE_JPEG_QUALITY), 70])
    assert ok
    return buf.tobytes(), boxes


def _heading(path: object, t: float, eps: float = 1e-3) -> float:
    a, b = path(np.array([t - eps, t + eps]))  # type: ignore[operator]
    return float(math.atan2(b[1] - a[1], b[0] - a[0]))


def simulate_demo(out: str, cfg: DemoConfig | None = None) -> dict[str, int]:
    """Write the demo log to ``out``; returns message counts per topic."""
    cfg = cfg or DemoConfig()
    rng = np.random.default_rng(cfg.seed)
    model = _camera(cfg)
    cam = PinholeCamera(model)
    counts: dict[str, int] = {}

    def put(writer: LogWriter, topic: str, msg: object, t_ns: int | None = None) -> None:
        writer.write(topic, msg, t_ns)
        counts[topic] = counts.get(topic, 0) + 1

    # People: p1 carries phone MAC aa:..:01, p2 carries nothing; robot r1 drives a slow ellipse.
    def person(t: np.ndarray, i: int) -> np.ndarray:
        return _walker_path(t, (3.0 + 0.3 * i, 2.5), (1.8 - 0.5 * i, 1.4), 14.0 + 4 * i, 1.7 * i)

    def robot(t: np.ndarray) -> np.ndarray:
        return _walker_path(t, (3.5, 2.0), (1.2, 0.8), 30.0, 0.0)

    mac = "aa:bb:cc:00:00:01"
    ap_pos = np.array([0.5, 4.5])
    wheel_base, ticks_per_m = 0.30, 2000.0
    with LogWriter(out) as w:
        w.add_metadata(
            "scenario",
            {
                "generator": "trackctl simulate demo",
                "seed": cfg.seed,
                "duration_s": cfg.duration_s,
                "field": "office 6x5 m",
            },
        )
        w.add_metadata("robot/r1", {"ticks_per_m": ticks_per_m, "wheel_base_m": wheel_base})
        put(w, topics.calibration("cam0"), to_foxglove_calibration(model), 0)
        put(w, topics.camera_model("cam0"), model)
        events: list[tuple[int, int, str, object]] = []
        # IMU of p1's phone: specific force = horizontal acceleration + gravity + step bounce,
        # rotated into a device frame that yaws with the walking direction.
        dt = 1.0 / cfg.imu_hz
        t = np.arange(0, cfg.duration_s, dt)
        xy = person(t, 0)
        vel = np.gradient(xy, dt, axis=0)
        acc = np.gradient(vel, dt, axis=0)
        yaw = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
        yaw_rate = np.gradient(yaw, dt)
        step = 1.2 * np.sin(2 * math.pi * 1.8 * t)
        for k, tk in enumerate(t):
            rot = Rotation.from_euler("z", yaw[k])
            f_world = np.array([acc[k, 0], acc[k, 1], G + step[k]])
            f_dev = rot.inv().apply(f_world) + rng.normal(0, 0.05, 3)
            gyro = np.array([0.0, 0.0, yaw_rate[k]]) + rng.normal(0, 0.01, 3)
            q = rot.as_quat()
            events.append(
                (
                    int(tk * S),
                    0,
                    topics.imu("p1"),
                    Imu(
                        int(tk * S),
                        "phone/p1",
                        Vec3(*map(float, f_dev)),
                        Vec3(*map(float, gyro)),
                        Quat(*map(float, q)),
                    ),
                )
            )
        # RSSI at 1 Hz from the AP by the door (log-distance path loss, 4 dB shadowing)
        for tk in np.arange(0, cfg.duration_s, 1.0):
            d = max(0.5, float(np.linalg.norm(person(np.array([tk]), 0)[0] - ap_pos)))
            rssi = -40.0 - 10 * 2.2 * math.log10(d) + rng.normal(0, 4.0)
            events.append(
                (
                    int(tk * S),
                    1,
                    topics.RSSI,
                    RssiScan(
                        int(tk * S),
                        "ap-door",
                        (RssiReading(mac, round(rssi, 1)),),
                        Vec3(float(ap_pos[0]), float(ap_pos[1]), 2.5),
                    ),
                )
            )
        # Robot odometry: cumulative ticks with 1% scale noise per wheel
        dt_o = 1.0 / cfg.odom_hz
        to = np.arange(0, cfg.duration_s, dt_o)
        rxy = robot(to)
        rvel = np.gradient(rxy, dt_o, axis=0)
        ryaw = np.unwrap(np.arctan2(rvel[:, 1], rvel[:, 0]))
        v = np.linalg.norm(rvel, axis=1)
        om = np.gradient(ryaw, dt_o)
        left = np.cumsum((v - om * wheel_base / 2) * dt_o * ticks_per_m * 1.01)
        right = np.cumsum((v + om * wheel_base / 2) * dt_o * ticks_per_m * 0.99)
        for k, tk in enumerate(to):
            events.append(
                (
                    int(tk * S),
                    2,
                    topics.odom("r1"),
                    WheelOdometry(
                        int(tk * S),
                        "robot/r1",
                        int(left[k]),
                        int(right[k]),
                    ),
                )
            )
        # Ground truth at 10 Hz
        for tk in np.arange(0, cfg.duration_s, 0.1):
            ts = np.array([tk])
            ents = (
                GroundTruthEntity(
                    "p1",
                    _ground(person(ts, 0)[0]),
                    electronic_id=mac,
                    visual_id="v1",
                ),
                GroundTruthEntity("p2", _ground(person(ts, 1)[0]), visual_id="v2"),
                GroundTruthEntity("r1", _ground(robot(ts)[0]), yaw_rad=_heading(robot, tk)),
            )
            events.append(
                (
                    int(round(tk * 10)) * S // 10,
                    3,
                    topics.GROUND_TRUTH,
                    GroundTruth(int(round(tk * 10)) * S // 10, ents),
                )
            )
        # Camera frames + detections
        for tk in np.arange(0, cfg.duration_s, 1.0 / cfg.fps):
            t_ns = int(round(tk * S))
            ts = np.array([tk])
            people = [(person(ts, 0)[0], (40, 60, 200)), (person(ts, 1)[0], (200, 80, 40))]
            jpeg, boxes = _render(cam, people, rng, cfg)
            events.append(
                (t_ns, 4, topics.image("cam0"), make_compressed_image(t_ns, "cam0", jpeg, "jpeg"))
            )
            dets = []
            for (pxy, _), box, vid in zip(people, boxes, ("v1", "v2"), strict=False):
                if rng.random() < 0.05:
                    continue  # miss
                # per-axis sigma so the mean 2-D error (Rayleigh mean) is det_noise_m
                err = rng.normal(0, cfg.det_noise_m / math.sqrt(math.pi / 2), 2)
                dets.append(
                    Detection(
                        box,
                        round(float(rng.uniform(0.6, 0.99)), 3),
                        "person",
                        Vec3(float(pxy[0] + err[0]), float(pxy[1] + err[1]), 0.0),
                        vid,
                    )
                )
            events.append(
                (t_ns, 5, topics.detections("cam0"), Detections(t_ns, "cam0", tuple(dets)))
            )
        events.sort(key=lambda e: (e[0], e[1]))
        for t_ns, _, topic, msg in events:
            put(w, topic, msg, t_ns)
    return counts
