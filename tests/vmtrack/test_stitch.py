"""Offline clean-up of visual-only tracks: stitching, coasting tails, short identities."""

from __future__ import annotations

import numpy as np

from trackctl.logs.messages import TrackState
from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.stitch import StitchConfig, Tracklet, plan_publication, stitch
from trackctl.vmtrack.tracker import GroundTrack, TrackerConfig

S = 1_000_000_000


def _tl(key: int, t0: float, t1: float, p0, p1, v=(0.0, 0.0), hits: int = 10) -> Tracklet:
    v = np.array(v, float)
    return Tracklet(
        key, hits, int(t0 * S), int(t1 * S), np.array(p0, float), np.array(p1, float), v, v
    )


def test_a_walker_reappearing_where_they_walked_to_is_one_identity() -> None:
    a = _tl(1, 0, 5, (0, 0), (5, 0), (1, 0))
    b = _tl(2, 7, 12, (7.2, 0.1), (12, 0), (1, 0))
    far = _tl(3, 7, 12, (0, 9), (5, 9), (1, 0))
    heads = stitch([a, b, far], StitchConfig())
    assert heads == {1: 1, 2: 1, 3: 3}


def test_links_are_one_to_one_and_chosen_together() -> None:
    # two walkers crossing out of view: each end continues the start its motion points at
    a = _tl(1, 0, 4, (0, 0), (4, 0), (1, 0))
    b = _tl(2, 0, 4, (0, 2), (4, 2), (1, 0))
    c = _tl(3, 5, 8, (5, 0.2), (8, 0), (1, 0))
    d = _tl(4, 5, 8, (5, 2.1), (8, 2), (1, 0))
    heads = stitch([a, b, c, d], StitchConfig())
    assert heads[3] == 1 and heads[4] == 2
    # overlapping in time is never the same person; a gap beyond max_gap_s is not linked
    late = _tl(5, 20, 22, (8.5, 0), (10, 0))
    assert stitch([c, late], StitchConfig())[5] == 5
    assert stitch([a, _tl(6, 3, 9, (4, 0), (9, 0))], StitchConfig())[6] == 6


def test_a_person_who_stood_still_out_of_sight_is_linked() -> None:
    a = _tl(1, 0, 5, (0, 0), (3, 0), (1.2, 0))
    b = _tl(2, 8, 12, (3.3, 0.2), (3.3, 0.2))
    assert stitch([a, b], StitchConfig())[2] == 1


def test_publication_hides_tails_and_short_identities_and_fills_gaps() -> None:
    times = [int(k * 0.5 * S) for k in range(30)]
    a = GroundTrack.start("v1", np.zeros(2), 0, TrackerConfig(), key=1)
    a.hit_ns = times[:10]  # seen 0-4.5 s, then coasts to 6 s
    b = GroundTrack.start("v2", np.array([6.0, 0.0]), times[13], TrackerConfig(), key=2)
    b.hit_ns = times[13:25]
    ghost = GroundTrack.start("v3", np.array([50.0, 50.0]), times[2], TrackerConfig(), key=3)
    ghost.hit_ns = times[2:5]
    frames, positions = [], {}
    for k, t in enumerate(times):
        rows = []
        for trk, first, last, speed in ((a, 0, 12, 1.0), (b, 13, 27, 1.0), (ghost, 2, 4, 0.0)):
            if first <= k <= last:
                x = np.array([k * 0.5 * speed if trk is not ghost else 50.0, 0.0, speed, 0.0])
                positions[(trk.key, k)] = (x, np.eye(4) * 0.01)
                rows.append((trk, None, TrackState.TRACKED, k))
        frames.append(FrameOut(t, rows))
    plan = plan_publication(frames, positions, StitchConfig())
    # v1's coasting after its last detection (frames 10-12) is hidden
    assert {(a.key, times[k]) for k in (10, 11, 12)} <= plan.hidden
    assert (a.key, times[9]) not in plan.hidden
    # v2 continues v1 and takes its name; the gap is filled at frames 10-12
    assert plan.name[b.key] == "v1" and plan.links == 1
    assert sorted(plan.fills) == [times[10], times[11], times[12]]
    assert all(name == "v1" for t in plan.fills for name, _, _ in plan.fills[t])
    # b's tail after its last hit (frames 25-27) is hidden; the 3-hit ghost is dropped
    assert (b.key, times[26]) in plan.hidden
    assert plan.dropped == 1 and (ghost.key, times[3]) in plan.hidden
