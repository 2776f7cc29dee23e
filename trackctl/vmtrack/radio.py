"""The phones' RSSI at the site's APs as evidence of where their carriers are, for re-tracking.

The paper's phone app streams its motion sensors over WiFi, so the site's APs hear each phone
every scan while it is within their range (§3.1.2; its check-point APs stand at the entries).
What one AP hears says two things about a phone's carrier, whatever their motion:

* **Present or not.** A phone no AP hears is far from the APs, so not in the cameras' view
  (the view lies within the APs' range); a phone heard is near, though perhaps just outside
  the view. In a crowd this is what tells the carrier's visit apart from a stranger's walk that
  fits the phone's while the carrier is elsewhere (:attr:`RetrackConfig.away_cost`).
* **Roughly where.** The log-distance path loss (the model of the check-points,
  :class:`~trackctl.vmtrack.config.VmTrackConfig`) gives the distance to the AP to within
  tens of per cent; a stranger across the room is told apart, a companion at one's side is not.

Each scan adds, at its nearest frame, a cost to every cell of the path's grid and one to the
out-of-view state (negative log-likelihoods, robust: a Huber loss on the level):

* heard at ``r`` dBm, in view at distance ``d``: ``huber((r - mu(d)) / sigma_db)`` and
  ``-log p_hear(d)``; out of view: ``away_heard_cost``;
* not heard, in view at ``d``: ``-log(1 - p_hear(d))``; out of view: nothing,

with ``p_hear(d) = hear_prob * Phi((mu(d) - floor_dbm) / sigma_db)``. ``sigma_db`` covers the
shadowing (the paper's 3 dB) and each AP's calibration, which the processor does not know (a
site calibrates its APs to within a few dB: :class:`~trackctl.sim.vm.VmRealism` draws them
7 dB either side of the default).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, overload

import numpy as np
from scipy.special import ndtr

from trackctl.logs.messages import RssiScan

if TYPE_CHECKING:
    from trackctl.vmtrack.retrack import _Grid

__all__ = ["RadioConfig", "RadioEvidence"]


@dataclass(frozen=True, slots=True)
class RadioConfig:
    """How re-tracking reads the phones' RSSI (dB, probabilities, costs in -log likelihood)."""

    enabled: bool = True
    sigma_db: float = 6.0
    """Spread of a reading about the path-loss model: the shadowing (3 dB, the paper's) and
    each AP's calibration error (about 5 dB for a site that calibrated to the nearest few dB)."""
    huber: float = 2.0
    """Readings further than this many ``sigma_db`` from the model cost linearly (a body in the
    way, a reflection)."""
    hear_prob: float = 0.9
    """Chance that an AP's scan hears a phone well within its range (the app streams; a scan
    can still miss a frame)."""
    floor_dbm: float = -90.0
    """Sensitivity of the APs: a phone whose level would fall below it is not heard."""
    away_heard_cost: float = 1.5
    """Cost of a reading while the carrier is out of view: -log(0.2), an AP hears a phone whose
    carrier is out of view a fifth of the time (they are just outside, by a door)."""


class RadioEvidence:
    """A log's RSSI scans, ready to weigh the paths of each phone.

    Args:
        frame_t: The frames' times, ns (a scan counts at its nearest frame).
        scans: The log's scans; those without an AP position are left out.
        model: The APs' path loss: RSSI at 1 m (dBm) and exponent.
        cfg: Its weights.
    """

    def __init__(
        self,
        frame_t: np.ndarray,
        scans: Sequence[RssiScan],
        model: tuple[float, float],
        cfg: RadioConfig,
    ) -> None:
        self.cfg = cfg
        self.model = model
        self.n = len(frame_t)
        self.by_frame: dict[int, list[tuple[tuple[float, float], dict[str, float]]]] = {}
        if not len(frame_t):
            return
        for scan in scans:
            pos = scan.observer_position_m
            if pos is None:
                continue
            k = int(np.searchsorted(frame_t, scan.t_ns))
            if k > 0 and (k == len(frame_t) or scan.t_ns - frame_t[k - 1] < frame_t[k] - scan.t_ns):
                k -= 1
            heard = {r.eid: float(r.rssi_dbm) for r in scan.readings}
            self.by_frame.setdefault(k, []).append(((float(pos.x), float(pos.y)), heard))
        self._dist: dict[tuple[int, tuple[float, float]], np.ndarray] = {}

    def __bool__(self) -> bool:
        return bool(self.by_frame)

    def away(self, mid: str, base: float) -> np.ndarray:
        """The cost of each frame out of view: ``base`` plus ``away_heard_cost`` per AP that
        heard the phone."""
        out = np.full(self.n, base, np.float32)
        for k, seen in self.by_frame.items():
            out[k] += self.cfg.away_heard_cost * sum(mid in heard for _, heard in seen)
        return out

    def emissions(
        self, mid: str, grid: _Grid, base: Sequence[np.ndarray | float]
    ) -> Sequence[np.ndarray | float]:
        """``base`` (each frame's cost per cell) with this phone's scans added (computed when a
        frame is read: one phone's grids are not all held)."""
        return _WithRadio(self, mid, grid, base, np.arange(len(base)))

    def cost(self, mid: str, grid: _Grid, k: int) -> np.ndarray | None:
        """The in-view cost per cell of frame ``k``'s scans of phone ``mid``; None without."""
        seen = self.by_frame.get(k)
        if not seen:
            return None
        cfg = self.cfg
        at1, exponent = self.model
        total = np.zeros(grid.shape, np.float32)
        for ap, heard in seen:
            mu = at1 - 10 * exponent * np.log10(self._distance(grid, ap))
            p = cfg.hear_prob * ndtr((mu - cfg.floor_dbm) / cfg.sigma_db)
            r = heard.get(mid)
            if r is None:
                total += -np.log1p(-p)
                continue
            z = np.abs(r - mu) / cfg.sigma_db
            h = cfg.huber
            total += np.where(z < h, 0.5 * z * z, h * z - 0.5 * h * h) - np.log(p)
        return total

    def _distance(self, grid: _Grid, ap: tuple[float, float]) -> np.ndarray:
        key = (id(grid), ap)
        d = self._dist.get(key)
        if d is None:
            rows, cols = np.indices(grid.shape)
            x = grid.lo[0] + cols * grid.cell - ap[0]
            y = grid.lo[1] + rows * grid.cell - ap[1]
            d = np.maximum(np.hypot(x, y), 0.3).astype(np.float32)
            self._dist[key] = d
        return d


class _WithRadio(Sequence[np.ndarray | float]):
    """Frames' emissions with one phone's radio costs added as they are read."""

    def __init__(
        self,
        radio: RadioEvidence,
        mid: str,
        grid: _Grid,
        base: Sequence[np.ndarray | float],
        order: np.ndarray,
    ) -> None:
        self.radio, self.mid, self.grid, self.base, self.order = radio, mid, grid, base, order

    def __len__(self) -> int:
        return len(self.order)

    @overload
    def __getitem__(self, k: int) -> np.ndarray | float: ...

    @overload
    def __getitem__(self, k: slice) -> _WithRadio: ...

    def __getitem__(self, k: int | slice) -> np.ndarray | float | _WithRadio:
        if isinstance(k, slice):
            return _WithRadio(self.radio, self.mid, self.grid, self.base, self.order[k])
        j = int(self.order[k])
        extra = self.radio.cost(self.mid, self.grid, j)
        return self.base[j] if extra is None else self.base[j] + extra

    def __iter__(self) -> Iterator[np.ndarray | float]:
        return (self[k] for k in range(len(self)))
