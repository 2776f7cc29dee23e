"""Pedestrian motion models: independent random waypoints and a crowd that avoids itself."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from trackctl.sim.walkers import random_waypoint, random_waypoint_crowd

SIZE = (20.0, 15.0)


def _close_share(paths: np.ndarray, within_m: float) -> float:
    """Share of person-samples with someone else within ``within_m``: paths (steps, n, 2)."""
    hits = total = 0
    for xy in paths[::10]:
        d, _ = cKDTree(xy).query(xy, k=2)
        hits += int(np.sum(d[:, 1] < within_m))
        total += len(xy)
    return hits / total


def test_a_crowd_keeps_its_distance_where_independent_walkers_do_not() -> None:
    names = [f"p{i}" for i in range(40)]
    crowd = random_waypoint_crowd(names, np.random.default_rng(1), SIZE, 120.0)
    rng = np.random.default_rng(1)
    alone = [random_waypoint(n, rng, SIZE, 120.0) for n in names]
    c = _close_share(np.stack([t.xy for t in crowd], axis=1), 0.4)
    a = _close_share(np.stack([t.xy for t in alone], axis=1), 0.4)
    assert c < 0.03 < a
    assert c < a / 3


def test_crowd_walkers_walk_stay_inside_and_are_deterministic() -> None:
    names = ["a", "b", "c"]
    one = random_waypoint_crowd(names, np.random.default_rng(7), SIZE, 60.0)
    two = random_waypoint_crowd(names, np.random.default_rng(7), SIZE, 60.0)
    for t1, t2 in zip(one, two, strict=True):
        assert np.array_equal(t1.xy, t2.xy)
        assert (
            np.all(t1.xy >= 0) and np.all(t1.xy[:, 0] <= SIZE[0]) and np.all(t1.xy[:, 1] <= SIZE[1])
        )
        speed = np.linalg.norm(t1.velocity(), axis=1)
        assert 0.3 < np.median(speed) < 1.6  # walking pace, pauses included
        assert np.max(speed) < 1.3 * 1.5 + 1e-6
