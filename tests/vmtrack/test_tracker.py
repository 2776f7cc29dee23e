"""Cross-camera merging: the heap agglomeration equals the definition (global nearest-first)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from trackctl.vmtrack.tracker import merge_detections, merge_with_covariance


def _reference(points: list[tuple[str, np.ndarray]], covs: np.ndarray, merge_m: float):
    """The definition, by brute force: repeatedly merge the two clusters with the nearest fused
    centroids that share no camera, while they are closer than ``merge_m``."""
    clusters = [
        ({cam}, np.linalg.inv(c), np.linalg.inv(c) @ xy, xy.copy())
        for (cam, xy), c in zip(points, covs, strict=True)
    ]
    while True:
        best = None
        for i in range(len(clusters)):
            for j in range(i + 1, len(clusters)):
                if clusters[i][0] & clusters[j][0]:
                    continue
                d = float(np.hypot(*(clusters[i][3] - clusters[j][3])))
                if d < merge_m and (best is None or d < best[0]):
                    best = (d, i, j)
        if best is None:
            break
        _, i, j = best
        cams, info, s, _ = clusters[i]
        info2, s2 = info + clusters[j][1], s + clusters[j][2]
        clusters[i] = (cams | clusters[j][0], info2, s2, np.linalg.solve(info2, s2))
        del clusters[j]
    return np.array([c[3] for c in clusters]).reshape(-1, 2)


def _sorted(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort((a[:, 1], a[:, 0]))]


people = st.lists(
    st.tuples(
        st.floats(0, 12, allow_nan=False),
        st.floats(0, 8, allow_nan=False),
        st.sets(st.integers(0, 5), min_size=1, max_size=4),
    ),
    min_size=1,
    max_size=25,
)


@settings(max_examples=examples(150), deadline=None)
@given(people, st.integers(0, 2**31 - 1))
def test_merge_equals_the_global_nearest_first_definition(crowd, seed) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    points, covs = [], []
    for x, y, cams in crowd:
        for cam in sorted(cams):
            points.append((f"cam{cam}", np.array([x, y]) + rng.normal(0, 0.15, 2)))
            a = rng.uniform(0.01, 0.2)
            covs.append(np.array([[a, 0.3 * a], [0.3 * a, 1.5 * a]]))
    covs_arr = np.array(covs)
    got, got_covs = merge_with_covariance(points, covs_arr, 0.6)
    want = _reference(points, covs_arr, 0.6)
    assert got.shape == want.shape
    np.testing.assert_allclose(_sorted(got), _sorted(want), atol=1e-9)
    assert got_covs is not None and len(got_covs) == len(got)


def test_one_camera_never_merges_and_two_cameras_fuse() -> None:
    pts = [("a", np.array([0.0, 0.0])), ("a", np.array([0.1, 0.0]))]
    assert len(merge_detections(pts, 0.6)) == 2
    pts = [("a", np.array([0.0, 0.0])), ("b", np.array([0.2, 0.0]))]
    np.testing.assert_allclose(merge_detections(pts, 0.6), [[0.1, 0.0]])
