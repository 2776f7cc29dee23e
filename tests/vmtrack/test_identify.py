"""Offline identity: the phone's path over chains (swaps at encounters), bridging short gaps."""

from __future__ import annotations

import numpy as np

from trackctl.vmtrack.identify import IdentifyConfig, _bridge, _Chain, _encounters, _viterbi

S = 1_000_000_000


def _chain(key: int, t0: float, t1: float, x0: float, x1: float) -> _Chain:
    """A chain walking along x from x0 at t0 to x1 at t1 (seconds), y = 0."""
    t = np.arange(t0, t1 + 1e-9, 1 / 3)
    x = np.interp(t, [t0, t1], [x0, x1])
    hits = np.column_stack([t * S, x, np.zeros_like(t)])
    return _Chain(key, np.round(t * S).astype(np.int64), np.zeros(len(t), complex), hits)


def _setup(chains: list[_Chain], n_f: int) -> tuple[np.ndarray, np.ndarray]:
    frame_t = np.round(np.arange(n_f) * S / 3).astype(np.int64)
    present = np.zeros((n_f, len(chains)), bool)
    for c, ch in enumerate(chains):
        present[np.isin(frame_t, ch.times), c] = True
    return frame_t, present


def test_a_gap_on_one_chain_is_held() -> None:
    chains = [_chain(1, 0, 10, 0, 10)]
    frame_t, present = _setup(chains, 31)
    path = np.zeros(31, int)
    path[10:16] = -1
    _bridge(path, present, chains, frame_t, 30, 1.0)
    assert (path == 0).all()


def test_a_handover_is_bridged_where_the_chains_meet() -> None:
    # chain 0 walks 0 -> 5 m over 0-5 s and stops being published; chain 1 starts at 4 s
    # near where chain 0 is (4 m) and walks on; the phone's path skips 3-6 s
    chains = [_chain(1, 0, 5, 0, 5), _chain(2, 4, 10, 4.1, 10)]
    frame_t, present = _setup(chains, 31)
    path = np.full(31, -1)
    path[:9] = 0
    path[19:] = 1
    _bridge(path, present, chains, frame_t, 30, 1.0)
    assert (path >= 0).all()
    h = int(np.argmax(path == 1))
    assert 12 <= h <= 16  # handed over while both were published, where they were closest
    assert (path[:h] == 0).all() and (path[h:] == 1).all()


def test_chains_that_do_not_meet_are_not_bridged() -> None:
    chains = [_chain(1, 0, 5, 0, 5), _chain(2, 4, 10, 9.0, 15)]  # 5 m apart at the handover
    frame_t, present = _setup(chains, 31)
    path = np.full(31, -1)
    path[:9] = 0
    path[19:] = 1
    before = path.copy()
    _bridge(path, present, chains, frame_t, 30, 1.0)
    assert (path == before).all()


def test_long_gaps_and_open_ends_stay() -> None:
    chains = [_chain(1, 0, 10, 0, 10)]
    frame_t, present = _setup(chains, 31)
    path = np.zeros(31, int)
    path[5:25] = -1  # 20 frames > max 10
    path[:2] = -1  # before the first stretch: no chain before it
    before = path.copy()
    _bridge(path, present, chains, frame_t, 10, 1.0)
    assert (path == before).all()


def test_a_route_through_a_third_chain() -> None:
    # the carrier's track breaks twice: 0-3 s, 2-6 s, 5-10 s, each taking over from the last
    chains = [_chain(1, 0, 3, 0, 3), _chain(2, 2, 6, 2.1, 6), _chain(3, 5, 10, 5.1, 10)]
    frame_t, present = _setup(chains, 31)
    path = np.full(31, -1)
    path[:6] = 0
    path[21:] = 2
    _bridge(path, present, chains, frame_t, 30, 1.0)
    assert (path >= 0).all()
    assert list(dict.fromkeys(path.tolist())) == [0, 1, 2]  # through chain 1, in order


def _crossing() -> tuple[list[_Chain], np.ndarray, list[np.ndarray]]:
    """Two chains crossing at x = 5 m at 5 s (one walks 0 -> 10 m, the other 10 -> 0 m)."""
    chains = [_chain(1, 0, 10, 0, 10), _chain(2, 0, 10, 10, 0)]
    frame_t, present = _setup(chains, 31)
    rows = [np.flatnonzero(present[:, c]) for c in range(2)]
    return chains, frame_t, _encounters(chains, rows, frame_t, 1.0)


def test_encounters_are_the_frames_where_chains_pass_close() -> None:
    _, frame_t, near = _crossing()
    close = [f for f in range(len(frame_t)) if len(near[f])]
    assert close == [14, 15, 16]  # within 1 m of each other: 4.5-5.5 s
    assert sorted(near[15][0].tolist()) == [0, 1]


def test_a_swap_at_an_encounter_moves_the_phone_where_a_switch_would_not() -> None:
    # the tracker swapped the two people at the crossing: the phone fits chain 0 before it and
    # chain 1 after it, each by a little
    chains, frame_t, near = _crossing()
    cost = np.full((31, 2), 0.1)
    cost[:15, 0] = 0.02
    cost[15:, 1] = 0.05
    cfg = IdentifyConfig()
    # staying on chain 0 costs 16 x 0.05 more than it should, less than switch_cost 2
    assert (_viterbi(cost, cfg) == 0).all()
    path = _viterbi(cost, cfg, near)
    assert (path[:15] == 0).all() and (path[16:] == 1).all()
    # chains that never meet are not swapped on such thin evidence
    far = [np.empty((0, 2), int)] * 31
    assert (_viterbi(cost, cfg, far) == 0).all()
