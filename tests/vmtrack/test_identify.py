"""Offline identity: the phone's path over chains (swaps at encounters), bridging short gaps."""

from __future__ import annotations

import numpy as np

from trackctl.vmtrack.align import AlignConfig
from trackctl.vmtrack.identify import (
    IdentifyConfig,
    Identities,
    _alignment_track,
    _bridge,
    _carry_through_unseen,
    _Chain,
    _encounters,
    _viterbi,
)

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


def test_a_carry_change_starts_a_new_alignment_at_once() -> None:
    # a walker turning now and then; the phone's heading offset flips by 180 deg when it moves
    # from one pocket to another at frame 150 (its motion stage reports the change)
    n_f = 300
    frame_t = np.round(np.arange(n_f) * S / 3).astype(np.int64)
    heading = np.cumsum(np.where(np.arange(n_f) % 40 < 5, 0.3, 0.0))
    z_track = 1.2 * np.exp(1j * heading)
    flip = np.where(np.arange(n_f) < 150, 1.0, -1.0)
    z_phone = (z_track / flip)[:, None]  # z_track = a z_phone, a = +1 then -1
    hits = np.column_stack([frame_t, np.zeros(n_f), np.zeros(n_f)]).astype(float)
    chain = _Chain(1, frame_t, z_track, hits)
    rows = [np.arange(n_f)]
    args = ([chain], rows, [z_phone], frame_t, np.array([0.0]), AlignConfig(), IdentifyConfig())
    path = np.zeros(n_f, int)
    known = _alignment_track(path, *args, carry_changes=frame_t[[150]])
    assert known is not None
    yaw = np.degrees(np.angle(known[1]))
    assert np.all(np.abs(yaw[:150]) < 1) and np.all(np.abs(np.abs(yaw[150:]) - 180) < 1)
    assert np.allclose(np.abs(known[1]), 1.0, atol=0.01)  # the step scale: right throughout
    # without the change, the windows near it mix the two carries: opposite velocities cancel,
    # and the fitted scale collapses (to the lowest allowed)
    _, blind = _alignment_track(path, *args)  # type: ignore[misc]
    assert np.all(np.abs(blind[130:170]) < 0.8)


def _unseen(b_x0: float) -> Identities:
    """A carrier walks along x at 1 m/s for 20 s; chain 1 shows them until 8 s, chain 2 from
    12 s (starting at ``b_x0``); the phone's dead-reckoned path is the walk, rotated by 90 deg
    (its device heading) and on its own clock, 0.5 s ahead."""
    a, b = _chain(1, 0, 8, 0, 8), _chain(2, 12, 20, b_x0, b_x0 + 8)
    frame_t = np.round(np.arange(61) * S / 3).astype(np.int64)
    out = Identities()
    for ch in (a, b):
        for t in ch.times:
            out.mid_at[(ch.key, int(t))] = "m1"
    t = np.arange(0, 21, 0.1)
    dr = np.column_stack([(t + 0.5) * S, np.zeros_like(t), t])  # phone time = camera + 0.5 s
    lags = np.array([0.0, 0.5])
    cfg = IdentifyConfig()
    known = (1, np.full(len(frame_t), np.exp(-1j * np.pi / 2)))  # z_track = a z_phone
    _carry_through_unseen("m1", out, [a, b], frame_t, dr, lags, known, cfg)
    return out


def test_a_carrier_no_camera_sees_is_walked_on_their_phone() -> None:
    out = _unseen(12.0)
    times = sorted(out.unseen)
    assert [round(t / S, 2) for t in (times[0], times[-1])] == [8.33, 11.67]
    for t_ns in times:
        ((mid, (x, y), (vx, _)),) = out.unseen[t_ns]
        assert mid == "m1"
        assert abs(x - t_ns / S) < 0.05 and abs(y) < 0.05 and abs(vx - 1.0) < 0.1


def test_a_gap_the_phone_did_not_walk_is_left_empty() -> None:
    # the chain after starts 3 m from where the phone's walk ends: somebody else
    assert _unseen(15.0).unseen == {}
