"""The robot: LEDs in a rendered node frame -> pose fix; dead reckoning with late fixes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackctl.geometry.camera import PinholeCamera
from trackctl.sim.smirror import SmirrorScenario, node_models
from trackctl.sim.smirror_render import NodeRenderer, RobotShape, line_of_sight, three_rooms
from trackctl.smirror.robot import (
    FilterConfig,
    LedConfig,
    LedFix,
    PoseFilter,
    detect_leds,
    fix_from_leds,
)


@pytest.fixture(scope="module")
def node1() -> tuple[PinholeCamera, NodeRenderer]:
    model = node_models(SmirrorScenario())[1]
    cam = PinholeCamera(model)
    return cam, NodeRenderer(cam, three_rooms(), np.random.default_rng(0), 2.0)


@pytest.mark.parametrize(
    ("pose", "tol_m"),
    [((12.0, 5.5, 0.3), 0.05), ((14.0, 3.0, -2.0), 0.06), ((16.0, 1.5, 2.5), 0.12)],
)
def test_fix_from_rendered_leds(node1, pose, tol_m) -> None:  # type: ignore[no-untyped-def]
    cam, ren = node1
    img = ren.render([], [np.array(pose)], RobotShape(), np.random.default_rng(1))
    front, back = detect_leds([(0, 0, img)], LedConfig())
    assert front is not None and back is not None
    fix = fix_from_leds(front, back, cam, LedConfig(), 0)
    assert fix is not None
    assert math.hypot(fix.x_m - pose[0], fix.y_m - pose[1]) < tol_m
    assert abs((fix.yaw_rad - pose[2] + math.pi) % (2 * math.pi) - math.pi) < 0.35
    assert fix.range_m == pytest.approx(math.dist(pose[:2], cam.position[:2]), abs=0.2)


def test_occluded_robot_gives_no_fix(node1) -> None:  # type: ignore[no-untyped-def]
    cam, ren = node1
    robot = np.array([14.0, 3.0, 0.0])
    towards = (cam.position[:2] - robot[:2]) / np.linalg.norm(cam.position[:2] - robot[:2])
    person = robot[:2] + 0.6 * towards
    img = ren.render([(person, (90, 90, 100))], [robot], RobotShape(), np.random.default_rng(2))
    front, back = detect_leds([(0, 0, img)], LedConfig())
    assert front is None and back is None


def test_walls_block_the_view() -> None:
    walls = three_rooms().walls
    assert line_of_sight(np.array([1.0, 1.0]), np.array([8.0, 7.0]), walls)
    assert not line_of_sight(np.array([1.0, 1.0]), np.array([12.0, 1.0]), walls)  # wall at x = 9
    assert line_of_sight(np.array([5.0, 4.0]), np.array([12.0, 4.0]), walls)  # through the door


def test_late_fix_rewinds_and_replays_odometry() -> None:
    f = PoseFilter(0.0, 0.0, 0.0, 0, FilterConfig())
    for k in range(1, 26):  # 1 m straight ahead in 1 s, but the robot truly drifted to y = 0.1
        f.step(k * 40_000_000, 0.04, 0.0)
    fix = LedFix(t_ns=12 * 40_000_000, x_m=0.48, y_m=0.1, yaw_rad=0.0, range_m=5.0, node="n")
    assert f.apply_fix(fix, 0.01, 0.05)
    x, y, yaw = f.pose
    # corrected at the image's time, then the 13 later steps (0.52 m) replayed on top
    assert x == pytest.approx(1.0, abs=0.01)
    assert y == pytest.approx(0.1, abs=0.01)
    assert f.t_ns == 25 * 40_000_000


def test_outlier_fix_is_gated_then_accepted_when_it_persists() -> None:
    f = PoseFilter(0.0, 0.0, 0.0, 0, FilterConfig(max_rejects=2))
    f.step(40_000_000, 0.02, 0.0)
    far = LedFix(40_000_000, 5.0, 5.0, 0.0, 5.0, "n")
    assert not f.apply_fix(far, 0.02, 0.05)
    assert not f.apply_fix(far, 0.02, 0.05)
    assert f.apply_fix(far, 0.02, 0.05)
    assert f.pose[0] == pytest.approx(5.0, abs=0.1)


def test_fix_sigma_grows_with_range(node1) -> None:  # type: ignore[no-untyped-def]
    cam, _ = node1
    f = PoseFilter(0.0, 0.0, 0.0, 0, FilterConfig())
    near = f.fix_sigma(LedFix(0, 0, 0, 0, 3.0, "n"), cam, 0.32)
    far = f.fix_sigma(LedFix(0, 0, 0, 0, 10.0, "n"), cam, 0.32)
    assert far[0] > 2 * near[0]


def test_filter_learns_the_heading_bias_of_mismatched_wheels() -> None:
    """Opposite wheel-scale errors turn the robot by b rad per metre the encoders never see; the
    fixes teach the filter b, and dead reckoning without fixes then follows the true arc."""
    b_true, step = 0.1, 0.04
    f = PoseFilter(0.0, 0.0, 0.0, 0, FilterConfig())
    x = y = yaw = 0.0
    for k in range(1, 501):  # 20 m, a fix every 0.4 m
        mid = yaw + b_true * step / 2
        x, y, yaw = x + step * math.cos(mid), y + step * math.sin(mid), yaw + b_true * step
        t = k * 40_000_000
        f.step(t, step, 0.0)  # the encoders say: straight
        if k % 10 == 0:
            f.apply_fix(LedFix(t, x, y, yaw, 5.0, "n"), 0.03, 0.05)
    assert f.heading_bias == pytest.approx(b_true, abs=0.02)
    for k in range(501, 551):  # 2 m without fixes
        mid = yaw + b_true * step / 2
        x, y, yaw = x + step * math.cos(mid), y + step * math.sin(mid), yaw + b_true * step
        f.step(k * 40_000_000, step, 0.0)
    assert math.hypot(f.pose[0] - x, f.pose[1] - y) < 0.1
