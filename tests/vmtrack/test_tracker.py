"""Cross-camera merging: the heap agglomeration equals the definition (global nearest-first).
The association's injected cost: a plugged-in cost decides the matches."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from trackctl.logs.messages import TrackState
from trackctl.vmtrack.binder import IdentityBinder
from trackctl.vmtrack.config import Identity, Mode, VmTrackConfig
from trackctl.vmtrack.cost import CostTrack, VisualCost, VisualMotionCost
from trackctl.vmtrack.online import OnlineTracker
from trackctl.vmtrack.tracker import (
    GroundTrack,
    TrackerConfig,
    associate,
    merge_detections,
    merge_with_covariance,
)


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


@dataclass(frozen=True, slots=True)
class _ForbidAll:
    """A custom cost: no pair passes the gate."""

    gate_p: float = 0.5

    def probabilities(
        self,
        tracks: Sequence[CostTrack],
        dets: np.ndarray,
        covs: np.ndarray,
        predicted: tuple[np.ndarray, np.ndarray],
        dt: Sequence[float],
        v_m: Sequence[np.ndarray | None],
    ) -> np.ndarray:
        return np.zeros((len(tracks), len(dets)))


def _walk(cost: VisualCost | _ForbidAll, frames: int = 6) -> OnlineTracker:
    cfg = VmTrackConfig(mode=Mode.V_AF)
    online = OnlineTracker(cfg, IdentityBinder({}, cfg.binding, cfg.align), Mode.V_AF, cost)
    for k in range(frames):
        # a slow walker, 0.6 m a second: the births of a forbidding cost are no clutter spot
        online.process_frame(k * 1_000_000_000, [("cam0", np.array([0.6 * k, 0.0]))])
    return online


def test_a_plugged_in_cost_decides_the_association() -> None:
    # the visual cost follows one walker with one track
    assert _walk(VisualCost()).tracks_started == 1
    # a cost that forbids every match: every detection starts a new track (the last one's
    # tentative predecessor, which missed, retires first)
    online = _walk(_ForbidAll())
    assert online.tracks_started == 6 and online.clutter_suppressed == 0
    assert [trk.vid for trk in online.tracks] == ["v6"]


def test_the_phone_velocity_term_moves_the_match() -> None:
    tcfg = TrackerConfig()
    trk = GroundTrack.start("v1", np.array([0.0, 0.0]), 0, tcfg)
    dets = np.array([[0.4, 0.0], [-0.6, 0.0]])
    v_m = np.array([-1.2, 0.0])  # the phone walks towards the farther detection
    visual = VisualCost(tcfg.gate_p)
    fused = VisualMotionCost(tcfg.gate_p, tcfg.pdr_sigma_mps)
    pairs, _, left = associate([trk], dets, [0.5], [v_m], tcfg, visual)
    assert [(i, j) for i, j, _ in pairs] == [(0, 0)] and left == [1]
    pairs, _, left = associate([trk], dets, [0.5], [v_m], tcfg, fused)
    assert [(i, j) for i, j, _ in pairs] == [(0, 1)] and left == [0]
    # without a phone velocity the two costs are one
    covs = np.broadcast_to(np.eye(2) * tcfg.det_sigma_m**2, (2, 2, 2))
    pred = (np.zeros((1, 2)), np.array([0.3]))
    np.testing.assert_array_equal(
        visual.probabilities([trk], dets, covs, pred, [0.5], [None]),
        fused.probabilities([trk], dets, covs, pred, [0.5], [None]),
    )


def _rows_per_frame(identity: Identity) -> list[list[tuple[str, TrackState]]]:
    cfg = VmTrackConfig(mode=Mode.V_AF, identity=identity)
    online = OnlineTracker(cfg, IdentityBinder({}, cfg.binding, cfg.align), Mode.V_AF, VisualCost())
    for k in range(6):
        points = [("cam0", np.array([0.6 * k, 0.0]))]
        if k == 2:
            points.append(("cam0", np.array([9.0, 9.0])))  # one frame of clutter
        online.process_frame(k * 1_000_000_000, points)
    online.close()
    return [[(trk.vid, state) for trk, _, state, _ in fr.rows] for fr in online.frames]


def test_offline_a_track_is_published_from_its_first_detection() -> None:
    # offline the walker's first frames (before confirm_hits made it a track) are published
    # as tracked; the clutter that never became a track is not
    offline = _rows_per_frame(Identity.OFFLINE)
    assert offline == [[("v1", TrackState.TRACKED)]] * 6
    # the online output cannot know the future: the track appears once confirmed
    online = _rows_per_frame(Identity.ONLINE)
    assert online[:2] == [[], []] and all(r == [("v1", TrackState.TRACKED)] for r in online[2:])
