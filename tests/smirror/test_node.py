"""The node: cast-mode decision, region packing, foreground-only encoding, beacons."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from trackctl.logs.messages import CameraModel
from trackctl.smirror.node import (
    MESSAGE_HEADER_BYTES,
    REGION_HEADER_BYTES,
    CastMode,
    MirrorNode,
    NodeConfig,
    beacon_bytes,
    decide_cast,
    pack_regions,
)

MODEL = CameraModel(0, "node0", 320, 240, 300.0, 300.0, 160.0, 120.0)


def test_broadcast_from_the_threshold_on() -> None:
    assert decide_cast(1, 15) is CastMode.UNICAST
    assert decide_cast(14, 15) is CastMode.UNICAST
    assert decide_cast(15, 15) is CastMode.BROADCAST
    assert decide_cast(20, 15) is CastMode.BROADCAST


@given(st.lists(st.tuples(st.integers(1, 200), st.integers(1, 200)), min_size=1, max_size=8))
def test_packed_regions_do_not_overlap_and_fit(sizes: list[tuple[int, int]]) -> None:
    pos, (mw, mh) = pack_regions(sizes, 320)
    canvas = np.zeros((mh, mw), np.int32)
    for (x, y), (w, h) in zip(pos, sizes, strict=True):
        assert x % 16 == 0 and y % 16 == 0
        canvas[y : y + h, x : x + w] += 1
        assert x + w <= mw and y + h <= mh
    assert canvas.max() == 1


def _scene(rng: np.random.Generator, square_x: int | None) -> np.ndarray:
    img = np.full((240, 320, 3), 150, np.uint8)
    img[::8] = 120  # some texture
    if square_x is not None:
        cv2.rectangle(img, (square_x, 100), (square_x + 30, 140), (40, 60, 200), -1)
    noise = rng.normal(0, 2, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


def test_moving_object_is_the_only_region_and_costs_far_less_than_the_frame() -> None:
    rng = np.random.default_rng(0)
    node = MirrorNode(MODEL, NodeConfig())
    for _ in range(30):
        node.sense(_scene(rng, None))
    frame = _scene(rng, 150)
    mask = node.sense(frame)
    payload, new = node.encode(1, frame, mask)
    assert new
    assert len(payload.regions) == 1
    fx, fy, _, _, w, h = payload.regions[0]
    assert 140 <= fx <= 150 and 90 <= fy <= 100 and 30 <= w <= 50 and 40 <= h <= 60
    assert payload.size_bytes == MESSAGE_HEADER_BYTES + REGION_HEADER_BYTES + len(payload.mosaic)
    assert payload.size_bytes * 3 < node.full_frame_bytes(frame)
    ((x0, y0, crop),) = payload.crops()
    assert (x0, y0) == (fx, fy) and crop.shape[:2] == (h, w)
    # the object itself survives encoding (the robot looks for things in it)
    assert np.abs(crop[20:30, 15:25].astype(int).mean(axis=(0, 1)) - (40, 60, 200)).max() < 25


def test_old_image_is_resent_when_nothing_moved() -> None:
    rng = np.random.default_rng(1)
    node = MirrorNode(MODEL, NodeConfig())
    for _ in range(30):
        node.sense(_scene(rng, None))
    frame = _scene(rng, 100)
    first, new = node.encode(1, frame, node.sense(frame))
    assert new
    still = _scene(rng, None)
    for _ in range(3):
        mask = node.sense(still)
    second, new = node.encode(2, still, mask)
    assert not new
    assert second is first


def test_beacon_size_is_the_json_configuration() -> None:
    body = {"node": "node0", "camera": MODEL.to_json()}
    assert beacon_bytes(MODEL) == len(json.dumps(body, separators=(",", ":")).encode())


@pytest.mark.parametrize("threshold", [0, -3])
def test_config_rejects_a_nonpositive_threshold(threshold: int) -> None:
    from trackctl.smirror import SmirrorConfig

    with pytest.raises(ValueError, match="broadcast_threshold must be >= 1"):
        SmirrorConfig(broadcast_threshold=threshold)
