"""BridgeLoc scenarios (dissertation §4.2.4, Fig. 4.19): a robot with encoders, an IR light and a
wide-angle camera among infrastructure cameras and N x N wall tags.

* ``office`` — one infrastructure camera (50° AoV), one tag about 1.5 m from it; the robot visits
  test spots at 1-4 m and -60..60° from the tag (Fig. 4.20), facing the tag's wall.
* ``lobby`` — 14 x 8 m, three infrastructure cameras (one with an occluded corner), 2-10 tags on
  the walls above/below the robot camera, some rotated by 45°, each of its own pattern (or a
  pool of ``patterns`` reused far apart); the robot drives random waypoints (or a CSV path).

Images of every camera are rendered: tags are warped onto the projected quads
(``cv2.warpPerspective``) over a simple background, the robot and its IR light are drawn in the
infrastructure views, then lens distortion (``cv2.remap``), blur, noise and JPEG. Same seed, same
bytes.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from trackctl.bridgeloc.tags import (
    Code,
    Mount,
    Placement,
    check_family,
    enumerate_practical,
    in_family,
    tag_texture,
)
from trackctl.errors import InputError
from trackctl.geometry.camera import PinholeCamera, ideal_camera, look_at
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

__all__ = [
    "PRESETS",
    "Realism",
    "BridgeLocScenario",
    "WallTag",
    "lobby_layout",
    "render_view",
    "robot_camera_model",
    "simulate_bridgeloc",
    "tag_corners",
]

S = 1_000_000_000
ROBOT = "r1"
ROBOT_CAMERA = "r1cam"
MARGIN = 0.25  # white quiet zone around the black square, fraction of its side


@dataclass(frozen=True, slots=True)
class Realism:
    """What the ``realistic`` preset adds to the idealised scene (``paper``: all off).

    Each model and its source (docs/bridgeloc.md lists them):

    * ``posters`` printed text and signage on the walls (notices, exit signs, framed boxes,
      arrows; :mod:`trackctl.sim.clutter`): what real corridors carry, and what a square-tag
      detector mistakes for tags.
    * ``lamps`` wall lamps at 2.3 m that saturate the IR-sensitive infrastructure cameras as
      the robot's IR light does (a lit sconce is far brighter than an IR LED at 6 m).
    * ``defocus_px`` Gaussian blur of a fixed-focus webcam lens (the JD-510 and C210 are
      fixed-focus; ~1 px is typical away from the focus distance).
    * ``noise_sigma`` sensor noise in grey levels at indoor light (consumer CMOS at 300 lux,
      EMVA 1288 datasheets of 1/4" sensors: 3-5 DN), ``jpeg_quality`` of webcam MJPEG.
    * ``exposure_s`` exposure time (webcam auto-exposure indoors: 1/60-1/30 s): the robot's
      turning and driving smear its images along the motion.
    * ``light_drift`` slow global gain change per camera (daylight through windows, dimming:
      +-15 % over minutes) and ``vignetting`` (corner falloff of a cheap wide lens).
    * ``tilt_deg`` robot pitch and roll std (floor unevenness and acceleration on a small
      robot; 2-3 mm bumps over a 0.3 m wheel base give ~0.5 deg).
    * ``infra_calib_deg`` / ``infra_calib_m`` the infrastructure cameras' true pose differs
      from the calibrated pose in the log by this much (floor-point PnP calibration at ~1 px).
    * ``mount_deg`` the robot camera's true mount differs from the calibrated one.
    * ``ir_offset_m`` the IR light sits this far ahead of the base centre (mounting).
    * ``wheelbase_err`` std of the effective wheel base's relative error, drawn once per robot:
      the contact points of soft tyres are not where the drawing puts them, so every turn is
      read this much too large or small (UMBmark, Borenstein & Feng 1996: the wheel base is
      the dominant systematic error in turns, a few percent before calibration).
    * ``slip_k_m`` non-systematic wheel slip: each wheel's measured travel errs with variance
      ``slip_k_m`` x its travel (Chong & Kleeman 1997's odometry error model; floor
      roughness, dust, carpet seams), a heading random walk of sqrt(2 k) / wheel base per
      sqrt(m).
    * ``turn_slip`` std of the relative heading error of each turn in place (tyres scrub
      sideways while turning; the error differs from turn to turn).
    """

    posters: int = 0
    lamps: int = 0
    defocus_px: float = 0.7
    noise_sigma: float = 2.5
    jpeg_quality: int = 75
    exposure_s: float = 0.0
    light_drift: float = 0.0
    vignetting: float = 0.0
    tilt_deg: float = 0.0
    infra_calib_deg: float = 0.0
    infra_calib_m: float = 0.0
    mount_deg: float = 0.0
    ir_offset_m: float = 0.0
    wheelbase_err: float = 0.0
    slip_k_m: float = 0.0
    turn_slip: float = 0.0


PRESETS: dict[str, Realism] = {
    "paper": Realism(),
    "realistic": Realism(
        posters=6,
        lamps=2,
        defocus_px=1.0,
        noise_sigma=4.0,
        jpeg_quality=65,
        exposure_s=1 / 60,
        light_drift=0.15,
        vignetting=0.25,
        tilt_deg=0.5,
        infra_calib_deg=0.3,
        infra_calib_m=0.02,
        mount_deg=0.5,
        ir_offset_m=0.05,
        wheelbase_err=0.02,
        slip_k_m=2e-5,
        turn_slip=0.03,
    ),
}
"""``paper``: the dissertation's idealised setting (clean renders, exact calibration), kept for
its tables; ``realistic`` (the default): the models above."""


@dataclass(frozen=True, slots=True)
class BridgeLocScenario:
    """Parameters of a BridgeLoc scenario log."""

    field: str = "lobby"
    tags: int = 10
    path: str = "random"
    seed: int = 0
    duration_s: float = 60.0
    robot_fps: float = 5.0
    """Robot camera rate in the log (the JD-510 runs at 30 fps; 5 Hz keeps logs small)."""
    infra_fps: float = 5.0
    odom_hz: float = 25.0
    tag_size_m: float = 0.30
    n: int = 2
    camera_height_m: float = 0.50
    ir_height_m: float = 0.65
    ir_range_m: float = 6.0
    """Distance beyond which the IR light is too dim for the infrastructure cameras."""
    speed_mps: float = 0.4
    turn_rps: float = 1.0
    preset: str = "realistic"
    """``realistic`` (default) or ``paper``: see :class:`Realism` and :data:`PRESETS`."""
    family: str = "plain"
    """Tag family: ``plain`` or ``parity`` (N >= 3, two check cells)."""
    patterns: int = 0
    """Distinct patterns deployed. 0 (the default): every tag its own while the family has
    them, as a deployer hangs them (N = 2 has 56 with placement and mount; the dissertation's
    lobby had 2-10). A number: the tags cycle through that many, so tags far apart share a
    pattern and a sighting names several candidates, which only a robot that knows roughly
    where it is can resolve (the nearest, Eq. 4.11)."""

    @property
    def realism(self) -> Realism:
        return PRESETS[self.preset]

    def __post_init__(self) -> None:
        check_family(self.family, self.n)
        if self.preset not in PRESETS:
            raise InputError(f"--preset {self.preset!r}: expected one of {', '.join(PRESETS)}")
        if self.field not in ("office", "lobby"):
            raise InputError(f"--field {self.field!r}: expected office or lobby")
        if not 1 <= self.tags <= 56:
            raise InputError(f"--tags {self.tags}: expected 1..56")
        if self.patterns < 0:
            raise InputError(f"--patterns {self.patterns}: expected 0 (all distinct) or more")
        if self.duration_s <= 0 or self.robot_fps <= 0 or self.infra_fps <= 0:
            raise InputError("duration and frame rates must be positive")


@dataclass(frozen=True, slots=True)
class WallTag:
    """A tag hung on a wall: centre, inward normal (horizontal), symbol."""

    tag_id: str
    code: Code
    placement: Placement
    mount: Mount
    center: tuple[float, float, float]
    normal: tuple[float, float]
    size_m: float

    def to_json(self) -> dict[str, object]:
        return {
            "tag_id": self.tag_id,
            "code": "".join(map(str, self.code)),
            "placement": self.placement.value,
            "mount": self.mount.value,
            "center_m": list(self.center),
            "normal": list(self.normal),
            "size_m": self.size_m,
        }


def tag_corners(tag: WallTag, scale: float = 1.0) -> np.ndarray:
    """World corners (4, 3) TL, TR, BR, BL of the printed square (``scale`` x its side).

    TL..BL are the printed tag's corners as a viewer facing the wall sees them; a diamond is the
    square turned 45° clockwise, so its top corner is the printed TL.
    """
    nrm = np.array([tag.normal[0], tag.normal[1], 0.0])
    up = np.array([0.0, 0.0, 1.0])
    right = np.cross(-nrm, up)
    if tag.placement is Placement.DIAMOND:
        c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
        right, up = c * right - s * up, s * right + c * up
    h = tag.size_m * scale / 2
    ctr = np.asarray(tag.center, float)
    return np.stack(
        [
            ctr - right * h + up * h,
            ctr + right * h + up * h,
            ctr + right * h - up * h,
            ctr - right * h - up * h,
        ]
    )


def _model(name: str, pose: Transform, aov_deg: float, dist: tuple[float, ...]) -> CameraModel:
    return ideal_camera(name, 640, 480, pose, hfov_deg=aov_deg, distortion=dist)


def robot_camera_model(height_m: float = 0.5) -> CameraModel:
    """The robot's 120° camera; its pose is base_link <- camera optical frame (not world)."""
    pose = look_at(np.array([0.10, 0.0, height_m]), np.array([1.10, 0.0, height_m]))
    return _model(ROBOT_CAMERA, pose, 120.0, (-0.03, 0.004, 0.0, 0.0, 0.0))


@dataclass
class Layout:
    """Static scene: room size, infrastructure cameras, occluded regions, tag candidates."""

    size: tuple[float, float]
    cameras: list[CameraModel]
    occluded: dict[str, np.ndarray] = field(default_factory=dict)
    tags: list[WallTag] = field(default_factory=list)


def _infra(
    name: str, eye: tuple[float, float, float], target: tuple[float, float, float]
) -> CameraModel:
    return _model(name, look_at(np.array(eye), np.array(target)), 50.0, (-0.02, 0.0, 0, 0, 0))


def _symbols(n: int, family: str = "plain") -> list[tuple[Code, Placement]]:
    seen: list[tuple[Code, Placement]] = []
    for t in enumerate_practical(n):
        if not in_family(t.code, n, family):
            continue
        key = (t.code, t.placement)
        if key not in seen:
            seen.append(key)
    return seen


def office_layout(cfg: BridgeLocScenario) -> Layout:
    """A 6 x 7 m office: one camera ~1.5 m from one tag on the wall x = 6 m."""
    cam = _infra("cam0", (5.0, 2.5, 1.9), (6.0, 3.5, 0.6))
    tag = WallTag(
        "t0",
        (0, 1, 1, 0),
        Placement.SQUARE,
        Mount.ABOVE,
        (6.0, 3.5, 0.85),
        (-1.0, 0.0),
        cfg.tag_size_m,
    )
    return Layout((6.0, 7.0), [cam], {}, [tag])


_LOBBY_SIZE = (14.0, 8.0)

_WallSpot = tuple[float, float, float, float]
"""A tag spot on a wall: x, y (m) and the wall's inward normal nx, ny."""


def _lobby_cameras() -> list[CameraModel]:
    """The lobby's three infrastructure cameras: two on the bottom wall, one on the top."""
    return [
        _infra("cam0", (3.0, 0.2, 2.6), (3.0, 8.0, 0.0)),
        _infra("cam1", (11.0, 0.2, 2.6), (11.0, 8.0, 0.0)),
        _infra("cam2", (7.0, 7.8, 2.6), (7.0, 0.0, 0.0)),
    ]


def _wall_candidates(w: float, h: float) -> list[_WallSpot]:
    """Spots every 0.5 m along the four walls, 1 m clear of the corners."""
    cand: list[_WallSpot] = []
    for x in np.arange(1.0, w - 0.99, 0.5):
        cand += [(x, 0.0, 0.0, 1.0), (x, h, 0.0, -1.0)]
    for y in np.arange(1.0, h - 0.99, 0.5):
        cand += [(0.0, y, 1.0, 0.0), (w, y, -1.0, 0.0)]
    return cand


def _sees_spot(pc: PinholeCamera, spot: _WallSpot) -> bool:
    """Whether camera ``pc`` sees a tag at ``spot`` (0.6 m up) well: inside the image 40 px
    clear of its border, nearer than 9.5 m, and not too oblique to the wall."""
    x, y, nx, ny = spot
    ctr = np.array([x, y, 0.6])
    d = pc.position - ctr
    dist = float(np.linalg.norm(d))
    cos_inc = (d[0] * nx + d[1] * ny) / max(1e-9, math.hypot(d[0], d[1]))
    px, front = pc.project(ctr[None])
    inside = front[0] and 40 < px[0, 0] < 600 and 40 < px[0, 1] < 440
    return bool(inside and dist < 9.5 and cos_inc > 0.35)


def _spread(ok: list[_WallSpot], count: int, rng: np.random.Generator) -> list[int]:
    """Farthest-point sampling of ``count`` of the spots ``ok`` (indices): spread tags over
    the walls, from a random first spot."""
    pts = np.array([[c[0], c[1]] for c in ok])
    chosen = [int(rng.integers(len(ok)))]
    while len(chosen) < count:
        d = np.min(np.linalg.norm(pts[:, None] - pts[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(d)))
    return chosen


def _lobby_tags(
    cfg: BridgeLocScenario, spots: list[_WallSpot], rng: np.random.Generator
) -> list[WallTag]:
    """Tags at ``spots`` (in order), with symbols of a random permutation of the family.

    Distinct patterns while the family has them, or a pool of cfg.patterns (tags far apart then
    share one; the EKF picks the nearest candidate, Eq. 4.11); mounts alternate above/below,
    and flip on the family's second round, so that up to twice its size no two tags are alike.
    """
    symbols = _symbols(cfg.n, cfg.family)
    order = rng.permutation(len(symbols))
    pool = cfg.patterns or len(symbols)
    tags = []
    for k, (x, y, nx, ny) in enumerate(spots):
        code, placement = symbols[int(order[k % pool])]
        mount = Mount.ABOVE if (k + k // len(symbols)) % 2 == 0 else Mount.BELOW
        z = round(cfg.camera_height_m + (0.40 if mount is Mount.ABOVE else -0.28), 3)
        tags.append(WallTag(f"t{k}", code, placement, mount, (x, y, z), (nx, ny), cfg.tag_size_m))
    return tags


def lobby_layout(cfg: BridgeLocScenario) -> Layout:
    """The 14 x 8 m lobby: three cameras, an occluded corner for the top camera, wall tags."""
    cams = _lobby_cameras()
    # a corner of the building hides this triangle from the top camera (the paper's grey area)
    occluded = {"cam2": np.array([[7.0, 3.5], [9.5, 1.0], [9.5, 3.5]], np.float32)}
    rng = np.random.default_rng(cfg.seed + 7)
    w, h = _LOBBY_SIZE
    pcams = [PinholeCamera(c) for c in cams]
    ok = [s for s in _wall_candidates(w, h) if any(_sees_spot(pc, s) for pc in pcams)]
    if len(ok) < cfg.tags:
        raise InputError(f"--tags {cfg.tags}: the lobby has only {len(ok)} usable wall spots")
    chosen = _spread(ok, cfg.tags, rng)
    tags = _lobby_tags(cfg, [ok[idx] for idx in chosen], rng)
    return Layout((w, h), cams, occluded, tags)


# ---------------------------------------------------------------- robot motion


def _segments(
    waypoints: list[tuple[float, float, float | None, float]],
    start_yaw: float,
    v: float,
    om: float,
    dt: float,
) -> np.ndarray:
    """Poses (K, 3) of a diff-drive robot visiting waypoints: turn, drive, (turn), hold."""
    x, y = waypoints[0][0], waypoints[0][1]
    yaw = start_yaw
    out = [(x, y, yaw)]

    def turn_to(target: float) -> None:
        nonlocal yaw
        err = math.atan2(math.sin(target - yaw), math.cos(target - yaw))
        steps = max(1, int(math.ceil(abs(err) / (om * dt))))
        for _ in range(steps):
            yaw += err / steps
            out.append((x, y, yaw))

    for wx, wy, heading, hold in waypoints[1:]:
        d = math.hypot(wx - x, wy - y)
        if d > 1e-6:
            turn_to(math.atan2(wy - y, wx - x))
            steps = max(1, int(math.ceil(d / (v * dt))))
            x0, y0 = x, y
            for k in range(1, steps + 1):
                x, y = x0 + (wx - x0) * k / steps, y0 + (wy - y0) * k / steps
                out.append((x, y, yaw))
        if heading is not None:
            turn_to(heading)
        for _ in range(int(round(hold / dt))):
            out.append((x, y, yaw))
    return np.array(out)


def _wheel_travel(
    ds: np.ndarray, dyaw: np.ndarray, wheel_base: float, real: Realism, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """What each wheel's encoder measures for the true increments (m per odometry step): the
    rolling travel, read through the effective wheel base, each turn's scrubbing and slip.
    The models (:class:`Realism`) draw from their own stream, so the paper preset's bytes and
    every other random choice of a log stay as they were."""
    turn = dyaw * wheel_base / 2
    if not (real.wheelbase_err or real.slip_k_m or real.turn_slip):
        return ds - turn, ds + turn
    rng = np.random.default_rng([seed, 4_3])
    # a wheel base longer than drawn makes the wheels roll farther for the same turn
    turn = turn * (1.0 + real.wheelbase_err * float(rng.standard_normal()))
    # scrubbing: one relative error per turn in place (a run of steps turning without driving)
    turning = (np.abs(dyaw) > 1e-9) & (np.abs(ds) < 1e-9)
    starts = np.flatnonzero(turning & ~np.r_[False, turning[:-1]])
    run_id = np.cumsum(np.isin(np.arange(len(ds)), starts)) - 1
    scrub = 1.0 + real.turn_slip * rng.standard_normal(max(1, len(starts)))
    turn = np.where(turning, turn * scrub[np.maximum(run_id, 0)], turn)
    left, right = ds - turn, ds + turn
    # slip: variance proportional to each wheel's travel (Chong & Kleeman 1997)
    left = left + rng.standard_normal(len(ds)) * np.sqrt(real.slip_k_m * np.abs(left))
    right = right + rng.standard_normal(len(ds)) * np.sqrt(real.slip_k_m * np.abs(right))
    return left, right


def _office_spots(
    layout: Layout,
) -> tuple[list[tuple[float, float, float | None, float]], list[tuple[float, float]]]:
    tag = layout.tags[0]
    nrm = np.array(tag.normal)
    tang = np.array([-nrm[1], nrm[0]])
    facing = math.atan2(-nrm[1], -nrm[0])
    wps: list[tuple[float, float, float | None, float]] = []
    spots = []
    for dist in (1.0, 2.0, 3.0, 4.0):
        for ang in (-60, -45, -30, 0, 30, 45, 60):
            a = math.radians(ang)
            p = np.array(tag.center[:2]) + dist * (math.cos(a) * nrm + math.sin(a) * tang)
            wps.append((float(p[0]), float(p[1]), facing, 1.2))
            spots.append((dist, float(ang)))
    return wps, spots


def _random_waypoints(
    rng: np.random.Generator, size: tuple[float, float], n: int
) -> list[tuple[float, float, float | None, float]]:
    m = 0.8
    return [
        (float(rng.uniform(m, size[0] - m)), float(rng.uniform(m, size[1] - m)), None, 0.0)
        for _ in range(n)
    ]


def _csv_waypoints(path: str) -> list[tuple[float, float, float | None, float]]:
    try:
        with open(path, newline="") as f:
            rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    except OSError as err:
        raise InputError(f"--path {path}: {err.strerror}") from err
    out: list[tuple[float, float, float | None, float]] = []
    for i, r in enumerate(rows):
        try:
            out.append((float(r[0]), float(r[1]), None, 0.0))
        except (ValueError, IndexError):
            if i == 0:
                continue  # header
            raise InputError(f"--path {path}:{i + 1}: expected x_m,y_m") from None
    if len(out) < 2:
        raise InputError(f"--path {path}: needs at least two x_m,y_m rows")
    return out


# ---------------------------------------------------------------- rendering


class _Renderer:
    """Draws one camera's views; keeps its distortion map and tag textures."""

    def __init__(
        self, model: CameraModel, rng: np.random.Generator, cfg: BridgeLocScenario
    ) -> None:
        self.model = model
        self.cfg = cfg
        self.rng = rng
        self.K = np.array([[model.fx_px, 0, model.cx_px], [0, model.fy_px, model.cy_px], [0, 0, 1]])
        self.lens = LensDistortion(model)
        self._tex: dict[tuple[Code, int], np.ndarray] = {}

    def texture(self, code: Code, side: int) -> np.ndarray:
        key = (code, side)
        if key not in self._tex:
            self._tex[key] = tag_texture(code, self.cfg.n, side, margin=MARGIN, white=205, black=30)
        return self._tex[key]

    def finish(self, ideal: np.ndarray, smear_px: float = 0.0) -> bytes:
        """Lens, motion smear (horizontal, ``smear_px`` long), defocus, noise, JPEG."""
        real = self.cfg.realism
        img = self.lens.apply(ideal)
        if smear_px >= 1.0:
            k = int(math.ceil(smear_px)) | 1
            kernel = np.zeros((1, k), np.float32)
            kernel[0, (k - int(round(smear_px))) // 2 : (k + int(round(smear_px))) // 2 + 1] = 1
            img = cv2.filter2D(img, -1, kernel / kernel.sum())
        img = cv2.GaussianBlur(img, (0, 0), real.defocus_px)
        noise = self.rng.normal(0.0, real.noise_sigma, img.shape)
        img = np.clip(img + noise, 0, 255).astype(np.uint8)
        ok, buf = cv2.imencode(".jpg", img, [int(cv2.IMWRITE_JPEG_QUALITY), real.jpeg_quality])
        assert ok
        return buf.tobytes()


def _pinhole(model: CameraModel, world_from_camera: Transform) -> PinholeCamera:
    from dataclasses import replace

    return PinholeCamera(replace(model, distortion=(0.0,) * 5, world_from_camera=world_from_camera))


def draw_tag(img: np.ndarray, cam: PinholeCamera, tag: WallTag, tex_fn) -> None:  # noqa: ANN001
    """Warp a tag's texture onto its projected quad (ideal, undistorted image)."""
    ctr = np.asarray(tag.center)
    to_cam = cam.position - ctr
    if to_cam[0] * tag.normal[0] + to_cam[1] * tag.normal[1] <= 0.02:
        return  # behind the wall
    outer = tag_corners(tag, 1.0 + 2 * MARGIN)
    _warp_quad(img, cam, outer, lambda side: tex_fn(tag.code, int(round(side / (1 + 2 * MARGIN)))))


@dataclass(frozen=True)
class Poster:
    """A printed poster on a wall: corners TL, TR, BR, BL (world), inward normal, texture."""

    corners: np.ndarray
    normal: tuple[float, float]
    texture: np.ndarray


def draw_poster(img: np.ndarray, cam: PinholeCamera, poster: Poster) -> None:
    to_cam = cam.position - poster.corners.mean(axis=0)
    if to_cam[0] * poster.normal[0] + to_cam[1] * poster.normal[1] <= 0.02:
        return
    tex = poster.texture
    _warp_quad(img, cam, poster.corners, lambda side: tex)


def _warp_quad(img: np.ndarray, cam: PinholeCamera, outer: np.ndarray, tex_for) -> None:  # noqa: ANN001
    """Warp the texture ``tex_for(side_px)`` onto the projected world quad ``outer``."""
    pc = cam.to_camera(outer)
    if (pc[:, 2] < 0.05).any():
        return
    px, _ = cam.project(outer)
    h, w = img.shape
    x0, y0 = np.floor(px.min(axis=0)).astype(int)
    x1, y1 = np.ceil(px.max(axis=0)).astype(int)
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    if x1 <= x0 or y1 <= y0:
        return
    side_px = float(np.max(np.linalg.norm(px - np.roll(px, 1, axis=0), axis=1)))
    size = (x1 - x0, y1 - y0)
    # supersample small quads and average down (INTER_AREA): edges land within ~0.1 px
    ss = 4 if size[0] * size[1] < 20_000 else (2 if size[0] * size[1] < 80_000 else 1)
    side = int(np.clip(2 ** math.ceil(math.log2(max(side_px * ss, 8))), 16, 1024))
    tex = tex_for(side)
    th, tw = tex.shape
    # texel centres are integers, so the texture's outer edges lie at -0.5 and size - 0.5
    src = np.array(
        [[-0.5, -0.5], [tw - 0.5, -0.5], [tw - 0.5, th - 0.5], [-0.5, th - 0.5]], np.float32
    )
    dst = ((px - [x0, y0]) * ss + (ss - 1) / 2).astype(np.float32)
    hmat = cv2.getPerspectiveTransform(src, dst)
    big = (size[0] * ss, size[1] * ss)
    warped = cv2.warpPerspective(tex, hmat, big, flags=cv2.INTER_LINEAR, borderValue=0)
    mask = cv2.warpPerspective(
        np.full_like(tex, 255), hmat, big, flags=cv2.INTER_LINEAR, borderValue=0
    )
    if ss > 1:
        warped = cv2.resize(warped, size, interpolation=cv2.INTER_AREA)
        mask = cv2.resize(mask, size, interpolation=cv2.INTER_AREA)
    roi = img[y0:y1, x0:x1]
    a = mask.astype(np.float32) / 255.0
    roi[:] = (roi * (1 - a) + warped * a).astype(np.uint8)


def render_view(
    model: CameraModel,
    world_from_camera: Transform,
    tags: list[WallTag],
    background: np.ndarray,
    tex_fn,  # noqa: ANN001
    robot: tuple[float, float, float] | None = None,
    ir_height_m: float = 0.65,
    ir_range_m: float = 7.0,
    posters: tuple[Poster, ...] = (),
    lamps: tuple[tuple[float, float, float], ...] = (),
    shade: np.ndarray | None = None,
    ir_offset_m: float = 0.0,
) -> np.ndarray:
    """The ideal (undistorted) grayscale view: background, posters, tags, robot body; the
    scene times ``shade`` (lighting gain x vignetting); then the saturating light sources (the
    robot's IR light, lamps), which stay saturated whatever the exposure."""
    cam = _pinhole(model, world_from_camera)
    img = background.copy()
    for poster in posters:
        draw_poster(img, cam, poster)
    order = sorted(tags, key=lambda t: -float(np.linalg.norm(cam.position - np.asarray(t.center))))
    for tag in order:
        draw_tag(img, cam, tag, tex_fn)
    lights: list[tuple[np.ndarray, float, float]] = []  # (world point, peak, radius m)
    if robot is not None:
        x, y, yaw = robot
        ang = np.linspace(0, 2 * math.pi, 16, endpoint=False)
        ring = np.column_stack([x + 0.2 * np.cos(ang), y + 0.2 * np.sin(ang), np.full(16, 0.0)])
        top = ring + [0, 0, ir_height_m - 0.05]
        pts, front = cam.project(np.vstack([ring, top]))
        if front.all():
            hull = cv2.convexHull(pts.astype(np.float32)).astype(np.int32)
            cv2.fillConvexPoly(img, hull, 45, cv2.LINE_AA)
        light = np.array(
            [x + ir_offset_m * math.cos(yaw), y + ir_offset_m * math.sin(yaw), ir_height_m]
        )
        d = float(np.linalg.norm(cam.position - light))
        # a light source overexposes the camera (its core is clipped, with bloom); it fades
        # with the inverse square and stops clipping at ir_range_m
        lights.append((light, 255.0 * min(3.0, (ir_range_m / d) ** 2), 0.03))
    for lamp in lamps:
        lights.append((np.asarray(lamp, float), 3.0 * 255.0, 0.06))
    if shade is not None:
        img = np.clip(img * shade, 0, 255).astype(np.uint8)
    for point, peak, radius_m in lights:
        lp, lfront = cam.project(point[None])
        if not lfront[0]:
            continue
        d = float(np.linalg.norm(cam.position - point))
        r = max(1.5, radius_m * model.fx_px / d)
        centre = tuple(int(round(v)) for v in lp[0])
        if not (
            -4 * r < centre[0] < img.shape[1] + 4 * r and -4 * r < centre[1] < img.shape[0] + 4 * r
        ):
            continue
        spot: np.ndarray = np.zeros_like(img, np.float32)
        cv2.circle(spot, centre, int(round(r * 2)), 1.0, -1, cv2.LINE_AA)
        spot = np.asarray(cv2.GaussianBlur(spot, (0, 0), r), np.float32)
        spot /= max(float(spot.max()), 1e-6)
        img = np.maximum(img, np.clip(spot * peak, 0, 255).astype(np.uint8))
    return img


def _background(model: CameraModel, rng: np.random.Generator, horizon: bool) -> np.ndarray:
    h, w = model.height_px, model.width_px
    low = cv2.resize(rng.normal(0, 1, (h // 40, w // 40)), (w, h), interpolation=cv2.INTER_CUBIC)
    if horizon:  # robot camera, level: wall above the horizon, floor below
        img = np.where(np.arange(h)[:, None] < model.cy_px, 150.0, 95.0) + np.zeros((h, w))
    else:
        img = np.full((h, w), 110.0)
    return np.clip(img + 12 * low, 0, 255).astype(np.uint8)


def _in_poly(poly: np.ndarray, x: float, y: float) -> bool:
    return cv2.pointPolygonTest(poly.reshape(-1, 1, 2), (float(x), float(y)), False) >= 0


def _compose(
    base_from_cam: Transform,
    x: float,
    y: float,
    yaw: float,
    pitch: float = 0.0,
    roll: float = 0.0,
) -> Transform:
    from scipy.spatial.transform import Rotation

    r_base = Rotation.from_euler("ZYX", [yaw, pitch, roll])
    q = base_from_cam.rotation
    r = r_base * Rotation.from_quat([q.x, q.y, q.z, q.w])
    t = base_from_cam.translation
    p = r_base.apply([t.x, t.y, t.z]) + [x, y, 0.0]
    return Transform(Vec3(*map(float, p)), Quat(*map(float, r.as_quat())))


def _posters(layout: Layout, real: Realism, rng: np.random.Generator, field: str) -> list[Poster]:
    """Posters on the walls, clear of the tags (0.4 m), 0.5-0.9 m wide, centred 1.1-1.6 m up."""
    from trackctl.sim.clutter import signage_texture

    w, h = layout.size
    walls = (
        [((w, 0.0), (w, h), (-1.0, 0.0))]
        if field == "office"
        else [
            ((0.0, 0.0), (w, 0.0), (0.0, 1.0)),
            ((w, h), (0.0, h), (0.0, -1.0)),
            ((0.0, h), (0.0, 0.0), (1.0, 0.0)),
            ((w, 0.0), (w, h), (-1.0, 0.0)),
        ]
    )
    out: list[Poster] = []
    for _ in range(200):
        if len(out) >= real.posters:
            break
        a, b, nrm = walls[int(rng.integers(len(walls)))]
        along = np.array(b) - np.array(a)
        length = float(np.linalg.norm(along))
        u = along / length
        pw, ph = float(rng.uniform(0.5, 0.9)), float(rng.uniform(0.6, 1.0))
        t = float(rng.uniform(pw / 2 + 0.2, length - pw / 2 - 0.2))
        c = np.array(a) + u * t
        zc = float(rng.uniform(1.1, 1.6))
        if any(
            abs((np.array(tag.center[:2]) - c) @ u) < pw / 2 + 0.4
            and abs((np.array(tag.center[:2]) - c) @ np.array(nrm)) < 0.1
            for tag in layout.tags
        ) or any(np.linalg.norm(p.corners.mean(axis=0)[:2] - c) < 1.2 for p in out):
            continue
        # a viewer facing the wall sees "right" as -normal x up
        right = np.cross(-np.array([nrm[0], nrm[1], 0.0]), [0.0, 0.0, 1.0])
        ctr = np.array([c[0], c[1], zc]) + 0.002 * np.array([nrm[0], nrm[1], 0.0])
        up = np.array([0.0, 0.0, 1.0])
        corners = np.stack(
            [
                ctr - right * pw / 2 + up * ph / 2,
                ctr + right * pw / 2 + up * ph / 2,
                ctr + right * pw / 2 - up * ph / 2,
                ctr - right * pw / 2 - up * ph / 2,
            ]
        )
        tex = signage_texture(rng, int(pw * 500), int(ph * 500))
        out.append(Poster(corners, nrm, tex))
    return out


def _lamps(
    layout: Layout, real: Realism, rng: np.random.Generator
) -> list[tuple[float, float, float]]:
    """Wall lamps at 2.3 m where an infrastructure camera sees them."""
    w, h = layout.size
    pins = [PinholeCamera(c) for c in layout.cameras]
    out: list[tuple[float, float, float]] = []
    for _ in range(200):
        if len(out) >= real.lamps:
            break
        side = int(rng.integers(2))
        p = (float(rng.uniform(0.5, w - 0.5)), h - 0.05 if side else 0.05, 2.3)
        if layout.size == (6.0, 7.0):  # office: on the tag's wall
            p = (w - 0.05, float(rng.uniform(0.5, h - 0.5)), 2.3)
        for pin in pins:
            px, front = pin.project(np.array([p]))
            if front[0] and 20 < px[0, 0] < 620 and 20 < px[0, 1] < 460:
                out.append(p)
                break
    return out


def _perturbed(tf: Transform, rng: np.random.Generator, deg: float, metres: float) -> Transform:
    """``tf`` rotated by a small random rotation (std ``deg`` per axis) and moved (``metres``)."""
    from scipy.spatial.transform import Rotation

    q = tf.rotation
    rot = Rotation.from_rotvec(np.radians(rng.normal(0.0, deg, 3))) * Rotation.from_quat(
        [q.x, q.y, q.z, q.w]
    )
    t = tf.translation
    p = np.array([t.x, t.y, t.z]) + rng.normal(0.0, metres, 3)
    return Transform(Vec3(*map(float, p)), Quat(*map(float, rot.as_quat())))


def _smooth_noise(rng: np.random.Generator, n: int, sigma: float, corr: int) -> np.ndarray:
    """A zero-mean series of std ``sigma`` correlated over ~``corr`` samples (AR(1))."""
    if sigma <= 0 or n == 0:
        return np.zeros(n)
    a = math.exp(-1.0 / max(corr, 1))
    e = rng.normal(0.0, sigma * math.sqrt(1 - a * a), n)
    out = np.empty(n)
    acc = rng.normal(0.0, sigma)
    for i in range(n):
        acc = a * acc + e[i]
        out[i] = acc
    return out


def _vignette(model: CameraModel, strength: float) -> np.ndarray | None:
    if strength <= 0:
        return None
    yy, xx = np.mgrid[0 : model.height_px, 0 : model.width_px].astype(np.float32)
    r2 = ((xx - model.cx_px) ** 2 + (yy - model.cy_px) ** 2) / (model.cx_px**2 + model.cy_px**2)
    return (1.0 - strength * r2).astype(np.float32)


_WHEEL_BASE_M = 0.30
_TICKS_PER_M = 2000.0

_Event = tuple[int, int, str, object]
"""A message to log: time (ns), priority among messages of that time, topic, message."""


@dataclass(frozen=True, slots=True)
class _Route:
    """The scene and the robot's true poses (K, 3) on the odometry grid."""

    layout: Layout
    poses: np.ndarray
    spots: list[tuple[float, float]]
    """Office test spots (distance m, angle deg) in visiting order; empty in the lobby."""
    dt: float
    """Odometry step (s)."""

    def pose_at(self, t: float) -> tuple[float, float, float]:
        """The pose of the odometry step nearest ``t``."""
        k = min(len(self.poses) - 1, int(round(t / self.dt)))
        return float(self.poses[k, 0]), float(self.poses[k, 1]), float(self.poses[k, 2])


def _route(cfg: BridgeLocScenario, rng: np.random.Generator) -> _Route:
    """The field's layout and the robot's drive: office test spots, or lobby waypoints (random
    from ``rng``, or the CSV of ``cfg.path``) cut to ``duration_s``."""
    spots: list[tuple[float, float]] = []
    if cfg.field == "office":
        layout = office_layout(cfg)
        wps, spots = _office_spots(layout)
        start = (float(wps[0][0]), float(wps[0][1]))
        wps = [(start[0], start[1], wps[0][2], 0.0), *wps]
        start_yaw = float(wps[0][2] or 0.0)
        fast = 2.5  # the robot is driven quickly between test spots (only they are evaluated)
    else:
        layout = lobby_layout(cfg)
        if cfg.path == "random":
            n_wp = int(cfg.duration_s * cfg.speed_mps / 2.0) + 4
            wps = _random_waypoints(rng, layout.size, n_wp)
        else:
            wps = _csv_waypoints(cfg.path)
        start_yaw = 0.0
        fast = 1.0
    dt = 1.0 / cfg.odom_hz
    poses = _segments(wps, start_yaw, cfg.speed_mps * fast, cfg.turn_rps * fast, dt)
    if cfg.field == "lobby":
        poses = poses[: int(cfg.duration_s * cfg.odom_hz)]
    return _Route(layout, poses, spots, dt)


@dataclass(frozen=True, slots=True)
class _Lighting:
    """Per camera: vignetting and a slow lighting drift (period 40-120 s) around the nominal
    exposure."""

    drift: float
    vignettes: dict[str, np.ndarray | None]
    phase: dict[str, float]
    period: dict[str, float]

    def shade(self, camera: str, t: float) -> np.ndarray | None:
        """The gain image of ``camera`` at ``t`` (None: no shading)."""
        v = self.vignettes[camera]
        if not self.drift and v is None:
            return None
        g = 1.0 + self.drift * math.sin(2 * math.pi * t / self.period[camera] + self.phase[camera])
        return np.full((1, 1), g, np.float32) if v is None else np.float32(g) * v


@dataclass(frozen=True, slots=True)
class _Stage:
    """What the frames are rendered from: the cameras (true poses), their renderers and
    backgrounds, the clutter, the lighting and the robot's camera and tilt."""

    cfg: BridgeLocScenario
    route: _Route
    rcam: CameraModel
    rrend: _Renderer
    rbg: np.ndarray
    renderers: dict[str, _Renderer]
    backgrounds: dict[str, np.ndarray]
    posters: tuple[Poster, ...]
    lamps: tuple[tuple[float, float, float], ...]
    true_pose: dict[str, Transform]
    true_mount: Transform
    lighting: _Lighting
    pitch: np.ndarray
    roll: np.ndarray
    """Robot pitch and roll (rad) per robot frame."""


def _true_infra_poses(
    layout: Layout, real: Realism, rrng: np.random.Generator
) -> dict[str, Transform]:
    """The infrastructure cameras' true poses: the calibrated ones off by the calibration error."""
    return {
        c.camera: _perturbed(c.world_from_camera, rrng, real.infra_calib_deg, real.infra_calib_m)
        if real.infra_calib_deg or real.infra_calib_m
        else c.world_from_camera
        for c in layout.cameras
        if c.world_from_camera is not None
    }


def _stage(
    cfg: BridgeLocScenario, route: _Route, rcam: CameraModel, rng: np.random.Generator
) -> _Stage:
    """Renderers and backgrounds (from ``rng``), then the realistic preset's models, which draw
    from their own stream so that the paper preset's bytes stay."""
    layout = route.layout
    base_from_cam = rcam.world_from_camera
    assert base_from_cam is not None
    renderers = {c.camera: _Renderer(c, rng, cfg) for c in layout.cameras}
    rrend = _Renderer(rcam, rng, cfg)
    backgrounds = {c.camera: _background(c, rng, False) for c in layout.cameras}
    rbg = _background(rcam, rng, True)
    real = cfg.realism
    rrng = np.random.default_rng([cfg.seed, 4_2])
    posters = tuple(_posters(layout, real, rrng, cfg.field)) if real.posters else ()
    lamps = tuple(_lamps(layout, real, rrng)) if real.lamps else ()
    true_pose = _true_infra_poses(layout, real, rrng)
    true_mount = (
        _perturbed(base_from_cam, rrng, real.mount_deg, 0.0) if real.mount_deg else base_from_cam
    )
    all_cams = [*layout.cameras, rcam]
    vignettes = {c.camera: _vignette(c, real.vignetting) for c in all_cams}
    n_frames = len(_frame_times(route, cfg.robot_fps))
    tilt_corr = max(1, int(round(0.5 * cfg.robot_fps)))
    pitch = np.radians(_smooth_noise(rrng, n_frames, real.tilt_deg, tilt_corr))
    roll = np.radians(_smooth_noise(rrng, n_frames, real.tilt_deg, tilt_corr))
    phase = {c.camera: float(rrng.uniform(0, 2 * math.pi)) for c in all_cams}
    period = {c.camera: float(rrng.uniform(40, 120)) for c in all_cams}
    lighting = _Lighting(real.light_drift, vignettes, phase, period)
    return _Stage(
        cfg,
        route,
        rcam,
        rrend,
        rbg,
        renderers,
        backgrounds,
        posters,
        lamps,
        true_pose,
        true_mount,
        lighting,
        pitch,
        roll,
    )


def _frame_times(route: _Route, fps: float) -> np.ndarray:
    """Frame times (s) at ``fps`` over the drive."""
    duration = len(route.poses) * route.dt
    return np.arange(0.0, duration - 1e-9, 1.0 / fps)


def _odometry_events(
    route: _Route, cfg: BridgeLocScenario, rng: np.random.Generator
) -> list[_Event]:
    """Wheel odometry at every step: wheel travel from the true pose increments, scale errors
    of +-1.5 %, tick noise."""
    poses = route.poses
    dyaw = np.diff(np.unwrap(poses[:, 2]), prepend=poses[0, 2])
    ds = np.hypot(
        np.diff(poses[:, 0], prepend=poses[0, 0]), np.diff(poses[:, 1], prepend=poses[0, 1])
    )
    travel_l, travel_r = _wheel_travel(ds, dyaw, _WHEEL_BASE_M, cfg.realism, cfg.seed)
    left = np.cumsum(travel_l * _TICKS_PER_M * 1.015 + rng.normal(0, 1.0, len(ds)))
    right = np.cumsum(travel_r * _TICKS_PER_M * 0.985 + rng.normal(0, 1.0, len(ds)))
    events: list[_Event] = []
    for k in range(len(poses)):
        t_ns = int(round(k * route.dt * S))
        events.append(
            (
                t_ns,
                0,
                topics.odom(ROBOT),
                WheelOdometry(t_ns, f"robot/{ROBOT}", int(left[k]), int(right[k])),
            )
        )
    return events


def _robot_frame_events(st: _Stage) -> list[_Event]:
    """The robot camera's frames (motion-smeared by its turning) and the ground truth."""
    route, rcam, real = st.route, st.rcam, st.cfg.realism
    yaw_rate = np.gradient(np.unwrap(route.poses[:, 2]), route.dt)
    events: list[_Event] = []
    for i, tk in enumerate(_frame_times(route, st.cfg.robot_fps)):
        t_ns = int(round(tk * S))
        x, y, yaw = route.pose_at(tk)
        ideal = render_view(
            rcam,
            _compose(st.true_mount, x, y, yaw, float(st.pitch[i]), float(st.roll[i])),
            route.layout.tags,
            st.rbg,
            st.rrend.texture,
            posters=st.posters,
            lamps=st.lamps,
            shade=st.lighting.shade(ROBOT_CAMERA, float(tk)),
        )
        k = min(len(route.poses) - 1, int(round(tk / route.dt)))
        smear = abs(float(yaw_rate[k])) * real.exposure_s * rcam.fx_px
        events.append(
            (
                t_ns,
                1,
                topics.image(ROBOT_CAMERA),
                make_compressed_image(t_ns, ROBOT_CAMERA, st.rrend.finish(ideal, smear), "jpeg"),
            )
        )
        ent = GroundTruthEntity(
            ROBOT, Vec3(x, y, 0.0), yaw_rad=float(math.atan2(math.sin(yaw), math.cos(yaw)))
        )
        events.append((t_ns, 3, topics.GROUND_TRUTH, GroundTruth(t_ns, (ent,))))
    return events


def _infra_frame(st: _Stage, cam: CameraModel, tk: float, t_ns: int) -> _Event:
    """Infrastructure camera ``cam``'s frame at ``tk``: the robot drawn unless occluded."""
    x, y, yaw = st.route.pose_at(tk)
    occ = st.route.layout.occluded.get(cam.camera)
    robot = None if occ is not None and _in_poly(occ, x, y) else (x, y, yaw)
    ideal = render_view(
        cam,
        st.true_pose[cam.camera],
        st.route.layout.tags,
        st.backgrounds[cam.camera],
        st.renderers[cam.camera].texture,
        robot,
        st.cfg.ir_height_m,
        st.cfg.ir_range_m,
        posters=st.posters,
        lamps=st.lamps,
        shade=st.lighting.shade(cam.camera, float(tk)),
        ir_offset_m=st.cfg.realism.ir_offset_m,
    )
    jpeg = st.renderers[cam.camera].finish(ideal)
    return (
        t_ns,
        2,
        topics.image(cam.camera),
        make_compressed_image(t_ns, cam.camera, jpeg, "jpeg"),
    )


def _infra_frame_events(st: _Stage) -> list[_Event]:
    """Every infrastructure camera's frames, time by time."""
    events: list[_Event] = []
    for tk in _frame_times(st.route, st.cfg.infra_fps):
        t_ns = int(round(tk * S))
        events.extend(_infra_frame(st, cam, tk, t_ns) for cam in st.route.layout.cameras)
    return events


def _write_log(
    out: str | Path,
    cfg: BridgeLocScenario,
    route: _Route,
    rcam: CameraModel,
    events: list[_Event],
) -> dict[str, int]:
    """Metadata, camera models at 0, then ``events``; message counts per topic."""
    layout = route.layout
    counts: dict[str, int] = {}
    with LogWriter(str(out)) as w:
        meta = {
            "generator": "trackctl simulate bridgeloc",
            "field": cfg.field,
            "seed": str(cfg.seed),
            "preset": cfg.preset,
            "robot": ROBOT,
            "robot_camera": ROBOT_CAMERA,
            "infra_cameras": ",".join(c.camera for c in layout.cameras),
            "tag_n": str(cfg.n),
            "tag_family": cfg.family,
            "tag_size_m": str(cfg.tag_size_m),
            "border_ratio": "5.0",
            "ir_height_m": str(cfg.ir_height_m),
            "tags_truth": json.dumps([t.to_json() for t in layout.tags]),
            "office_spots": json.dumps(route.spots),
        }
        w.add_metadata("bridgeloc", meta)
        w.add_metadata(
            f"robot/{ROBOT}",
            {"ticks_per_m": str(_TICKS_PER_M), "wheel_base_m": str(_WHEEL_BASE_M)},
        )
        for cam in [*layout.cameras, rcam]:
            w.write(topics.camera_model(cam.camera), cam, 0)
            counts[topics.camera_model(cam.camera)] = 1
        for t_ns, _, topic, msg in events:
            w.write(topic, msg, t_ns)
            counts[topic] = counts.get(topic, 0) + 1
    return counts


def simulate_bridgeloc(out: str | Path, cfg: BridgeLocScenario | None = None) -> dict[str, int]:
    """Write a BridgeLoc scenario log to ``out``; returns message counts per topic."""
    cfg = cfg or BridgeLocScenario()
    rng = np.random.default_rng(cfg.seed)
    route = _route(cfg, rng)
    rcam = robot_camera_model(cfg.camera_height_m)
    st = _stage(cfg, route, rcam, rng)
    events = _odometry_events(route, cfg, rng)
    events += _robot_frame_events(st)
    events += _infra_frame_events(st)
    events.sort(key=lambda e: (e[0], e[1]))
    return _write_log(out, cfg, route, rcam, events)
