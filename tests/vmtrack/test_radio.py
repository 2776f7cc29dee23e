"""RSSI as evidence of where a phone's carrier is (trackctl.vmtrack.radio)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackctl.logs.messages import RssiReading, RssiScan, Vec3
from trackctl.vmtrack.radio import RadioConfig, RadioEvidence
from trackctl.vmtrack.retrack import _Grid

MODEL = (-40.0, 2.5)
AP = (0.0, 6.0)


def _scan(t_ns: int, heard: dict[str, float], ap: tuple[float, float] = AP) -> RssiScan:
    readings = tuple(RssiReading(mid, dbm) for mid, dbm in heard.items())
    return RssiScan(t_ns, "ap-0", readings, Vec3(ap[0], ap[1], 2.0))


def _room() -> _Grid:
    return _Grid([np.array([[0.0, 0.0], [16.0, 12.0]])], 0.2)


def _at(grid: _Grid, cost: np.ndarray, x: float, y: float) -> float:
    j, i = np.round((np.array([x, y]) - grid.lo) / grid.cell).astype(int)
    return float(cost[i, j])


def test_a_reading_puts_the_carrier_at_its_distance_from_the_ap():
    frame_t = np.arange(3) * 333_333_333
    level = MODEL[0] - 25 * math.log10(5.0)  # what the model gives at 5 m
    radio = RadioEvidence(frame_t, [_scan(340_000_000, {"m": level})], MODEL, RadioConfig())
    grid = _room()
    assert radio.cost("m", grid, 0) is None and radio.cost("m", grid, 2) is None
    cost = radio.cost("m", grid, 1)  # the scan counts at its nearest frame
    assert cost is not None
    rows, cols = np.unravel_index(np.argsort(cost, axis=None)[:50], cost.shape)
    d = np.hypot(grid.lo[0] + cols * grid.cell - AP[0], grid.lo[1] + rows * grid.cell - AP[1])
    assert np.all(np.abs(d - 5.0) < 0.3)
    # 1 m and 14 m from the AP are both far less likely than 5 m
    assert _at(grid, cost, 1.0, 6.0) > _at(grid, cost, 5.0, 6.0) + 1.0
    assert _at(grid, cost, 14.0, 6.0) > _at(grid, cost, 5.0, 6.0) + 1.0


def test_a_phone_no_ap_hears_is_out_of_view_and_one_heard_in_it():
    frame_t = np.arange(4) * 1_000_000_000
    scans = [_scan(0, {"m": -55.0}), _scan(2_000_000_000, {"other": -50.0})]
    cfg = RadioConfig()
    radio = RadioEvidence(frame_t, scans, MODEL, cfg)
    away = radio.away("m", 2.0)
    assert away.tolist() == [2.0 + cfg.away_heard_cost, 2.0, 2.0, 2.0]
    grid = _room()
    unheard = radio.cost("m", grid, 2)
    assert unheard is not None
    # in view anywhere in the room, the AP would have heard it: -log(1 - 0.9)
    assert unheard.min() == pytest.approx(-math.log(1 - cfg.hear_prob), rel=0.01)
    assert unheard.min() > cfg.away_heard_cost


def test_scans_without_an_ap_position_are_left_out():
    frame_t = np.arange(3) * 1_000_000_000
    scan = RssiScan(0, "ap-x", (RssiReading("m", -50.0),), None)
    radio = RadioEvidence(frame_t, [scan], MODEL, RadioConfig())
    assert not radio
    assert radio.away("m", 2.0).tolist() == [2.0, 2.0, 2.0]


def test_emissions_with_radio_add_the_scans_to_their_frames_and_reverse():
    frame_t = np.arange(3) * 1_000_000_000
    radio = RadioEvidence(frame_t, [_scan(1_000_000_000, {"m": -60.0})], MODEL, RadioConfig())
    grid = _room()
    base = [np.zeros(grid.shape, np.float32), 3.0, np.ones(grid.shape, np.float32)]
    em = radio.emissions("m", grid, base)
    assert len(em) == 3
    assert em[0] is base[0] and em[2] is base[2]
    extra = radio.cost("m", grid, 1)
    assert extra is not None
    np.testing.assert_allclose(em[1], 3.0 + extra)
    back = em[::-1]
    assert back[0] is base[2] and back[2] is base[0]
    np.testing.assert_allclose(back[1], em[1])
