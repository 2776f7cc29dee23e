"""Colour signatures of tracks and the re-identification they allow."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from trackctl.logs.messages import BBox, Detection, Detections, Vec3
from trackctl.vmtrack.appearance import AppearanceBook, descriptor, distance
from trackctl.vmtrack.stitch import StitchConfig, Tracklet, reidentify

S = 1_000_000_000


def _person(shirt: tuple[int, int, int], trousers: tuple[int, int, int]) -> np.ndarray:
    """A 60 x 20 BGR person box: head, shirt, trousers, on grey floor at the sides."""
    img = np.full((60, 20, 3), 128, np.uint8)
    img[0:9, 7:13] = (40, 60, 90)
    img[9:33, 3:17] = shirt
    img[33:57, 4:16] = trousers
    return img


def _noisy(img: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(img + rng.normal(0, 6, img.shape), 0, 255).astype(np.uint8)


BOX = np.array([0.0, 0.0, 20.0, 60.0])


def test_the_same_clothes_are_closer_than_other_clothes() -> None:
    red_blue = _person((30, 30, 200), (160, 60, 20))
    again = descriptor(_noisy(red_blue, 1), BOX)
    first = descriptor(_noisy(red_blue, 2), BOX)
    swapped = descriptor(_noisy(_person((160, 60, 20), (30, 30, 200)), 3), BOX)
    dark = descriptor(_noisy(_person((25, 25, 25), (30, 30, 30)), 4), BOX)
    assert first is not None and again is not None and swapped is not None and dark is not None
    assert distance(first, again) < 0.2
    # torso and legs are separate parts: the same colours the other way round differ
    assert distance(first, swapped) > 0.5
    assert distance(first, dark) > 0.5


def test_a_box_off_the_image_or_too_small_has_no_descriptor() -> None:
    img = _person((30, 30, 200), (160, 60, 20))
    assert descriptor(img, np.array([40.0, 0.0, 20.0, 60.0])) is None
    assert descriptor(img, np.array([0.0, 0.0, 3.0, 5.0])) is None


@given(
    st.lists(st.floats(0, 1), min_size=48, max_size=48),
    st.lists(st.floats(0, 1), min_size=48, max_size=48),
)
def test_distance_is_a_bounded_symmetric_dissimilarity(a: list[float], b: list[float]) -> None:
    def sig(v: list[float]) -> np.ndarray:
        x = np.array(v) + 1e-6
        return np.concatenate([x[:24] / x[:24].sum(), x[24:] / x[24:].sum()])

    sa, sb = sig(a), sig(b)
    d = distance(sa, sb)
    assert 0.0 <= d <= 1.0
    assert abs(d - distance(sb, sa)) < 1e-9
    assert distance(sa, sa) < 1e-6


def _det(x: float, y: float, box: tuple[float, float, float, float]) -> Detection:
    return Detection(BBox(*box), 0.9, "person", Vec3(x, y, 0.0))


def test_only_a_detection_clear_of_other_boxes_is_sampled() -> None:
    book = AppearanceBook()
    dets = (
        _det(0.0, 0.0, (10, 10, 20, 60)),
        _det(0.5, 0.0, (25, 10, 20, 60)),  # overlaps the first box
        _det(5.0, 0.0, (200, 10, 20, 60)),
    )
    book.add(7, "cam0", Detections(7, "cam0", dets))
    assert book.isolated_box(7, np.array([0.0, 0.05]), 0.3) is None
    hit = book.isolated_box(7, np.array([5.1, 0.0]), 0.3)
    assert hit is not None and hit[0] == "cam0" and hit[1][0] == 200
    assert book.isolated_box(7, np.array([9.0, 0.0]), 0.3) is None  # nobody there
    assert book.isolated_box(8, np.array([5.0, 0.0]), 0.3) is None  # no such frame


def _tl(key: int, t0: float, t1: float, p0, p1) -> Tracklet:
    z = np.zeros(2)
    return Tracklet(
        key, 20, int(t0 * S), int(t1 * S), np.array(p0, float), np.array(p1, float), z, z
    )


def _sig(k: int) -> np.ndarray:
    v = np.full(48, 0.01)
    v[k] = 1.0
    v[24 + k] = 1.0
    return np.concatenate([v[:24] / v[:24].sum(), v[24:] / v[24:].sum()])


def test_a_person_back_after_a_long_absence_is_re_identified_by_colour() -> None:
    # two people leave the view at 10 s; two come back at 25 s, where they left, each in the
    # other's order: the colours, not the order or the place, say who is who
    tls = [
        _tl(1, 0, 10, (0, 0), (5, 0)),
        _tl(2, 0, 10, (0, 1), (5, 1)),
        _tl(3, 25, 35, (5, 1), (0, 1)),
        _tl(4, 25, 35, (5, 0), (0, 0)),
    ]
    look = {1: _sig(0), 2: _sig(5), 3: _sig(0), 4: _sig(5)}
    heads = reidentify(tls, {t.key: t.key for t in tls}, look, StitchConfig())
    assert heads == {1: 1, 2: 2, 3: 1, 4: 2}
    # without colours nothing is joined across the gap
    assert reidentify(tls, {t.key: t.key for t in tls}, {}, StitchConfig()) == {
        t.key: t.key for t in tls
    }


def test_ambiguous_unreachable_or_too_late_returns_are_not_joined() -> None:
    cfg = StitchConfig()
    a = _tl(1, 0, 10, (0, 0), (5, 0))
    # two returns dressed alike: which one is the person is not clear, neither is joined
    twins = [a, _tl(2, 20, 30, (5, 0), (9, 0)), _tl(3, 20, 30, (5, 2), (9, 2))]
    look = {1: _sig(0), 2: _sig(0), 3: _sig(0)}
    assert reidentify(twins, {t.key: t.key for t in twins}, look, cfg) == {1: 1, 2: 2, 3: 3}
    # too far to have walked in the gap, or back after reid_max_gap_s
    far = [a, _tl(2, 12, 20, (40, 0), (45, 0))]
    assert reidentify(far, {1: 1, 2: 2}, {1: _sig(0), 2: _sig(0)}, cfg)[2] == 2
    late = [a, _tl(2, 10 + cfg.reid_max_gap_s + 1, 60, (5, 0), (6, 0))]
    assert reidentify(late, {1: 1, 2: 2}, {1: _sig(0), 2: _sig(0)}, cfg)[2] == 2
    # other clothes
    other = [a, _tl(2, 12, 20, (5, 0), (6, 0))]
    assert reidentify(other, {1: 1, 2: 2}, {1: _sig(0), 2: _sig(9)}, cfg)[2] == 2


def test_chains_already_stitched_are_joined_whole() -> None:
    tls = [
        _tl(1, 0, 5, (0, 0), (2, 0)),
        _tl(2, 6, 10, (2, 0), (5, 0)),
        _tl(3, 30, 35, (5, 0), (1, 0)),
    ]
    look = {1: _sig(3), 3: _sig(3)}  # track 2 had no clear view: the chain's colours are 1's
    heads = reidentify(tls, {1: 1, 2: 1, 3: 3}, look, StitchConfig())
    assert heads == {1: 1, 2: 1, 3: 1}
