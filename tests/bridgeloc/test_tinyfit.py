"""The tiny-tag model fit: far tags located to a fraction of a pixel, nothing found in clutter."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from trackctl.bridgeloc.detect import DetectorConfig, detect_tags
from trackctl.bridgeloc.tags import Mount, Placement, tag_texture
from trackctl.bridgeloc.tinyfit import fit_tiny_tag
from trackctl.geometry.camera import PinholeCamera
from trackctl.logs.messages import Quat, Transform, Vec3
from trackctl.sim.bridgeloc import (
    BridgeLocScenario,
    WallTag,
    _infra,
    _Renderer,
    render_view,
    tag_corners,
)


def _far_view(code, d: float, n: int = 2, seed: int = 0):  # noqa: ANN001, ANN202
    """A 30 cm tag ``d`` metres in front of the 50° infrastructure camera (640x480)."""
    from dataclasses import replace

    model = replace(
        _infra("c", (0.0, 0.0, 1.0), (5.0, 0.0, 1.0)),
        world_from_camera=Transform(Vec3(0.0, 0.0, 1.0), Quat(0.5, -0.5, 0.5, -0.5)),
    )
    ren = _Renderer(model, np.random.default_rng(seed), BridgeLocScenario(n=n, preset="paper"))
    tag = WallTag("t", code, Placement.SQUARE, Mount.ABOVE, (d, 0.03, 1.02), (-1.0, 0.0), 0.3)
    bg = np.full((480, 640), 110, np.uint8)
    ideal = render_view(model, model.world_from_camera, [tag], bg, ren.texture)
    img = cv2.imdecode(np.frombuffer(ren.finish(ideal), np.uint8), cv2.IMREAD_GRAYSCALE)
    truth, _ = PinholeCamera(model).project(tag_corners(tag))
    return img, truth


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_far_tag_is_read_only_with_the_fit(seed: int) -> None:
    code = (1, 0, 1, 0)
    img, truth = _far_view(code, 33.0, seed=seed)  # the tag is 6.2 px wide
    assert np.linalg.norm(truth[1] - truth[0]) < 6.5
    assert not [d for d in detect_tags(img, DetectorConfig(fit=None)) if d.code == code]
    (det,) = detect_tags(img)
    assert det.code == code and det.placement is Placement.SQUARE
    assert np.abs(det.corners - truth).max() < 0.6  # located to a fraction of a pixel


def test_fit_tightens_a_lopsided_start() -> None:
    img, truth = _far_view((0, 1, 1, 0), 30.0)
    start = truth + np.array([[0.9, -0.6], [1.4, -0.6], [1.4, 0.8], [0.9, 0.8]])  # off and wide
    got = fit_tiny_tag(img, start, 2, 5.0)
    assert got is not None
    assert np.abs(got.corners - truth).max() < 0.5
    assert got.contrast > 100 and got.rms < 0.12 * got.contrast


def _synthetic(centre: tuple[float, float], side: float, angle: float, code, n: int):  # noqa: ANN001, ANN202
    """A tag drawn by OpenCV (texture warp + blur + noise), independent of the fit's model."""
    ss = 8
    tex = tag_texture(code, n, 64 * n, margin=0.25, white=205, black=30)
    big = np.full((60 * ss, 60 * ss), 110, np.uint8)
    scale = side * ss / (64 * n)
    # pixel centres are integers at both scales: texel (w-1)/2 is the tag's centre, and pixel x
    # of the small image covers big pixels around (x + 0.5) * ss - 0.5
    tc = ((tex.shape[1] - 1) / 2, (tex.shape[0] - 1) / 2)
    rot = cv2.getRotationMatrix2D(tc, math.degrees(angle), scale)
    rot[:, 2] += (np.array(centre) + 0.5) * ss - 0.5 - np.array(tc)
    warped = cv2.warpAffine(tex, rot, big.shape[::-1], flags=cv2.INTER_AREA, borderValue=0)
    mask = cv2.warpAffine(np.full_like(tex, 255), rot, big.shape[::-1], borderValue=0)
    big = np.where(mask > 127, warped, big).astype(np.uint8)
    img = cv2.resize(big, (60, 60), interpolation=cv2.INTER_AREA)
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    noise = np.random.default_rng(0).normal(0, 2.0, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


@settings(max_examples=examples(25), deadline=None)
@given(
    cx=st.floats(25.0, 35.0),
    cy=st.floats(25.0, 35.0),
    side=st.floats(6.0, 11.0),
    angle=st.floats(-0.15, 0.15),
    n=st.sampled_from([2, 3]),
)
def test_fit_recovers_centre_and_size(
    cx: float, cy: float, side: float, angle: float, n: int
) -> None:
    code = tuple(([1, 0] * (n * n))[: n * n])
    img = _synthetic((cx, cy), side, angle, code, n)
    # a start off by a pixel and 15 % too small, as a far tag's quiet-zone hole gives
    h = side * 0.85 / 2
    start = np.array([[-h, -h], [h, -h], [h, h], [-h, h]]) + [cx + 0.8, cy - 0.6]
    got = fit_tiny_tag(img, start, n, 5.0)
    assert got is not None
    assert np.linalg.norm(got.corners.mean(axis=0) - [cx, cy]) < 0.35
    sides = np.linalg.norm(got.corners - np.roll(got.corners, 1, axis=0), axis=1)
    assert np.abs(sides - side).max() < 0.1 * side


def test_clutter_gives_no_tags() -> None:
    rng = np.random.default_rng(3)
    img = cv2.GaussianBlur(rng.integers(60, 200, (480, 640)).astype(np.uint8), (0, 0), 1.2)
    assert detect_tags(img) == []
    # a dark speck without a white margin, and a uniform dark square with one: no code
    grey = np.full((120, 120), 110, np.uint8)
    cv2.rectangle(grey, (30, 30), (35, 35), 30, -1)
    cv2.rectangle(grey, (68, 68), (81, 81), 205, -1)
    cv2.rectangle(grey, (71, 71), (78, 78), 30, -1)
    assert detect_tags(cv2.GaussianBlur(grey, (0, 0), 0.7)) == []
