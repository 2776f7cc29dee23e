"""Step detection: synthetic walks at 5-200 Hz, and the real phone traces (Oxford step counter)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import SHARED_DATA, examples, shared_file
from trackctl.pdr.steps import detect_steps

G = 9.80665


def _walk(
    rate: float,
    cadence: float,
    walk_s: float = 60.0,
    still_s: float = 10.0,
    stride_share: float = 0.5,
    seed: int = 0,
    jitter: float = 0.0,
    drop: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, int]:
    """A walker standing, walking ``walk_s`` at ``cadence``, standing: time, specific force in a
    tilted device frame, true steps. The bounce has a stride component (one leg) and noise."""
    rng = np.random.default_rng(seed)
    total = walk_s + 2 * still_s
    t = np.arange(0.0, total, 1.0 / rate)
    t = t + rng.uniform(-jitter, jitter, len(t)) / rate
    t = np.sort(t)
    walking = (t >= still_s) & (t < still_s + walk_s)
    ph = 2 * math.pi * cadence * (t - still_s)
    bounce = 2.5 * np.sin(ph) + stride_share * 2.5 * np.sin(ph / 2 + 0.3)
    bounce += 0.8 * np.sin(2 * ph + 1.0)  # impact harmonic
    vert = np.where(walking, bounce, 0.0) + rng.normal(0, 0.05, len(t))
    fwd = np.where(walking, 0.8 * np.sin(ph + 0.7), 0.0)
    acc = np.column_stack([fwd, np.zeros(len(t)), G + vert])
    tilt = np.array(
        [[1, 0, 0], [0, math.cos(0.6), -math.sin(0.6)], [0, math.sin(0.6), math.cos(0.6)]]
    )
    acc = acc @ tilt.T + rng.normal(0, 0.1, acc.shape)
    keep = rng.uniform(size=len(t)) >= drop
    return t[keep], acc[keep], int(math.floor(cadence * walk_s))


@pytest.mark.parametrize("rate", [5.0, 25.0, 100.0, 200.0])
def test_synthetic_walk_counts_steps_and_stands_still(rate: float) -> None:
    t, acc, true = _walk(rate, 1.8)
    res = detect_steps(t, acc)
    assert abs(res.steps - true) <= 0.03 * true + 1
    # no steps while standing (a second of margin for the windows' edges)
    assert not ((res.step_times_s < 9.0) | (res.step_times_s > 71.0)).any()


@settings(max_examples=examples(25), deadline=None)
@given(
    cadence=st.floats(1.4, 2.3),
    rate=st.sampled_from([5.0, 10.0, 20.0, 50.0, 100.0, 200.0]),
    stride=st.floats(0.0, 2.0),
    jitter=st.floats(0.0, 0.3),
    drop=st.floats(0.0, 0.1),
    seed=st.integers(0, 1000),
)
def test_step_count_holds_across_rates_jitter_and_drops(
    cadence: float, rate: float, stride: float, jitter: float, drop: float, seed: int
) -> None:
    if cadence >= 0.95 * rate / 2:  # above Nyquist the step rate cannot be recovered
        return
    t, acc, true = _walk(rate, cadence, 40.0, 6.0, stride, seed, jitter, drop)
    res = detect_steps(t, acc)
    assert abs(res.steps - true) <= 0.05 * true + 2


def test_bad_samples_are_dropped_and_counted() -> None:
    t, acc, true = _walk(50.0, 1.7, 40.0, 5.0)
    acc[:20] = 0.0  # a sensor warming up
    acc[500] = np.nan
    res = detect_steps(t, acc)
    assert res.bad_samples == 21
    assert abs(res.steps - true) <= 0.03 * true + 1


CARRIES = ["hand", "frontpocket", "backpocket", "bag", "armband", "neckpouch"]


def _trace(carry: str) -> tuple[np.ndarray, np.ndarray, float]:
    shared_file("phones", "README.md")
    (path,) = sorted((SHARED_DATA / "phones").glob(f"user1_{carry}_*.csv"))
    d = pd.read_csv(path, header=None).to_numpy()
    return d[:, 0] / 1e9, d[:, 1:4], float(d[-1, 5] - d[0, 5])


@pytest.mark.parametrize("carry", CARRIES)
def test_real_walks_at_100_hz_within_3_percent(carry: str) -> None:
    t, acc, true = _trace(carry)
    assert abs(detect_steps(t, acc).steps - true) <= 0.03 * true


@pytest.mark.parametrize("carry", CARRIES)
def test_real_walks_decimated_to_5_hz_within_5_percent(carry: str) -> None:
    t, acc, true = _trace(carry)
    assert abs(detect_steps(t[::20], acc[::20]).steps - true) <= 0.05 * true
