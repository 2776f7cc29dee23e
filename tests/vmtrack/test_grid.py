"""The re-tracking's site grid: what a log says of how people come and go (the visit model)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from trackctl.vmtrack.grid import SiteGrid, occupancy_steadiness
from trackctl.vmtrack.retrack import RetrackConfig, read_visits

HZ = 5.0
N = int(120 * HZ)  # 120 s: four steadiness windows
CFG = RetrackConfig()


def _frames() -> np.ndarray:
    return (np.arange(N) * 1e9 / HZ).astype(np.int64)


def _closed_room(seed: int = 1) -> list[np.ndarray]:
    """Eight people walking about a 12 x 10 m room all log, turning back at its walls, each
    detection missed 10 % of the time and in bursts of a second (occlusions) anywhere."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform([1, 1], [11, 9], (8, 2))
    vel = rng.normal(0, 1, (8, 2))
    vel *= 1.2 / np.linalg.norm(vel, axis=1, keepdims=True)
    hidden = np.zeros(8, int)
    out = []
    for _ in range(N):
        pos += vel / HZ
        for d, hi in ((0, 12.0), (1, 10.0)):
            bounce = (pos[:, d] < 0.3) | (pos[:, d] > hi - 0.3)
            vel[bounce, d] *= -1
        vel += rng.normal(0, 0.05, vel.shape)
        hidden = np.where(hidden > 0, hidden - 1, np.where(rng.random(8) < 0.01, 5, 0))
        seen = (hidden == 0) & (rng.random(8) > 0.1)
        out.append(pos[seen] + rng.normal(0, 0.1, (int(seen.sum()), 2)))
    return out


def _crossing(seed: int = 1) -> list[np.ndarray]:
    """People crossing a 12 x 10 m view from one side to the other at 1.3 m/s, one every 2 s."""
    rng = np.random.default_rng(seed)
    walkers: list[tuple[int, float, float]] = []  # start frame, y, direction
    for k in range(0, N, int(2 * HZ)):
        walkers.append((k, float(rng.uniform(1, 9)), float(rng.choice([-1.0, 1.0]))))
    out = []
    for k in range(N):
        pts = []
        for k0, y, d in walkers:
            x = 1.3 * (k - k0) / HZ
            if 0 <= x <= 12 and rng.random() > 0.1:
                pts.append((x if d > 0 else 12 - x, y))
        out.append(np.array(pts, float).reshape(-1, 2) + rng.normal(0, 0.1, (len(pts), 2)))
    return out


def _door_inside(seed: int = 1) -> list[np.ndarray]:
    """A hotel's entrance: people come out of a door in the middle of the view and walk off its
    edge, several a second for the first 40 s, then one every 10 s."""
    rng = np.random.default_rng(seed)
    starts = [*range(0, int(40 * HZ), 2), *range(int(40 * HZ), N, int(10 * HZ))]
    walkers = [(k, float(rng.uniform(0, 2 * np.pi))) for k in starts]
    out = []
    for k in range(N):
        pts = []
        for k0, heading in walkers:
            r = 1.3 * (k - k0) / HZ
            p = (6 + r * np.cos(heading), 5 + r * np.sin(heading))
            if r >= 0 and 0 <= p[0] <= 12 and 0 <= p[1] <= 10:
                pts.append(p)
        out.append(np.array(pts, float).reshape(-1, 2))
    return out


def test_steadiness_is_one_where_as_many_are_in_view_all_log() -> None:
    points = [np.zeros((4, 2))] * N
    assert occupancy_steadiness(_frames(), points, 30.0) == 1.0


def test_steadiness_falls_where_people_come_and_go() -> None:
    points = [np.zeros((4 if k < N // 2 else 1, 2)) for k in range(N)]
    got = occupancy_steadiness(_frames(), points, 30.0)
    assert got is not None and got < 0.3


def test_steadiness_is_not_read_from_a_log_shorter_than_four_windows() -> None:
    points = [np.zeros((4, 2))] * N
    assert occupancy_steadiness(_frames(), points, 31.0) is None
    assert occupancy_steadiness(_frames()[:1], points[:1], 30.0) is None
    assert occupancy_steadiness(_frames(), [np.zeros((0, 2))] * N, 30.0) is None


def test_walks_begin_and_end_at_the_edge_where_people_cross() -> None:
    crossing, closed = _crossing(), _closed_room()
    across = SiteGrid(crossing, CFG.cell_m).edge_turnover(crossing, CFG)
    room = SiteGrid(closed, CFG.cell_m).edge_turnover(closed, CFG)
    assert across is not None and room is not None
    assert across > CFG.turnover_min > room  # type: ignore[operator]


def test_a_closed_room_is_followed_in_view_throughout() -> None:
    points = _closed_room()
    cfg, reading = read_visits(SiteGrid(points, CFG.cell_m), _frames(), points, CFG)
    assert not reading.one_visit and cfg.away_cost is None
    assert reading.steadiness is not None and reading.steadiness >= CFG.steadiness_min


def test_a_scene_people_cross_has_one_visit_per_phone() -> None:
    points = _crossing()
    cfg, reading = read_visits(SiteGrid(points, CFG.cell_m), _frames(), points, CFG)
    assert reading.one_visit and cfg == CFG


def test_a_door_inside_the_view_is_told_by_the_occupancy() -> None:
    """Walks begin inside the view, and nobody stays: one visit, even where the edge turnover
    alone would call the scene closed (``biwi_hotel`` reads 4.3)."""
    points = _door_inside()
    blind = dataclasses.replace(CFG, turnover_min=math.inf)
    cfg, reading = read_visits(SiteGrid(points, CFG.cell_m), _frames(), points, blind)
    assert reading.steadiness is not None and reading.steadiness < CFG.steadiness_min
    assert reading.one_visit and cfg == blind


def test_one_visit_asked_for_is_not_read_from_the_log() -> None:
    points = _closed_room()
    fixed = RetrackConfig(turnover_min=None)
    cfg, reading = read_visits(SiteGrid(points, fixed.cell_m), _frames(), points, fixed)
    assert cfg == fixed and reading.one_visit and reading.edge_turnover is None
    free = RetrackConfig(away_cost=None)
    cfg, reading = read_visits(SiteGrid(points, free.cell_m), _frames(), points, free)
    assert cfg == free and not reading.one_visit
