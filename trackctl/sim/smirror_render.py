"""Rendering of S-Mirror node frames: a textured three-room floor plan seen by a calibrated camera,
with walking people and a robot carrying two coloured LEDs.

Real pixels, so that the processor's background subtraction, foreground JPEG sizes and LED
detection are measured on images, not assumed. A static background (floor texture warped through
the ground homography, walls painted far to near) is built once per node; each frame copies it,
draws the moving things far to near (nearer ones occlude farther ones) and adds sensor noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from trackctl.geometry.camera import PinholeCamera
from trackctl.geometry.floorplan import FloorPlan, Wall, line_of_sight, three_rooms

__all__ = [
    "FloorPlan",
    "Wall",
    "RobotShape",
    "NodeRenderer",
    "line_of_sight",
    "three_rooms",
    "LED_FRONT_BGR",
    "LED_BACK_BGR",
]

LED_FRONT_BGR = (60, 255, 60)
"""Front LED: saturated green."""
LED_BACK_BGR = (255, 60, 255)
"""Back LED: saturated magenta (no floor, wall or clothing colour is that saturated)."""


@dataclass(frozen=True)
class RobotShape:
    """Body box and LED placement of the robot (metres, in the robot frame: x forward)."""

    length_m: float = 0.45
    width_m: float = 0.35
    height_m: float = 0.26
    led_height_m: float = 0.32
    led_front_m: float = 0.15
    led_back_m: float = -0.15
    led_radius_m: float = 0.035
    front_bgr: tuple[int, int, int] = LED_FRONT_BGR
    back_bgr: tuple[int, int, int] = LED_BACK_BGR
    """LED colours (robots of one fleet may carry different pairs to tell each other apart)."""


def _clip_near(pts_c: np.ndarray, near: float = 0.05) -> np.ndarray:
    """Sutherland-Hodgman clip of a camera-frame polygon against the plane z = near."""
    out = []
    n = len(pts_c)
    for i in range(n):
        a, b = pts_c[i], pts_c[(i + 1) % n]
        ina, inb = a[2] >= near, b[2] >= near
        if ina:
            out.append(a)
        if ina != inb:
            t = (near - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.array(out)


class NodeRenderer:
    """Renders the frames of one node camera (true pose) over a floor plan."""

    def __init__(
        self, cam: PinholeCamera, plan: FloorPlan, rng: np.random.Generator, noise_sigma: float
    ) -> None:
        self.cam = cam
        self.plan = plan
        self.w = cam.model.width_px
        self.h = cam.model.height_px
        self.background = self._background(rng)
        # A small bank of noise images, picked and shifted per frame: fresh-looking sensor noise
        # at the cost of one add instead of a Gaussian draw of the whole frame.
        self._noise = [
            np.clip(rng.normal(0.0, noise_sigma, (self.h, self.w, 3)) + 8, 0, 255).astype(np.uint8)
            for _ in range(4)
        ]
        self._offset = np.full((self.h, self.w, 3), 8, np.uint8)

    # -- static background -------------------------------------------------------------------
    def _project_cam(self, pts_c: np.ndarray) -> np.ndarray:
        k = self.cam.K
        return np.column_stack(
            [
                k[0, 0] * pts_c[:, 0] / pts_c[:, 2] + k[0, 2],
                k[1, 1] * pts_c[:, 1] / pts_c[:, 2] + k[1, 2],
            ]
        )

    def _poly(self, pts_w: np.ndarray) -> np.ndarray | None:
        clipped = _clip_near(self.cam.to_camera(pts_w))
        if len(clipped) < 3:
            return None
        return np.round(self._project_cam(clipped) * 16).astype(np.int32)

    def _background(self, rng: np.random.Generator) -> np.ndarray:
        img = np.empty((self.h, self.w, 3), np.uint8)
        img[:] = (205, 210, 215)  # ceiling
        # floor: a texture of the whole plan (tiles + grain) warped through the ground homography
        ppm = 40
        sx, sy = self.plan.size_m
        tex = np.empty((int(sy * ppm), int(sx * ppm), 3), np.uint8)
        tex[:] = (150, 160, 165)
        for i in range(int(sx / 0.6) + 1):
            for j in range(int(sy / 0.6) + 1):
                shade = int(rng.integers(-18, 18))
                x0, y0 = int(i * 0.6 * ppm), int(j * 0.6 * ppm)
                cv2.rectangle(
                    tex,
                    (x0 + 1, y0 + 1),
                    (x0 + int(0.6 * ppm) - 1, y0 + int(0.6 * ppm) - 1),
                    (150 + shade, 158 + shade, 163 + shade),
                    -1,
                )
        grain = rng.normal(0, 6, tex.shape[:2])
        tex = np.clip(tex + cv2.GaussianBlur(grain, (0, 0), 1.5)[..., None], 0, 255).astype(
            np.uint8
        )
        # texture pixel (u, v) <-> world (u / ppm, v / ppm, 0)
        # a homography from 4 world points only works if all 4 are in front; use an inner grid
        grid = np.array(
            [[x, y, 0.0] for x in np.linspace(0, sx, 7) for y in np.linspace(0, sy, 5)], float
        )
        depth = self.cam.to_camera(grid)[:, 2]
        front = depth > 0.5
        px, _ = self.cam.project(grid[front])
        hmat, _ = cv2.findHomography(
            (grid[front, :2] * ppm).astype(np.float32), px.astype(np.float32)
        )
        floor = cv2.warpPerspective(
            tex,
            hmat,
            (self.w, self.h),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=(205, 210, 215),  # beyond the plan: over the wall tops, the ceiling
        )
        # pixels whose ray goes down hit the floor; the others see the ceiling
        uu, vv = np.meshgrid(np.arange(self.w), np.arange(self.h))
        k = self.cam.K
        rays = np.stack(
            [(uu - k[0, 2]) / k[0, 0], (vv - k[1, 2]) / k[1, 1], np.ones_like(uu, float)], -1
        )
        down = (rays @ self.cam.world_R_cam.T)[..., 2] < -1e-3
        img[down] = floor[down]
        # walls far to near, with a skirting band so they are not flat colour
        eye = self.cam.position[:2]
        order = sorted(
            self.plan.walls,
            key=lambda wl: -float(np.linalg.norm((np.add(wl[0], wl[1]) / 2) - eye)),
        )
        hgt = self.plan.wall_height_m
        for a, b in order:
            self._paint_wall(img, a, b, hgt, rng)
        return img

    def _paint_wall(
        self,
        img: np.ndarray,
        a: tuple[float, float],
        b: tuple[float, float],
        hgt: float,
        rng: np.random.Generator,
    ) -> None:
        """A wall with posters, a skirting board and plaster grain, warped onto its image area."""
        length = math.dist(a, b)
        ppm = 40
        tw, th = max(8, int(length * ppm)), int(hgt * ppm)
        tone = 190 + int(rng.integers(-12, 12))
        tex = np.empty((th, tw, 3), np.uint8)
        tex[:] = (tone - 20, tone - 5, tone)
        for _ in range(int(length / 2.5)):
            pw, ph = int(rng.uniform(0.5, 1.2) * ppm), int(rng.uniform(0.5, 1.0) * ppm)
            px0 = int(rng.uniform(0, max(1, tw - pw)))
            py0 = int(rng.uniform(0.6, 1.2) * ppm)
            # muted colours only: nothing in the scene may look like a saturated LED
            grey = int(rng.integers(80, 200))
            color = tuple(int(np.clip(grey + t, 0, 255)) for t in rng.integers(-25, 26, 3))
            cv2.rectangle(tex, (px0, py0), (px0 + pw, py0 + ph), color, -1)
            for _ in range(4):  # print on the poster
                y = int(rng.uniform(py0 + 3, py0 + ph - 3))
                cv2.line(tex, (px0 + 4, y), (px0 + pw - 4, y), (230, 230, 225), 1)
        cv2.rectangle(tex, (0, th - int(0.12 * ppm)), (tw, th), (70, 75, 80), -1)
        grain = cv2.GaussianBlur(rng.normal(0, 7, (th, tw)), (0, 0), 1.2)
        tex = np.clip(tex + grain[..., None], 0, 255).astype(np.uint8)
        # texture (u, v) <-> wall point a + (b - a) * u / tw at height hgt * (1 - v / th)
        grid_u, grid_v = np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1, 4))
        u, v = grid_u.ravel(), grid_v.ravel()
        pts = np.column_stack([a[0] + (b[0] - a[0]) * u, a[1] + (b[1] - a[1]) * u, hgt * (1 - v)])
        front = self.cam.to_camera(pts)[:, 2] > 0.3
        if front.sum() < 4:
            return
        px, _ = self.cam.project(pts[front])
        src = np.column_stack([u[front] * tw, v[front] * th]).astype(np.float32)
        hmat, _ = cv2.findHomography(src, px.astype(np.float32))
        if hmat is None:
            return
        quad = np.array([[*a, 0.0], [*b, 0.0], [*b, hgt], [*a, hgt]], float)
        poly = self._poly(quad)
        if poly is None:
            return
        mask = np.zeros((self.h, self.w), np.uint8)
        cv2.fillPoly(mask, [poly], 255, cv2.LINE_8, 4)
        x, y, w, h = cv2.boundingRect(mask)
        if w == 0 or h == 0:
            return
        # warp only the wall's bounding box of the image
        shift = np.array([[1, 0, -x], [0, 1, -y], [0, 0, 1.0]])
        warped = cv2.warpPerspective(tex, shift @ hmat, (w, h), flags=cv2.INTER_LINEAR)
        sel = mask[y : y + h, x : x + w] > 0
        img[y : y + h, x : x + w][sel] = warped[sel]

    # -- dynamic content ---------------------------------------------------------------------
    def _visible(self, xy: np.ndarray) -> bool:
        return line_of_sight(self.cam.position[:2], xy, self.plan.walls)

    def _draw_person(self, img: np.ndarray, xy: np.ndarray, color: tuple[int, int, int]) -> None:
        foot = np.array([xy[0], xy[1], 0.0])
        head = np.array([xy[0], xy[1], 1.7])
        away = np.r_[xy - self.cam.position[:2], 0.0]
        away /= max(1e-6, float(np.linalg.norm(away)))
        side = np.array([xy[0], xy[1], 0.85]) + 0.25 * np.cross([0, 0, 1.0], away)
        pts = np.stack([foot, head, side])
        if (self.cam.to_camera(pts)[:, 2] < 0.3).any():
            return
        px, _ = self.cam.project(pts)
        (fx, fy), (hx, hy), (sx, sy) = px
        half_w = max(2.0, abs(sx - (fx + hx) / 2))
        cx, cy = (fx + hx) / 2, (fy + hy) / 2
        if not (-200 < cx < self.w + 200 and -400 < cy < self.h + 400):
            return
        cv2.ellipse(
            img, (int(cx), int(cy)), (int(half_w), int(abs(fy - hy) / 2)), 0, 0, 360, color, -1
        )
        # a head of skin tone: a second blob so people are not uniform ellipses
        cv2.circle(
            img, (int(hx), int(hy + half_w * 0.6)), max(1, int(half_w * 0.6)), (120, 150, 190), -1
        )

    def _draw_robot(self, img: np.ndarray, pose: np.ndarray, shape: RobotShape) -> None:
        x, y, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s], [s, c]])
        hl, hw = shape.length_m / 2, shape.width_m / 2
        base = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]]) @ rot.T + [x, y]
        box = np.vstack(
            [
                np.column_stack([base, np.zeros(4)]),
                np.column_stack([base, np.full(4, shape.height_m)]),
            ]
        )
        if (self.cam.to_camera(box)[:, 2] < 0.3).any():
            return
        px, _ = self.cam.project(box)
        hull = cv2.convexHull(np.round(px * 16).astype(np.int32))
        cv2.fillConvexPoly(img, hull, (50, 45, 40), cv2.LINE_AA, 4)
        top, _ = self.cam.project(box[4:])
        cv2.fillConvexPoly(img, np.round(top * 16).astype(np.int32), (80, 75, 70), cv2.LINE_AA, 4)
        leds = ((shape.led_front_m, shape.front_bgr), (shape.led_back_m, shape.back_bgr))
        for off, color in leds:
            led = np.array([[x + off * c, y + off * s, shape.led_height_m]])
            ((u, v),) = self.cam.project(led)[0]
            depth = float(self.cam.to_camera(led)[0, 2])
            # a bright LED blooms over a couple of pixels however far it is
            r = max(2.0, self.cam.model.fx_px * shape.led_radius_m / depth)
            center = (int(round(u * 16)), int(round(v * 16)))
            cv2.circle(img, center, int(round(r * 16)), color, -1, cv2.LINE_AA, 4)

    def render(
        self,
        people: list[tuple[np.ndarray, tuple[int, int, int]]],
        robots: list[np.ndarray],
        shape: RobotShape | list[RobotShape],
        rng: np.random.Generator,
    ) -> np.ndarray:
        """One BGR frame: the background, then people and robots far to near, then noise.
        ``shape`` is every robot's, or one per robot."""
        shapes = shape if isinstance(shape, list) else [shape] * len(robots)
        img = self.background.copy()
        eye = self.cam.position[:2]
        things: list[tuple[float, str, object]] = []
        for xy, color in people:
            if np.isfinite(xy).all() and self._visible(xy):
                things.append((float(np.linalg.norm(xy - eye)), "p", (xy, color)))
        for pose, body in zip(robots, shapes, strict=True):
            if self._visible(pose[:2]):
                things.append((float(np.linalg.norm(pose[:2] - eye)), "r", (pose, body)))
        for _, kind, obj in sorted(things, key=lambda t: -t[0]):
            if kind == "p":
                self._draw_person(img, *obj)  # type: ignore[misc]
            else:
                self._draw_robot(img, *obj)  # type: ignore[misc]
        k = int(rng.integers(len(self._noise)))
        shift = int(rng.integers(self.w))
        noise = np.roll(self._noise[k], shift, axis=1)
        img = cv2.subtract(cv2.add(img, noise), self._offset)
        return img
