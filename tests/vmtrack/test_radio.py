"""RSSI as evidence of where a phone's carrier is (trackctl.vmtrack.radio)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackctl.logs.messages import RssiReading, RssiScan, Vec3
from trackctl.vmtrack.grid import SiteGrid
from trackctl.vmtrack.radio import (
    PathLoss,
    RadioConfig,
    RadioEvidence,
    _scan_cost,
    fit_path_loss,
)

MODEL = (-40.0, 2.5)
AP = (0.0, 6.0)


def _scan(t_ns: int, heard: dict[str, float], ap: tuple[float, float] = AP) -> RssiScan:
    readings = tuple(RssiReading(mid, dbm) for mid, dbm in heard.items())
    return RssiScan(t_ns, "ap-0", readings, Vec3(ap[0], ap[1], 2.0))


def _room() -> SiteGrid:
    return SiteGrid([np.array([[0.0, 0.0], [16.0, 12.0]])], 0.2)


def _at(grid: SiteGrid, cost: np.ndarray, x: float, y: float) -> float:
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


def test_a_frames_cost_is_the_sum_of_its_scans_costs_bit_for_bit():
    # the AP's level and hearing chance are computed once per grid; each scan's cost is
    # what _scan_cost gives it on its own (heard at two levels, not heard, two APs)
    frame_t = np.arange(3) * 1_000_000_000
    scans = [
        _scan(0, {"m": -62.0}),
        _scan(10, {"other": -50.0}, ap=(12.0, 2.0)),
        _scan(1_000_000_000, {"m": -48.5}),
        _scan(2_000_000_000, {"other": -70.0}),
    ]
    cfg = RadioConfig()
    radio = RadioEvidence(frame_t, scans, MODEL, cfg)
    grid = _room()
    rows, cols = np.indices(grid.shape)
    for k, parts in enumerate([[(AP, -62.0), ((12.0, 2.0), None)], [(AP, -48.5)], [(AP, None)]]):
        want = np.zeros(grid.shape, np.float32)
        for ap, r in parts:
            d = np.hypot(
                grid.lo[0] + cols * grid.cell - ap[0], grid.lo[1] + rows * grid.cell - ap[1]
            )
            d = np.maximum(d, 0.3).astype(np.float32)
            want += _scan_cost(radio.default, d, r, cfg)
        for _ in range(2):  # computed, then from the AP's cached level
            got = radio.cost("m", grid, k)
            assert got is not None and np.array_equal(got, want)


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


def _walk_past_aps(
    aps: dict[str, tuple[float, float, float, float]],
    wrong_share: float = 0.0,
    seed: int = 0,
) -> tuple[list[RssiScan], dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Three carriers walking a 16 x 12 m room for 200 s, heard once a second by each AP
    (id -> x, y, level at 1 m, exponent; 4 dB shadowing); ``wrong_share`` of the placements
    are the next walker's position (a wrong identity)."""
    rng = np.random.default_rng(seed)
    t = np.arange(200) * 1_000_000_000
    walks = {}
    for i in range(3):
        phase = rng.uniform(0, 2 * np.pi)
        s = np.arange(200) / 15.0 + phase
        walks[f"m{i}"] = np.column_stack([8 + 7 * np.cos(s + i), 6 + 5 * np.sin(1.3 * s)])
    scans = []
    for k, tk in enumerate(t):
        for ap, (x, y, at1, n) in aps.items():
            heard = {}
            for mid, xy in walks.items():
                d = max(0.3, math.hypot(xy[k, 0] - x, xy[k, 1] - y))
                heard[mid] = at1 - 10 * n * math.log10(d) + rng.normal(0, 4.0)
            readings = tuple(RssiReading(m, r) for m, r in heard.items())
            scans.append(RssiScan(int(tk), ap, readings, Vec3(x, y, 2.0)))
    placed = {}
    for i, (mid, xy) in enumerate(walks.items()):
        xy = xy.copy()
        wrong = rng.random(len(xy)) < wrong_share
        xy[wrong] = walks[f"m{(i + 1) % 3}"][wrong]
        placed[mid] = (t, xy)
    return scans, placed


