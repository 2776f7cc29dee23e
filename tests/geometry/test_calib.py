"""Camera calibration on the floor: Tsai import, floor pose from point pairs, sanity checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import ROOT, examples, shared_file
from trackctl.geometry.calib import (
    TsaiCamera,
    camera_geometry,
    camera_problems,
    ground_pose,
    pose_vectors,
    scale_translation,
    tsai_model,
    tsai_project,
    with_pose,
)
from trackctl.geometry.camera import PinholeCamera, look_at
from trackctl.ingest.calibration import read_calibration, read_point_pairs, read_tsai_xml
from trackctl.logs.messages import CameraModel

POINTS = ROOT / "tests" / "data" / "pets2009_view001_floor_points.csv"


def _camera(eye: tuple[float, float, float], target: tuple[float, float, float]) -> CameraModel:
    return CameraModel(
        0,
        "c",
        640,
        480,
        600.0,
        600.0,
        320.0,
        240.0,
        distortion=(-0.1, 0.02, 0.0, 0.0, 0.0),
        world_from_camera=look_at(np.array(eye), np.array(target)),
    )


def _floor_grid(cam: PinholeCamera) -> np.ndarray:
    u, v = np.meshgrid(
        np.linspace(0, cam.model.width_px - 1, 24), np.linspace(0, cam.model.height_px - 1, 18)
    )
    return np.column_stack([u.ravel(), v.ravel()])


def test_pets_tsai_xml_imports_within_a_pixel_of_the_converted_yaml() -> None:
    xml = shared_file("footage", "pets2009_View_001.xml")
    converted = PinholeCamera(
        read_calibration(shared_file("footage", "pets2009_view001.yaml"), "c")
    )
    imported = PinholeCamera(read_calibration(xml, "c"))  # Tsai's unit (mm) by default
    gx, gy = np.meshgrid(np.linspace(-30, 30, 61), np.linspace(-30, 30, 61))
    world = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    seen = converted.visible(world)
    assert seen.sum() > 200
    a, _ = converted.project(world[seen])
    b, _ = imported.project(world[seen])
    assert np.abs(a - b).max() < 1.0
    # and the conversion agrees with Tsai's own projection (distortion solved exactly)
    c = tsai_project(read_tsai_xml(xml), world[seen])
    assert np.abs(b - c).max() < 0.05
    assert camera_geometry(imported.model).height_m == pytest.approx(7.07, abs=0.01)


@settings(max_examples=examples(40), deadline=None)
@given(
    kappa=st.floats(-0.02, 0.02),
    focal=st.floats(3.0, 12.0),
    sx=st.floats(0.9, 1.1),
)
def test_tsai_conversion_matches_tsai_projection(kappa: float, focal: float, sx: float) -> None:
    tsai = TsaiCamera(
        width=768,
        height=576,
        dpx=0.005,
        dpy=0.005,
        focal=focal,
        kappa1=kappa,
        cx=380.0,
        cy=290.0,
        sx=sx,
        t=(0.0, 0.0, 10_000.0),
        r=(math.pi, 0.0, 0.0),
    )
    model = tsai_model(tsai, "c")
    cam = PinholeCamera(model)
    # points on a plane in front of the camera that land inside the image
    fx, fy = model.fx_px, model.fy_px
    u, v = np.meshgrid(np.linspace(0, 767, 12), np.linspace(0, 575, 10))
    xn, yn = (u.ravel() - 380) / fx, (v.ravel() - 290) / fy
    cam_pts = np.column_stack([xn * 10, yn * 10, np.full(xn.size, 10.0)])
    world = (cam_pts - np.array([0, 0, 10.0])) @ tsai.rotation()  # R^T (Xc - T)
    ours, _ = cam.project(world)
    theirs = tsai_project(tsai, world)
    inside = (theirs[:, 0] >= 0) & (theirs[:, 0] < 768) & (theirs[:, 1] >= 0) & (theirs[:, 1] < 576)
    assert inside.sum() > 20
    assert np.abs(ours - theirs)[inside].max() < 0.5


def test_pets_floor_points_reproduce_the_published_floor_projection() -> None:
    shipped = read_calibration(shared_file("footage", "pets2009_view001.yaml"), "c")
    img, world = read_point_pairs(POINTS)
    assert len(img) == 6
    fit = ground_pose(shipped, img, world)
    assert fit.rms_px < 1.0
    a = PinholeCamera(shipped).ground_point(_floor_grid(PinholeCamera(shipped)))
    b = PinholeCamera(fit.model).ground_point(_floor_grid(PinholeCamera(shipped)))
    near = np.linalg.norm(a[:, :2] - PinholeCamera(shipped).position[:2], axis=1) < 40
    ok = near & ~np.isnan(a).any(axis=1) & ~np.isnan(b).any(axis=1)
    assert ok.sum() > 200
    assert np.linalg.norm(a - b, axis=1)[ok].max() < 0.2


@settings(max_examples=examples(30), deadline=None)
@given(
    x=st.floats(-5, 5),
    y=st.floats(-5, 5),
    h=st.floats(2.0, 8.0),
    yaw=st.floats(-math.pi, math.pi),
    reach=st.floats(4.0, 10.0),
)
def test_ground_pose_recovers_a_camera_from_exact_floor_points(
    x: float, y: float, h: float, yaw: float, reach: float
) -> None:
    target = (x + reach * math.cos(yaw), y + reach * math.sin(yaw), 0.0)
    true = PinholeCamera(_camera((x, y, h), target))
    px = np.array([[100, 300], [540, 300], [320, 460], [60, 470], [600, 420], [320, 330]], float)
    world = true.ground_point(px)
    assert not np.isnan(world).any()
    fit = ground_pose(true.model, px, world[:, :2])
    assert fit.max_px < 1e-3
    assert np.allclose(PinholeCamera(fit.model).position, true.position, atol=1e-4)


def test_ground_pose_refuses_too_few_or_collinear_points() -> None:
    cam = _camera((0, 0, 3), (4, 0, 0))
    with pytest.raises(ValueError, match="at least 4"):
        ground_pose(cam, np.zeros((3, 2)), np.zeros((3, 2)))
    line = np.column_stack([np.arange(5.0), np.zeros(5)])
    with pytest.raises(ValueError, match="one line"):
        ground_pose(cam, np.arange(10.0).reshape(5, 2), line)


def test_pose_vectors_round_trip_and_unit_scaling() -> None:
    cam = _camera((1, 2, 3), (5, 2, 0))
    rvec, tvec = pose_vectors(cam)
    again = with_pose(cam, rvec, tvec)
    assert np.allclose(PinholeCamera(again).position, [1, 2, 3])
    in_mm = with_pose(cam, rvec, tvec * 1000)
    assert np.allclose(PinholeCamera(scale_translation(in_mm, 1e-3)).position, [1, 2, 3])


def test_camera_problems_name_unit_frame_and_size_mistakes() -> None:
    good = _camera((0, 0, 3), (4, 0, 0))
    assert camera_problems(good, (640, 480)) == ([], [])
    errors, _ = camera_problems(good, (768, 576))
    assert "640x480" in errors[0] and "768x576" in errors[0]
    rvec, tvec = pose_vectors(good)
    errors, _ = camera_problems(with_pose(good, rvec, tvec * 1000))
    assert "millimetres" in errors[0]
    below = _camera((0, 0, -3), (4, 0, -6))
    assert "below the floor" in camera_problems(below)[0][0]
    sky = _camera((0, 0, 3), (4, 0, 8))
    assert "no pixel sees the floor" in camera_problems(sky)[0][0]
    low = _camera((0, 0, 0.1), (4, 0, 0))
    assert "only 0.10 m" in camera_problems(low)[1][0]
