"""The BridgeLoc simulator's wheel odometry: the paper preset reads the true wheel travel, the
realistic one adds the documented errors (wheel base, scrubbing per turn, slip) at their
stated sizes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackctl.sim.bridgeloc import PRESETS, _wheel_travel

BASE = 0.30
DT = 1 / 25


def _drive(metres: float, v: float = 0.4) -> tuple[np.ndarray, np.ndarray]:
    n = int(round(metres / (v * DT)))
    return np.full(n, v * DT), np.zeros(n)


def _turn(rad: float, om: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    n = int(round(abs(rad) / (om * DT)))
    return np.zeros(n), np.full(n, rad / n)


def _heading(left: np.ndarray, right: np.ndarray) -> float:
    return float(np.sum(right - left) / BASE)


def test_paper_preset_reads_the_true_travel() -> None:
    ds, dyaw = _drive(3.0)
    left, right = _wheel_travel(ds, dyaw, BASE, PRESETS["paper"], seed=1)
    assert np.array_equal(left, ds) and np.array_equal(right, ds)
    ds, dyaw = _turn(math.pi / 2)
    left, right = _wheel_travel(ds, dyaw, BASE, PRESETS["paper"], seed=1)
    assert _heading(left, right) == pytest.approx(math.pi / 2)


def test_slip_is_a_heading_random_walk_of_the_stated_size() -> None:
    real = PRESETS["realistic"]
    ds, dyaw = _drive(25.0)
    errs = [_heading(*_wheel_travel(ds, dyaw, BASE, real, seed)) for seed in range(300)]
    expected = math.sqrt(2 * real.slip_k_m * 25.0) / BASE
    assert float(np.std(errs)) == pytest.approx(expected, rel=0.2)
    assert abs(float(np.mean(errs))) < 3 * expected / math.sqrt(300)


def test_turns_err_by_wheel_base_and_scrubbing_whatever_the_odometry_rate() -> None:
    real = PRESETS["realistic"]
    expected = math.hypot(real.wheelbase_err, real.turn_slip) * (math.pi / 2)
    for om in (1.0, 0.25):  # 40 or 160 odometry steps in the turn: the same error
        ds, dyaw = _turn(math.pi / 2, om)
        errs = [
            _heading(*_wheel_travel(ds, dyaw, BASE, real, seed)) - math.pi / 2
            for seed in range(300)
        ]
        assert float(np.std(errs)) == pytest.approx(expected, rel=0.2)


def test_each_turn_scrubs_on_its_own() -> None:
    """Two turns in one log err differently (scrubbing), on top of the common wheel base."""
    real = PRESETS["realistic"]
    a_ds, a_dyaw = _turn(math.pi / 2)
    d_ds, d_dyaw = _drive(1.0)
    ds = np.concatenate([a_ds, d_ds, a_ds])
    dyaw = np.concatenate([a_dyaw, d_dyaw, a_dyaw])
    n = len(a_ds)
    diffs = []
    for seed in range(200):
        left, right = _wheel_travel(ds, dyaw, BASE, real, seed)
        first = _heading(left[:n], right[:n])
        second = _heading(left[-n:], right[-n:])
        diffs.append(first - second)
    expected = math.sqrt(2) * real.turn_slip * (math.pi / 2)
    assert float(np.std(diffs)) == pytest.approx(expected, rel=0.25)
