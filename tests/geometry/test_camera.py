"""Pinhole camera: projection and back-projection to the ground are inverses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from trackctl.geometry import PinholeCamera, look_at
from trackctl.logs.messages import CameraModel


def _camera(eye: tuple[float, float, float], dist: tuple[float, ...] = (0.0,) * 5) -> PinholeCamera:
    pose = look_at(np.array(eye), np.array([5.0, 4.0, 0.0]))
    return PinholeCamera(
        CameraModel(0, "c", 640, 480, 500.0, 500.0, 320.0, 240.0, "plumb_bob", dist, pose)
    )


@settings(max_examples=examples(60), deadline=None)
@given(
    x=st.floats(2.0, 9.0),
    y=st.floats(1.0, 8.0),
    eye=st.tuples(st.floats(-2, 0), st.floats(-2, 0), st.floats(2.0, 5.0)),
    k1=st.floats(-0.05, 0.05),
)
def test_ground_point_inverts_projection(
    x: float, y: float, eye: tuple[float, float, float], k1: float
) -> None:
    cam = _camera(eye, (k1, 0.0, 0.0, 0.0, 0.0))
    world = np.array([[x, y, 0.0]])
    px, front = cam.project(world)
    assert front[0]
    back = cam.ground_point(px)
    assert back[0] == pytest.approx(world[0], abs=1e-4)


def test_look_at_points_the_optical_axis_at_the_target() -> None:
    cam = _camera((0.0, 0.0, 3.0))
    px, front = cam.project(np.array([[5.0, 4.0, 0.0]]))
    assert front[0]
    assert px[0] == pytest.approx([320.0, 240.0], abs=1e-6)


def test_points_behind_the_camera_are_not_visible() -> None:
    cam = _camera((0.0, 0.0, 3.0))
    assert not cam.visible(np.array([[-5.0, -4.0, 0.0]]))[0]


def test_camera_without_pose_is_refused() -> None:
    with pytest.raises(ValueError, match="has no world pose"):
        PinholeCamera(CameraModel(0, "c", 640, 480, 500.0, 500.0, 320.0, 240.0))
