"""A node's wireless link as a queue with a capacity (what makes the broadcast switch matter).

Each S-Mirror node sends through its own access point: one FIFO transmit queue drained at the
link's throughput. A unicast answer to N requesters is N copies of the payload queued one after
the other; a broadcast answer is one copy sent at the basic rate when the access point next
delivers group-addressed frames (the DTIM beacon: a wait uniform over the DTIM interval) and,
having no link-layer retry, is lost with some probability. When the queue already holds more than
``max_queue_ms`` of airtime, a new answer is dropped (tail drop): offered load beyond the
capacity shows as growing delay, then as answers that never arrive.

Defaults (§4.1.3 and 802.11 practice): 1000 kB/s unicast throughput (the paper's link), 35 ms
latency, 250 kB/s basic rate, beacon interval 102.4 ms x DTIM period 3 (a wait of 154 ms on
average: with the airtime, the paper's ~250 ms broadcast delay), 5 % broadcast loss, 1 s queue.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["LinkConfig", "NodeLink", "Delivery"]


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """Throughputs, latency, DTIM interval, broadcast loss and queue limit of a node's link."""

    unicast_kBps: float = 1000.0  # noqa: N815 - kB/s, as the paper writes it
    latency_ms: float = 35.0
    broadcast_kBps: float = 250.0  # noqa: N815
    dtim_ms: float = 3 * 102.4
    broadcast_loss: float = 0.05
    max_queue_ms: float = 1000.0

    def __post_init__(self) -> None:
        for name in ("unicast_kBps", "broadcast_kBps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if not 0.0 <= self.broadcast_loss <= 1.0:
            raise ValueError(f"broadcast_loss must be in 0..1, got {self.broadcast_loss}")
        if self.max_queue_ms < 0 or self.dtim_ms < 0 or self.latency_ms < 0:
            raise ValueError("latency_ms, dtim_ms and max_queue_ms must be >= 0")


@dataclass(frozen=True, slots=True)
class Delivery:
    """What became of one answer: when each of our robots' copies arrives, or why not."""

    queue_ms: float
    """Time the answer waited behind earlier ones (not counting a broadcast's DTIM wait)."""
    dropped: bool = False
    """The queue was full: nothing was sent."""
    arrivals: tuple[float | None, ...] = ()
    """Per receiving robot of ours: queueing + transmission + latency of its copy (ms after the
    answer was queued), None when a broadcast without link-layer retry did not reach it."""

    @property
    def comm_ms(self) -> float | None:
        """The first receiving robot's arrival (None: none of ours received it)."""
        return self.arrivals[0] if self.arrivals else None

    @property
    def lost(self) -> int:
        """How many of our robots missed the broadcast."""
        return sum(a is None for a in self.arrivals)


class NodeLink:
    """One node's transmit queue (times in ms of log time)."""

    def __init__(self, cfg: LinkConfig, rng: np.random.Generator) -> None:
        self.cfg = cfg
        self.rng = rng
        self.busy_until_ms = 0.0
        self.sent_bytes = 0
        # the access point's DTIM beacons: every dtim_ms from a random phase
        self._dtim_phase = float(rng.uniform(0.0, cfg.dtim_ms)) if cfg.dtim_ms > 0 else 0.0

    def _next_dtim(self, t_ms: float) -> float:
        d = self.cfg.dtim_ms
        if d <= 0:
            return t_ms
        return self._dtim_phase + math.ceil((t_ms - self._dtim_phase) / d) * d

    def send(
        self, t_ms: float, size_bytes: int, requests: int, broadcast: bool, ours: int
    ) -> Delivery:
        """Queue one answer of ``size_bytes`` for ``requests`` requesters, ``ours`` of which are
        robots this run localizes (the others are traffic)."""
        cfg = self.cfg
        queue_ms = max(0.0, self.busy_until_ms - t_ms)
        if queue_ms > cfg.max_queue_ms:
            return Delivery(queue_ms, dropped=True)
        if broadcast:
            # held for the next DTIM beacon (the channel stays free meanwhile), then sent
            # after whatever is queued ahead of it
            start = max(self._next_dtim(t_ms), self.busy_until_ms)
            airtime = size_bytes / cfg.broadcast_kBps
            self.busy_until_ms = start + airtime
            self.sent_bytes += size_bytes
            done = self.busy_until_ms + cfg.latency_ms - t_ms
            # no link-layer retry: each receiver misses it on its own
            got = [bool(self.rng.random() >= cfg.broadcast_loss) for _ in range(ours)]
            return Delivery(queue_ms, arrivals=tuple(done if g else None for g in got))
        start = max(t_ms, self.busy_until_ms)
        airtime = size_bytes / cfg.unicast_kBps
        self.busy_until_ms = start + requests * airtime
        self.sent_bytes += size_bytes * requests
        if ours <= 0:
            return Delivery(queue_ms)
        # our copies' places among the requests' copies
        if ours == 1:
            places = [int(self.rng.integers(1, requests + 1))]
        else:
            places = [int(k) + 1 for k in self.rng.choice(requests, ours, replace=False)]
        return Delivery(
            queue_ms, arrivals=tuple(start + k * airtime + cfg.latency_ms - t_ms for k in places)
        )
