"""Rendering of simulated camera frames: a textured floor and people drawn in perspective.

The images are simple but real pixels: a detector working on them sees perspective scale changes,
people hiding each other (drawn far to near), sensor noise and JPEG artefacts. Everything is
deterministic for a given random generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from trackctl.geometry.camera import PinholeCamera

__all__ = ["PersonLook", "floor_image", "render_frame", "person_outline", "draw_shadow"]

PERSON_HEIGHT_M = 1.7
SHOULDER_M = 0.46
HEAD_RADIUS_M = 0.11


@dataclass(frozen=True, slots=True)
class PersonLook:
    """Clothing colours of one person (BGR)."""

    shirt: tuple[int, int, int]
    trousers: tuple[int, int, int]

    @classmethod
    def random(cls, rng: np.random.Generator) -> PersonLook:
        """Saturated shirt, dark trousers: people stand out from the grey floor."""
        hue = int(rng.integers(0, 180))
        hsv = np.array(
            [[[hue, int(rng.integers(120, 255)), int(rng.integers(90, 220))]]], dtype=np.uint8
        )
        shirt = tuple(int(c) for c in cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0])
        dark = int(rng.integers(20, 70))
        return cls(shirt, (dark, dark, dark + int(rng.integers(0, 30))))  # type: ignore[arg-type]


def floor_image(cam: PinholeCamera, rng: np.random.Generator, tile_m: float = 1.0) -> np.ndarray:
    """The empty scene seen by ``cam``: a light floor with smooth shading, tile joints and
    blotches (texture a background model must cope with), and a wall colour above the horizon."""
    m = cam.model
    h, w = m.height_px, m.width_px
    low = rng.normal(0, 1, (h // 32 + 2, w // 32 + 2)).astype(np.float32)
    shade = cv2.resize(low, (w, h), interpolation=cv2.INTER_CUBIC)
    base = 175 + 12 * shade
    img = np.repeat(base[:, :, None], 3, axis=2)
    img[:, :, 0] += 8  # a cool grey
    img = np.clip(img, 0, 255).astype(np.uint8)
    # tile joints: project a world grid on the floor
    pos = cam.position
    reach = 40.0
    lines = []
    for k in np.arange(np.floor((pos[0] - reach) / tile_m), np.ceil((pos[0] + reach) / tile_m)):
        x = k * tile_m
        lines.append(((x, pos[1] - reach), (x, pos[1] + reach)))
    for k in np.arange(np.floor((pos[1] - reach) / tile_m), np.ceil((pos[1] + reach) / tile_m)):
        y = k * tile_m
        lines.append(((pos[0] - reach, y), (pos[0] + reach, y)))
    for (x0, y0), (x1, y1) in lines:
        seg = np.linspace([x0, y0, 0.0], [x1, y1, 0.0], 80)
        px, front = cam.project(seg)
        pts = px[front]
        if len(pts) >= 2:
            cv2.polylines(img, [pts.astype(np.int32)], False, (150, 150, 158), 1, cv2.LINE_AA)
    # walls: everything above the projected horizon of the far floor
    sky = cam.ground_point(np.column_stack([np.arange(w), np.zeros(w)]))
    if np.isnan(sky).any():
        img[: h // 6] = (120, 135, 150)
    return img


def person_outline(cam: PinholeCamera, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Foot and head pixels of a person standing at ``xy`` and the body width in pixels."""
    foot = np.array([xy[0], xy[1], 0.0])
    head = np.array([xy[0], xy[1], PERSON_HEIGHT_M])
    px, _ = cam.project(np.stack([foot, head]))
    depth = float(cam.to_camera(foot[None])[0, 2])
    width_px = cam.model.fx_px * SHOULDER_M / max(depth, 1e-6)
    return px[0], px[1], width_px


