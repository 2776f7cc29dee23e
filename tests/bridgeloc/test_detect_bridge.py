"""Detection/decoding on rendered views, bridging (Eq. 4.9 and solvePnP), the EKF."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackctl.bridgeloc.bridge import CameraGeometry, bridge_lstsq, bridge_pnp
from trackctl.bridgeloc.detect import detect_tags, order_corners
from trackctl.bridgeloc.ekf import RobotEkf
from trackctl.bridgeloc.tags import Mount, Placement
from trackctl.geometry.camera import PinholeCamera
from trackctl.sim.bridgeloc import (
    BridgeLocScenario,
    WallTag,
    _compose,
    _infra,
    _Renderer,
    render_view,
    robot_camera_model,
    tag_corners,
)


def _view(tag: WallTag, eye, target, seed: int = 0):  # noqa: ANN001, ANN202
    model = _infra("c", eye, target)
    ren = _Renderer(model, np.random.default_rng(seed), BridgeLocScenario())
    bg = np.full((480, 640), 110, np.uint8)
    ideal = render_view(model, model.world_from_camera, [tag], bg, ren.texture)
    img = cv2.imdecode(np.frombuffer(ren.finish(ideal), np.uint8), cv2.IMREAD_GRAYSCALE)
    return model, img


@pytest.mark.parametrize("placement", list(Placement))
@pytest.mark.parametrize("code", [(1, 0, 0, 0), (0, 1, 1, 0), (1, 1, 1, 0), (0, 0, 1, 1)])
def test_rendered_tag_decodes_with_orientation(code, placement) -> None:  # noqa: ANN001
    tag = WallTag("t", code, placement, Mount.ABOVE, (3.0, 0.4, 1.0), (-1.0, 0.0), 0.3)
    model, img = _view(tag, (0.0, 0.0, 1.2), (3.0, 0.2, 1.0))
    (det,) = detect_tags(img)
    assert det.code == code and det.placement is placement
    truth, _ = PinholeCamera(model).project(tag_corners(tag))
    assert np.abs(det.corners - truth).max() < 1.0  # sub-pixel corners, printed order


def test_oblique_view_still_reads_upright() -> None:
    tag = WallTag(
        "t", (1, 0, 0, 0), Placement.SQUARE, Mount.ABOVE, (3.0, 0.0, 1.0), (-1.0, 0.0), 0.3
    )
    # 55 degrees off the tag's normal
    a = math.radians(55)
    eye = (3.0 - 2.0 * math.cos(a), 2.0 * math.sin(a), 1.0)
    _, img = _view(tag, eye, (3.0, 0.0, 1.0))
    (det,) = detect_tags(img)
    assert det.code == (1, 0, 0, 0) and det.placement is Placement.SQUARE


def test_half_out_of_view_gives_nothing() -> None:
    tag = WallTag(
        "t", (0, 1, 1, 0), Placement.SQUARE, Mount.ABOVE, (2.0, 0.0, 1.0), (-1.0, 0.0), 0.3
    )
    # aim so that the tag is cut by the left image edge
    f = 640 / (2 * math.tan(math.radians(25)))
    shift = 2.0 * 320 / f  # metres at the tag's depth from the centre to the image edge
    _, img = _view(tag, (0.0, shift, 1.0), (2.0, shift, 1.0))
    assert detect_tags(img) == []


def test_uniform_squares_are_not_tags() -> None:
    img = np.full((200, 200), 200, np.uint8)
    cv2.rectangle(img, (50, 50), (120, 120), 20, -1)
    assert detect_tags(img) == []


def test_order_corners_square_and_diamond() -> None:
    sq = np.array([[10, 10], [50, 12], [48, 50], [12, 48]], float)
    ordered, placement = order_corners(sq[[2, 0, 3, 1]])
    assert placement is Placement.SQUARE and np.allclose(ordered[0], [10, 10])
    dia = np.array([[30, 0], [60, 30], [30, 60], [0, 30]], float)
    ordered, placement = order_corners(dia[[1, 3, 0, 2]])
    assert placement is Placement.DIAMOND and np.allclose(ordered[0], [30, 0])


@settings(max_examples=50, deadline=None)
@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(-math.pi, math.pi), st.integers(2, 8))
def test_bridge_lstsq_recovers_pose(x: float, y: float, yaw: float, m: int) -> None:
    rng = np.random.default_rng(m)
    robot_pts = rng.uniform(-3, 3, (m, 2))
    rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    world = robot_pts @ rot.T + [x, y]
    ex, ey, eyaw = bridge_lstsq(world, robot_pts)
    assert ex == pytest.approx(x, abs=1e-6) and ey == pytest.approx(y, abs=1e-6)
    assert math.cos(eyaw - yaw) == pytest.approx(1.0, abs=1e-9)


def test_bridge_lstsq_needs_two_points() -> None:
    with pytest.raises(ValueError, match="at least 2 points"):
        bridge_lstsq(np.zeros((1, 2)), np.zeros((1, 2)))


def test_bridge_pnp_recovers_base_pose() -> None:
    rcam = robot_camera_model(0.5)
    geo = CameraGeometry.from_model(rcam)
    pose = (2.0, 1.0, 0.3)
    from dataclasses import replace

    world_cam = replace(rcam, world_from_camera=_compose(rcam.world_from_camera, *pose))
    tag = WallTag(
        "t", (0, 1, 1, 0), Placement.SQUARE, Mount.ABOVE, (5.0, 2.0, 0.9), (-1.0, 0.0), 0.3
    )
    corners = tag_corners(tag)
    px, _ = PinholeCamera(world_cam).project(corners)
    x, y, yaw = bridge_pnp(corners, px, geo)
    assert (x, y, yaw) == pytest.approx(pose, abs=1e-3)


def test_ekf_range_bearing_pulls_towards_truth() -> None:
    ekf = RobotEkf()
    ekf.init(0.5, 0.3, 0.1, 0.5, 0.2)
    truth = np.array([0.0, 0.0, 0.0])
    tags = [np.array([3.0, 1.0]), np.array([3.0, -1.0]), np.array([-2.0, 2.0])]
    for _ in range(10):
        for t in tags:
            d = t - truth[:2]
            ekf.update_range_bearing(float(np.hypot(*d)), math.atan2(d[1], d[0]), t)
    x, y, yaw = ekf.pose
    assert math.hypot(x, y) < 0.05 and abs(yaw) < 0.02
    s0 = ekf.sigma_m
    for _ in range(50):
        ekf.predict(0.05, 0.0)
    assert ekf.sigma_m > s0  # odometry alone loses certainty
    assert ekf.pose[0] == pytest.approx(x + 2.5, abs=0.05)
