"""Phones of the realistic preset (trackctl.sim.phones): what an always-on phone's carrier
does while no camera sees them."""

from __future__ import annotations

import numpy as np
import pytest

from trackctl.sim.phones import _walk_velocity, _whereabouts
from trackctl.sim.walkers import Trajectory


@pytest.mark.parametrize("seed", range(8))
def test_an_unseen_carrier_never_walks_back_through_the_view(seed: int) -> None:
    # in view from 40 s to 60 s, crossing a 10 m wide view from x = 0 to x = 10 at 0.5 m/s
    dt = 0.1
    xs = np.arange(0.0, 10.0 + 1e-9, 0.5 * dt)
    view = Trajectory("p", 40.0, dt, np.column_stack([xs, np.full(len(xs), 5.0)]))
    t, vel, xy = _walk_velocity(view, 120.0, dt, np.random.default_rng(seed), True)
    inside = ~np.isnan(xy).any(axis=1)
    i0, i1 = np.flatnonzero(inside)[[0, -1]]
    # positions the phone's walk puts them at, from where they came into view and left it
    before = xy[i0] - np.cumsum(vel[: i0 + 1][::-1], axis=0)[::-1] * dt + vel[i0] * dt
    after = xy[i1] + np.cumsum(vel[i1 + 1 :], axis=0) * dt
    assert (before[:-1, 0] <= 0.0 + 1e-6).all()
    assert (after[:, 0] >= 10.0 - 1e-6).all()
    # and they walk there: not standing the whole time
    assert np.hypot(*vel[:i0].T).max() > 0.7
    assert np.hypot(*vel[i1 + 1 :].T).max() > 0.7


def test_phones_that_report_only_in_view_have_no_walk_outside() -> None:
    dt = 0.1
    view = Trajectory("p", 5.0, dt, np.column_stack([np.linspace(0, 5, 51), np.zeros(51)]))
    _, vel, xy = _walk_velocity(view, 20.0, dt, np.random.default_rng(0), False)
    assert np.isnan(vel[np.isnan(xy).any(axis=1)]).all()


@pytest.mark.parametrize("seed", range(4))
def test_the_carriers_whereabouts_continue_their_walk_out_of_view(seed: int) -> None:
    # what the APs hear an always-on phone from: where the carrier is, in view or not
    dt = 0.1
    xs = np.arange(0.0, 10.0 + 1e-9, 0.5 * dt)
    view = Trajectory("p", 40.0, dt, np.column_stack([xs, np.full(len(xs), 5.0)]))
    t, vel, xy = _walk_velocity(view, 120.0, dt, np.random.default_rng(seed), True)
    where = _whereabouts(t, vel, xy)
    inside = ~np.isnan(xy).any(axis=1)
    assert not np.isnan(where).any()
    np.testing.assert_allclose(where[inside, 1:], xy[inside])
    # no jump anywhere: each step is the walk's (1.4 m/s at most out of view)
    jumps = np.hypot(*np.diff(where[:, 1:], axis=0).T)
    assert jumps.max() <= 1.4 * dt + 1e-6
    # out of view they are out of the view's span, and away from it by the end
    assert (where[~inside & (t < 40.0), 1] <= 1e-6).all()
    assert (where[~inside & (t > 60.0), 1] >= 10.0 - 1e-6).all()
    assert where[-1, 1] > 15.0


def test_a_carrier_never_in_view_is_nowhere_the_aps_hear() -> None:
    dt = 0.1
    view = Trajectory("p", 500.0, dt, np.column_stack([np.zeros(3), np.zeros(3)]))
    t, vel, xy = _walk_velocity(view, 20.0, dt, np.random.default_rng(0), True)
    assert np.isnan(_whereabouts(t, vel, xy)[:, 1:]).all()