SHADOW_AZIMUTH_RAD = math.radians(35.0)
"""Direction the shadows fall in (world frame), from a lamp at ``SHADOW_ELEVATION_RAD``."""
SHADOW_ELEVATION_RAD = math.radians(50.0)
SHADOW_DARKNESS = 0.55
"""Floor brightness inside a shadow (indoor lamps: 40-60% of the lit floor)."""


def draw_shadow(img: np.ndarray, cam: PinholeCamera, xy: np.ndarray) -> None:
    """Darken the floor where a person at ``xy`` casts their shadow: a body-wide strip from the
    feet, PERSON_HEIGHT / tan(elevation) long, soft-edged."""
    d = np.array([math.cos(SHADOW_AZIMUTH_RAD), math.sin(SHADOW_AZIMUTH_RAD)])
    n = np.array([-d[1], d[0]])
    length = PERSON_HEIGHT_M / math.tan(SHADOW_ELEVATION_RAD)
    half = SHOULDER_M / 2
    corners = [xy + n * half, xy - n * half, xy + d * length - n * half * 0.6]
    corners.append(xy + d * length + n * half * 0.6)
    ground = np.column_stack([np.array(corners), np.zeros(4)])
    px, front = cam.project(ground)
    if not front.all():
        return
    mask = np.zeros(img.shape[:2], np.float32)
    cv2.fillConvexPoly(mask, np.round(px).astype(np.int32), 1.0, cv2.LINE_AA)
    soft = cv2.GaussianBlur(mask, (5, 5), 0)
    factor = 1.0 - (1.0 - SHADOW_DARKNESS) * soft
    img[:] = np.clip(img.astype(np.float32) * factor[:, :, None], 0, 255).astype(np.uint8)


def render_frame(
    cam: PinholeCamera,
    background: np.ndarray,
    people: list[tuple[np.ndarray, PersonLook]],
    rng: np.random.Generator,
    noise_std: float = 3.0,
    shadows: bool = False,
) -> np.ndarray:
    """One frame: ``people`` (ground xy, look) drawn far to near over ``background``; with
    ``shadows``, each casts a shadow on the floor first (see :func:`draw_shadow`)."""
    img = background.copy()
    if shadows:
        for xy, _ in people:
            draw_shadow(img, cam, xy)
    order = []
    for xy, look in people:
        depth = float(cam.to_camera(np.array([[xy[0], xy[1], 0.0]]))[0, 2])
        if depth > 0.3:
            order.append((depth, xy, look))
    order.sort(key=lambda o: -o[0])
    for _, xy, look in order:
        foot, head, wpx = person_outline(cam, xy)
        hpx = float(np.linalg.norm(foot - head))
        if hpx < 4:
            continue
        up = (head - foot) / hpx  # image direction of the body axis
        side = np.array([-up[1], up[0]])
        r_head = max(1.0, hpx * HEAD_RADIUS_M / PERSON_HEIGHT_M)
        neck = foot + up * (hpx - 2.2 * r_head)
        hip = foot + up * hpx * 0.47
        half = wpx / 2
        torso = np.array(
            [
                hip - side * half * 0.85,
                hip + side * half * 0.85,
                neck + side * half,
                neck - side * half,
            ]
        )
        legs = np.array(
            [
                foot - side * half * 0.7,
                foot + side * half * 0.7,
                hip + side * half * 0.85,
                hip - side * half * 0.85,
            ]
        )
        cv2.fillConvexPoly(img, np.round(legs).astype(np.int32), look.trousers, cv2.LINE_AA)
        cv2.fillConvexPoly(img, np.round(torso).astype(np.int32), look.shirt, cv2.LINE_AA)
        centre = foot + up * (hpx - r_head)
        cv2.circle(
            img,
            tuple(int(v) for v in np.round(centre)),
            int(round(r_head)),
            (60, 80, 120),
            -1,
            cv2.LINE_AA,
        )
    if noise_std > 0:
        noise = rng.normal(0.0, noise_std, img.shape[:2]).astype(np.float32)
        img = np.clip(img.astype(np.float32) + noise[:, :, None], 0, 255).astype(np.uint8)
    return img
