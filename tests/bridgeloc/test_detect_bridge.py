"""Detection/decoding on rendered views, bridging (Eq. 4.9 and solvePnP), the EKF."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from trackctl.bridgeloc.bridge import (
    CameraGeometry,
    bridge_lstsq,
    bridge_pnp,
    project_corners,
    tag_corners_in_camera,
)
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


@settings(max_examples=examples(50), deadline=None)
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


def _seen_tag(pose: tuple[float, float, float], center=(5.0, 2.0, 0.9)):  # noqa: ANN001, ANN202
    """A tag on the wall x = 5 seen by the robot camera at ``pose``: (geometry, detection)."""
    from dataclasses import replace

    from trackctl.bridgeloc.detect import TagDetection

    rcam = robot_camera_model(0.5)
    geo = CameraGeometry.from_model(rcam)
    world_cam = replace(rcam, world_from_camera=_compose(rcam.world_from_camera, *pose))
    tag = WallTag("t", (0, 1, 1, 0), Placement.SQUARE, Mount.ABOVE, center, (-1.0, 0.0), 0.3)
    px, _ = PinholeCamera(world_cam).project(tag_corners(tag))
    det = TagDetection((0, 1, 1, 0), Placement.SQUARE, px, 100.0)
    # the map's corners in the order the pipeline's solvePnP gives them (base frame -> world)
    pb = tag_corners_in_camera(det, geo, 0.3) @ geo.R.T + geo.t
    c, s = math.cos(pose[2]), math.sin(pose[2])
    world = pb @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [pose[0], pose[1], 0]
    # and the pixels exactly those of these corners through the distorted lens
    return geo, world, replace(det, corners=project_corners(pose, world, geo))


@pytest.mark.parametrize(
    ("pose", "robust"),
    [((3.5, 1.5, 0.1), False), ((2.0, 1.0, 0.3), True)],
    ids=["1.5m", "3m"],
)
def test_bridge_pose_covariance_matches_pixel_noise_scatter(
    pose: tuple[float, float, float], robust: bool
) -> None:
    """The propagated covariance is what 1 px of corner noise actually does to the pose: its
    std at 1.5 m; at 3 m (a 17 px tag) the scatter has heavy tails (a fifth of the draws fall
    outside the 99.7 % ellipsoid: the EKF gates them), so its core (1.4826 MAD) is compared."""
    from dataclasses import replace

    from trackctl.bridgeloc.bridge import BridgeObservation, bridge_branches, bridge_pose

    geo, corners, det = _seen_tag(pose)
    est, cov, _ = bridge_branches([BridgeObservation(det, corners)], geo, 0.3, 1.0)[0]
    assert est == pytest.approx(pose, abs=1e-3)
    rng = np.random.default_rng(0)
    samples = []
    for _ in range(400):
        noisy = replace(det, corners=det.corners + rng.normal(0, 1.0, det.corners.shape))
        p = bridge_pose([BridgeObservation(noisy, corners)], geo, 0.3, 1.0)
        assert p is not None
        samples.append(p[0])
    dev = np.array(samples) - np.array(pose)
    if robust:
        # heavy tails (the linearisation fails for some draws): the core is compared
        core = 1.4826 * np.median(np.abs(dev - np.median(dev, axis=0)), axis=0)
        for i in range(3):
            assert core[i] == pytest.approx(math.sqrt(cov[i, i]), rel=0.3)
    else:
        spread = dev.std(axis=0)
        for i in range(3):
            assert spread[i] == pytest.approx(math.sqrt(cov[i, i]), rel=0.25)


def test_ekf_learns_heading_bias_and_gates_outliers() -> None:
    """Wheels with opposite scale errors curve the dead-reckoned path; bridged poses every
    metre teach the filter the bias, and an outlier is rejected."""
    from trackctl.geometry.odometry import integrate_step

    ekf = RobotEkf()
    cov = np.diag([0.05**2, 0.05**2, 0.03**2])
    ekf.init((0.0, 0.0, 0.0), cov)
    true = (0.0, 0.0, 0.0)
    bias = 0.08  # rad/m, what +-1.2 % scale errors on a 0.30 m base give
    for k in range(400):  # 20 m straight, reported as straight by the wheels
        true = integrate_step(*true, 0.05, bias * 0.05)
        ekf.predict(0.05, 0.0)
        if k % 20 == 19:
            assert ekf.update_pose(true, cov)
    assert float(ekf.kf.x[3, 0]) == pytest.approx(bias, abs=0.02)
    before = ekf.pose
    assert not ekf.update_pose((before[0] + 3.0, before[1], before[2]), cov)  # a wrong tag
    assert ekf.pose == pytest.approx(before)
    assert len(ekf.nis_values) == 20 + 1  # every tested update leaves its NIS


@pytest.mark.parametrize("view_deg", [68.0, 70.0])
@pytest.mark.parametrize("code", [(1, 0, 0, 0), (0, 1, 1, 1), (1, 0, 1, 1)])
def test_diamond_seen_obliquely_is_read_as_a_diamond(view_deg: float, code) -> None:  # noqa: ANN001
    """Foreshortening makes a diamond's edges look steep at 65-70° view angles, and the image
    rule (an edge within 20° of vertical) reads it as a square tag: a different symbol, often
    a different code. Its 3-D pose against the world's up direction reads it right."""
    from dataclasses import replace

    from trackctl.bridgeloc.detect import DetectorConfig, read_oriented
    from trackctl.logs.messages import Quat, Transform, Vec3
    from trackctl.sim.bridgeloc import BridgeLocScenario, _infra, _Renderer, render_view

    level = Transform(Vec3(0.0, 0.0, 1.0), Quat(0.5, -0.5, 0.5, -0.5))  # looking along +x
    model = replace(_infra("c", (0.0, 0.0, 1.0), (5.0, 0.0, 1.0)), world_from_camera=level)
    a = math.radians(view_deg)
    tag = WallTag(
        "t", code, Placement.DIAMOND, Mount.ABOVE, (2.0, 0.0, 1.0), (-math.cos(a), math.sin(a)), 0.3
    )
    ren = _Renderer(model, np.random.default_rng(0), BridgeLocScenario(preset="paper"))
    ideal = render_view(model, level, [tag], np.full((480, 640), 110, np.uint8), ren.texture)
    img = cv2.imdecode(np.frombuffer(ren.finish(ideal), np.uint8), cv2.IMREAD_GRAYSCALE)
    (det,) = detect_tags(img, DetectorConfig())
    assert det.placement is Placement.SQUARE  # the image rule is fooled
    geo = CameraGeometry.from_model(model)
    corners = tag_corners_in_camera(det, geo, 0.3)
    assert corners is not None
    got = read_oriented(img, det, corners, geo.R.T @ np.array([0.0, 0.0, 1.0]), DetectorConfig())
    assert got is not None and got.placement is Placement.DIAMOND and got.code == code