def test_each_aps_path_loss_is_fitted_from_where_the_carriers_were():
    aps = {"a": (0.0, 6.0, -47.0, 3.2), "b": (16.0, 0.0, -33.0, 2.1)}
    scans, placed = _walk_past_aps(aps)
    fit = fit_path_loss(scans, placed, MODEL, RadioConfig())
    for ap, (_, _, at1, n) in aps.items():
        assert fit[ap].at1_dbm == pytest.approx(at1, abs=1.5)
        assert fit[ap].exponent == pytest.approx(n, abs=0.15)
        assert 3.0 <= fit[ap].sigma_db < 5.0  # the shadowing, shrunk a little towards 6 dB
        assert fit[ap].readings == 600


def test_a_fit_survives_a_tenth_of_the_carriers_placed_on_somebody_else():
    # a wrong placement's distance is another walker's: it dilutes the slope (an error in the
    # variable, not an outlier of the reading); a tenth of them, by a little
    aps = {"a": (0.0, 6.0, -47.0, 3.2)}
    for seed in (1, 2):
        scans, placed = _walk_past_aps(aps, wrong_share=0.1, seed=seed)
        fit = fit_path_loss(scans, placed, MODEL, RadioConfig())["a"]
        assert fit.at1_dbm == pytest.approx(-47.0, abs=1.5)
        assert fit.exponent == pytest.approx(3.2, abs=0.15)


def test_an_ap_without_placed_readings_keeps_the_prior():
    scans, _ = _walk_past_aps({"a": (0.0, 6.0, -47.0, 3.2)})
    fit = fit_path_loss(scans, {}, MODEL, RadioConfig())
    assert fit == {"a": PathLoss(MODEL[0], MODEL[1], RadioConfig().sigma_db, 0)}
    # a placement far in time from every scan does not count
    far = {"m0": (np.array([10**15]), np.array([[1.0, 1.0]]))}
    assert fit_path_loss(scans, far, MODEL, RadioConfig())["a"].readings == 0


def test_fitted_evidence_weighs_each_ap_by_its_own_model():
    frame_t = np.arange(3) * 1_000_000_000
    loud = PathLoss(-30.0, 2.0, 3.0, 100)
    level = loud.at1_dbm - 20 * math.log10(5.0)  # 5 m from the loud AP
    scans = [_scan(1_000_000_000, {"m": level})]
    grid = _room()
    fitted = RadioEvidence(frame_t, scans, {"ap-0": loud}, RadioConfig()).cost("m", grid, 1)
    default = RadioEvidence(frame_t, scans, MODEL, RadioConfig()).cost("m", grid, 1)
    assert fitted is not None and default is not None
    assert _at(grid, fitted, 5.0, 6.0) < _at(grid, fitted, 2.0, 6.0) - 1.0
    # the default model puts the same level much nearer the AP
    assert _at(grid, default, 2.0, 6.0) < _at(grid, default, 5.0, 6.0)


def test_gain_is_the_away_cost_less_the_in_view_cost_at_the_path():
    frame_t = np.arange(4) * 1_000_000_000
    level = MODEL[0] - 25 * math.log10(5.0)
    scans = [_scan(0, {"m": level}), _scan(2_000_000_000, {"other": -50.0})]
    radio = RadioEvidence(frame_t, scans, MODEL, RadioConfig())
    grid = _room()
    path = np.array([[5.0, 6.0], [5.0, 6.0], [5.0, 6.0], [np.nan, np.nan]])
    gain = radio.gain("m", path)
    heard, unheard = radio.cost("m", grid, 0), radio.cost("m", grid, 2)
    assert heard is not None and unheard is not None
    away = radio.away("m", 0.0)
    assert gain[0] == pytest.approx(away[0] - _at(grid, heard, 5.0, 6.0), abs=0.05)
    assert gain[2] == pytest.approx(-_at(grid, unheard, 5.0, 6.0), abs=0.05)
    assert gain[1] == 0.0 and gain[3] == 0.0  # no scan; out of view
    assert gain[0] > 0 > gain[2]
    # heard at the level of 5 m, a path 1 m from the AP gains less than one 5 m away
    assert radio.gain("m", np.array([[1.0, 6.0]]))[0] < gain[0] - 1.0
