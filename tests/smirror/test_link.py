"""The node link: a FIFO queue with a capacity; unicast copies pile up, broadcast does not."""

from __future__ import annotations

import numpy as np
import pytest

from trackctl.smirror.link import LinkConfig, NodeLink


def _run(requests: int, broadcast: bool, n: int = 200, period_ms: float = 200.0) -> list:
    link = NodeLink(LinkConfig(), np.random.default_rng(0))
    return [link.send(i * period_ms, 10_000, requests, broadcast, True) for i in range(n)]


def test_single_unicast_answer_is_latency_plus_airtime() -> None:
    (d,) = _run(1, False, n=1)
    # 10 kB at 1000 kB/s = 10 ms, + 35 ms latency
    assert d.comm_ms == pytest.approx(45.0) and d.queue_ms == 0.0 and not d.dropped


def test_unicast_overload_grows_the_queue_then_drops() -> None:
    # 5 answers/s x 100 copies x 10 kB = 5 MB/s offered on a 1 MB/s link
    out = _run(100, False)
    queues = [d.queue_ms for d in out]
    assert queues[5] > queues[1] > 0
    assert sum(d.dropped for d in out) > 0.5 * len(out)
    assert max(queues) <= LinkConfig().max_queue_ms + 100 * 10.0


def test_broadcast_delay_does_not_grow_with_requesters() -> None:
    one = [d.comm_ms for d in _run(1, True) if d.comm_ms is not None]
    many = [d.comm_ms for d in _run(500, True) if d.comm_ms is not None]
    assert np.mean(many) == pytest.approx(np.mean(one), rel=0.05)
    # DTIM wait (mean 154 ms) + 40 ms airtime + 35 ms latency: the paper's ~250 ms
    assert 180 < np.mean(one) < 300
    lost = sum(d.lost for d in _run(1, True, n=2000))
    assert 50 < lost < 150  # 5 % of 2000


def test_other_requesters_traffic_occupies_the_link() -> None:
    link = NodeLink(LinkConfig(), np.random.default_rng(0))
    first = link.send(0.0, 10_000, 50, False, False)
    assert first.comm_ms is None and link.busy_until_ms == pytest.approx(500.0)
    ours = link.send(100.0, 10_000, 1, False, True)
    assert ours.queue_ms == pytest.approx(400.0) and ours.comm_ms == pytest.approx(445.0)


def test_bad_configs() -> None:
    with pytest.raises(ValueError, match="unicast_kBps must be positive"):
        LinkConfig(unicast_kBps=0)
    with pytest.raises(ValueError, match="broadcast_loss"):
        LinkConfig(broadcast_loss=1.5)


def test_each_of_our_robots_gets_its_own_copy() -> None:
    link = NodeLink(LinkConfig(), np.random.default_rng(0))
    d = link.send(0.0, 10_000, 5, False, 3)
    # five 10 ms copies queued; ours are three different places among them
    assert len(d.arrivals) == 3 and len(set(d.arrivals)) == 3
    assert all(a is not None and 45.0 <= a <= 85.0 for a in d.arrivals)
    none = link.send(1000.0, 10_000, 5, False, 0)
    assert none.arrivals == () and none.comm_ms is None


def test_broadcast_losses_are_per_receiver() -> None:
    link = NodeLink(LinkConfig(broadcast_loss=0.5), np.random.default_rng(1))
    out = [link.send(i * 500.0, 10_000, 20, True, 2) for i in range(400)]
    # one copy on the air, every receiver of ours with its own chance to miss it
    both = [d.arrivals for d in out]
    assert all(len(a) == 2 for a in both)
    one_only = sum((a[0] is None) != (a[1] is None) for a in both)
    assert 120 < one_only < 280  # 2 x 0.5 x 0.5 of 400
    assert sum(d.lost for d in out) == sum(a is None for x in both for a in x)