def _corner_updates(r_of: object, start: tuple[float, float, float]) -> float:
    """Position error after 10 corner updates of one tag 3 m away, from ``start``;
    ``r_of(pose, world, geo)`` gives the corners' covariance."""
    from functools import partial

    from trackctl.bridgeloc.bridge import corner_jacobian

    truth = (2.0, 1.0, 0.3)
    geo, world, det = _seen_tag(truth)
    z = det.corners.reshape(-1)
    ekf = RobotEkf()
    ekf.init(start, np.diag([0.4**2, 0.4**2, 0.15**2]))
    for _ in range(10):
        jac = corner_jacobian(ekf.pose, world, geo)
        hx = partial(lambda p, w: project_corners(p, w, geo).reshape(-1), w=world)
        assert ekf.update_measurement(z, hx, jac, r_of(ekf.pose, world, geo))  # type: ignore[operator]
    return math.dist(ekf.pose[:2], truth[:2])


def test_a_tags_shape_corrects_a_position_its_bearing_cannot() -> None:
    """A state 0.4 m to the side, turned so that the tag sits at the same bearing: the corners'
    shape (range, view angle) must pull it back. The map's error of the tag's pose enters
    through how it moves the corners (together for its position, turning the shape for its
    yaw); as independent noise per corner (what Full mode did) it leaves only the bearing, and
    the state stays off."""
    from trackctl.bridgeloc.bridge import map_jacobian
    from trackctl.bridgeloc.ekf import EkfConfig, corner_covariance

    truth = np.array([2.0, 1.0, 0.3])
    tag = np.array([5.0, 2.0])
    to_tag = tag - truth[:2]
    side = np.array([-to_tag[1], to_tag[0]]) / np.linalg.norm(to_tag)
    xy = truth[:2] + 0.4 * side
    turn = math.atan2(*(tag - xy)[::-1]) - math.atan2(*to_tag[::-1])
    start = (float(xy[0]), float(xy[1]), float(truth[2] + turn))
    e = EkfConfig()
    map_m, f = 0.09, 185.0  # a map good to 9 cm; the robot camera's focal length, px

    def mapped(pose, world, geo):  # noqa: ANN001, ANN202
        cov = np.diag([map_m**2] * 3 + [e.map_yaw_rad**2])
        return corner_covariance(4, 1.0, f * 0.01, map_jacobian(pose, world, geo), cov)

    def apart(pose, world, geo):  # noqa: ANN001, ANN202
        rng_m = math.dist(pose[:2], tag)
        return corner_covariance(4, math.hypot(1.0, f * map_m / rng_m), f * 0.01)

    err_mapped = _corner_updates(mapped, start)
    err_apart = _corner_updates(apart, start)
    print(f"error after 10 updates: map via its Jacobian {err_mapped:.3f}, apart {err_apart:.3f} m")
    assert err_mapped < 0.2
    assert err_apart > 1.5 * err_mapped


def test_corner_covariance_keeps_the_shape_of_a_common_shift() -> None:
    from trackctl.bridgeloc.ekf import corner_covariance

    r = corner_covariance(4, 1.0, 3.0)
    diff = np.zeros(8)
    diff[0], diff[2] = 1.0, -1.0  # u0 - u1: one side of the tag's width
    assert diff @ r @ diff == pytest.approx(2.0)  # the corners' own noise only
    assert np.full(4, 0.25) @ r[0::2, 0::2] @ np.full(4, 0.25) == pytest.approx(0.25 + 9.0)
    jac = np.zeros((8, 1))
    jac[0::2, 0] = [1.0, -1.0, -1.0, 1.0]  # a change of the tag's width
    widened = corner_covariance(4, 1.0, 3.0, jac, np.array([[4.0]]))
    assert diff @ widened @ diff == pytest.approx(2.0 + 4.0 * 4)
