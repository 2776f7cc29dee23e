"""Person detection on rendered frames: full search, motion-predicted regions, geometry checks."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from trackctl.geometry.camera import PinholeCamera
from trackctl.sim.render import PersonLook, draw_shadow, floor_image, render_frame
from trackctl.sim.vm import _cameras
from trackctl.vmtrack.detect import (
    BackgroundModel,
    DetectorConfig,
    detect_people,
    person_height_px,
    predict_region,
    refine_feet,
)


@pytest.fixture(scope="module")
def scene() -> tuple[PinholeCamera, np.ndarray, BackgroundModel]:
    (model,) = _cameras((6.0, 5.0), (1, 1), 4.0, 1.5, 1.5)
    cam = PinholeCamera(model)
    rng = np.random.default_rng(0)
    floor = floor_image(cam, rng)
    empty = [render_frame(cam, floor, [], rng) for _ in range(5)]
    return cam, floor, BackgroundModel(empty)


def _frame(cam: PinholeCamera, floor: np.ndarray, people: list[np.ndarray]) -> np.ndarray:
    rng = np.random.default_rng(1)
    looks = [PersonLook.random(rng) for _ in people]
    img = render_frame(cam, floor, list(zip(people, looks, strict=True)), rng)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 60])
    assert ok
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)


def _ground(cam: PinholeCamera, boxes: np.ndarray) -> np.ndarray:
    feet = np.column_stack([boxes[:, 0] + boxes[:, 2] / 2, boxes[:, 1] + boxes[:, 3]])
    return cam.ground_point(feet)[:, :2]


PEOPLE = [np.array([1.5, 2.0]), np.array([3.0, 3.5]), np.array([4.5, 1.5])]


def test_full_search_finds_every_person_on_the_ground(scene) -> None:
    cam, floor, bg = scene
    gray = _frame(cam, floor, PEOPLE)
    cfg = DetectorConfig()
    boxes, scores = detect_people(
        gray, bg, cfg, None, lambda f: person_height_px(cam, f, cfg.person_height_m)
    )
    ground = _ground(cam, boxes)
    assert len(boxes) == len(PEOPLE)
    for p in PEOPLE:
        assert np.min(np.linalg.norm(ground - p, axis=1)) < 0.3
    assert np.all(scores >= cfg.threshold)


def test_predicted_regions_find_the_same_people_and_nothing_else(scene) -> None:
    cam, floor, bg = scene
    gray = _frame(cam, floor, PEOPLE)
    cfg = DetectorConfig()
    # the prediction of the first two people is 0.3 m off; the third is not predicted
    regions = [predict_region(cam, p + 0.3, 0.6) for p in PEOPLE[:2]]
    assert all(r is not None for r in regions)
    boxes, _ = detect_people(
        gray,
        bg,
        cfg,
        regions,
        lambda f: person_height_px(cam, f, cfg.person_height_m),  # type: ignore[arg-type]
    )
    ground = _ground(cam, boxes)
    assert len(boxes) == 2
    for p in PEOPLE[:2]:
        assert np.min(np.linalg.norm(ground - p, axis=1)) < 0.3


def test_empty_scene_has_no_detection(scene) -> None:
    cam, floor, bg = scene
    boxes, _ = detect_people(_frame(cam, floor, []), bg, DetectorConfig())
    assert len(boxes) == 0


@settings(max_examples=examples(40), deadline=None)
@given(x=st.floats(0.5, 5.5), y=st.floats(0.5, 4.5), radius=st.floats(0.1, 1.0))
def test_predicted_region_contains_the_person_image(
    scene, x: float, y: float, radius: float
) -> None:
    cam = scene[0]
    xy = np.array([x, y])
    reg = predict_region(cam, xy, radius)
    px, front = cam.project(np.array([[x, y, 0.0], [x, y, 1.7]]))
    inside = (px[:, 0] >= 0) & (px[:, 0] < 640) & (px[:, 1] >= 0) & (px[:, 1] < 480)
    if reg is None:
        assert not inside.all()
        return
    for u, v in px[inside]:
        assert reg.x0 <= u <= reg.x1 and reg.y0 <= v <= reg.y1
    assert reg.height_px == pytest.approx(float(np.linalg.norm(px[0] - px[1])), rel=1e-6)


def _detect(cam: PinholeCamera, bg: BackgroundModel, image: np.ndarray) -> np.ndarray:
    cfg = DetectorConfig()
    bg.set_frame(image)
    boxes, _ = detect_people(
        image, bg, cfg, None, lambda f: person_height_px(cam, f, cfg.person_height_m)
    )
    return _ground(cam, boxes)


def _fresh(scene) -> BackgroundModel:
    return BackgroundModel([scene[2].image])


def test_a_darker_or_brighter_frame_finds_the_same_people(scene) -> None:
    cam, floor, _ = scene
    frame = _frame(cam, floor, PEOPLE)
    for gain in (0.75, 1.2):
        bg = _fresh(scene)
        dimmed = np.clip(frame.astype(np.float32) * gain, 0, 255).astype(np.uint8)
        ground = _detect(cam, bg, dimmed)
        assert bg.gain == pytest.approx(gain, abs=0.05)
        assert len(ground) == len(PEOPLE)
        for p in PEOPLE:
            assert np.min(np.linalg.norm(ground - p, axis=1)) < 0.3


def test_cast_shadows_are_not_people_and_do_not_move_the_feet(scene) -> None:
    cam, floor, _ = scene
    rng = np.random.default_rng(1)
    looks = [PersonLook.random(rng) for _ in PEOPLE]
    img = render_frame(cam, floor, list(zip(PEOPLE, looks, strict=True)), rng, shadows=True)
    ground = _detect(cam, _fresh(scene), img)
    assert len(ground) == len(PEOPLE)
    for p in PEOPLE:
        assert np.min(np.linalg.norm(ground - p, axis=1)) < 0.3
    # a shadow alone (its person outside the view) is no detection
    shadow_only = floor.copy()
    draw_shadow(shadow_only, cam, np.array([3.0, 2.5]))
    assert len(_detect(cam, _fresh(scene), shadow_only)) == 0


def test_floor_revealed_where_the_background_holds_a_person_is_a_ghost(scene) -> None:
    cam, floor, _ = scene
    with_person = _frame(cam, floor, [PEOPLE[0]])
    bg = BackgroundModel([with_person])  # someone stood there while the background was made
    ground = _detect(cam, bg, _frame(cam, floor, [PEOPLE[1]]))
    assert len(ground) == 1  # the real person, not the ghost of the one who left
    assert np.linalg.norm(ground[0] - PEOPLE[1]) < 0.3


def test_background_adapts_except_where_people_are_kept_out(scene) -> None:
    cam, floor, _ = scene
    frame = _frame(cam, floor, PEOPLE[:2])
    bg = _fresh(scene)
    keep = [predict_region(cam, PEOPLE[0], 0.5)]
    for k in range(60):  # 60 s of a scene where both people stand still
        bg.set_frame(frame)
        bg.update(frame, k * 1_000_000_000, keep, tau_s=10.0)  # type: ignore[list-item]
    ground = _detect(cam, bg, frame)
    # the protected person is still found; the other has become background
    assert len(ground) == 1
    assert np.linalg.norm(ground[0] - PEOPLE[0]) < 0.3


def test_feet_are_found_below_a_striding_persons_legs_apart() -> None:
    """A person walking across the view: a coat down to 60% of the body, then two legs in an
    inverted V, the feet 32 px apart (0.4 of the body: a stride), wider than the shoulders. The
    box's bottom goes to the feet, not to where the floor shows between the legs."""
    bg_img = np.full((200, 200, 3), 128, np.uint8)
    img = bg_img.copy()
    top, hem, feet, cx = 40, 88, 120, 100  # an 80 px person: coat 40-88, legs to 120
    img[top:hem, cx - 12 : cx + 12] = 30
    for r in range(hem, feet):  # each leg 4 px wide, 0 -> 12 px from the centre line
        off = round(12 * (r - hem) / (feet - hem))
        img[r, cx - off - 4 : cx - off] = 30
        img[r, cx + off : cx + off + 4] = 30
    bg = BackgroundModel([bg_img])
    bg.set_frame(img)
    box = np.array([[cx - 12.0, top, 24.0, hem + 12 - top]])  # the window fits the coat
    (refined,) = refine_feet(img, bg, box, DetectorConfig())
    assert abs(refined[1] + refined[3] - feet) <= 2
    # the central half of the box alone (the former rule) loses the legs as they part
    narrow = DetectorConfig(feet_span=0.0)
    (kept,) = refine_feet(img, bg, box, narrow)
    assert kept[1] + kept[3] < feet - 10
