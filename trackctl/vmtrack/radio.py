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

with ``p_hear(d) = hear_prob * Phi((mu(d) - floor_dbm) / sigma_db)``.

**Each AP's calibration is fitted from the log** (:func:`fit_path_loss`). A site's APs differ
from any default model: antenna gain, height, walls and furniture move the level at 1 m by
5-10 dB and the exponent between 1.8 and 4 indoors (Rappaport, *Wireless Communications*,
table 4.2; :class:`~trackctl.sim.vm.VmRealism` draws -47..-33 dBm and 2.0-3.5). A 7 dB error at
10 m pulls a path 5 m off in a closed room where every phone is always heard. Where the
offline identity placed a carrier, the readings of its phone against its distance to each AP
give that AP's level at 1 m and exponent (a robust regression with the check-points' model as
the prior, so an AP heard little keeps about the default), and the spread of the residuals
replaces ``sigma_db`` (shrunk towards it by the readings' number).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np
from scipy.special import ndtr

from trackctl.logs.messages import RssiScan
from trackctl.vmtrack.grid import SiteGrid

__all__ = ["PathLoss", "RadioConfig", "RadioEvidence", "fit_path_loss"]


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
    fit: bool = True
    """Fit each AP's path loss from the log (:func:`fit_path_loss`); off, every AP has the
    check-points' model and ``sigma_db``."""
    fit_prior_db: float = 8.0
    """Prior std of an AP's level at 1 m about the check-points' model."""
    fit_prior_exponent: float = 0.7
    """Prior std of an AP's exponent about the check-points' model."""
    fit_prior_readings: float = 30.0
    """A fitted AP's ``sigma_db`` is its residuals' spread shrunk towards ``sigma_db`` as if
    from this many readings."""
    fit_min_db: float = 3.0
    """The fitted ``sigma_db`` is kept at least this (the paper's shadowing): the placed
    positions fit their own readings."""
    fit_gap_s: float = 0.3
    """A reading counts for the fit when its carrier was placed within this time of it."""


@dataclass(frozen=True, slots=True)
class PathLoss:
    """One AP's log-distance path loss: ``at1_dbm - 10 exponent log10(d)``, spread ``sigma_db``."""

    at1_dbm: float
    exponent: float
    sigma_db: float
    readings: int = 0
    """Readings it was fitted from (0: the default)."""

    def mean(self, d: np.ndarray) -> np.ndarray:
        """Expected level (dBm) at distances ``d`` (m)."""
        return self.at1_dbm - 10 * self.exponent * np.log10(d)


def fit_path_loss(
    scans: Sequence[RssiScan],
    placed: Mapping[str, tuple[np.ndarray, np.ndarray]],
    prior: tuple[float, float],
    cfg: RadioConfig,
) -> dict[str, PathLoss]:
    """Each AP's path loss, fitted from the readings of phones whose carrier was placed.

    Args:
        scans: The log's scans (those without an AP position are left out).
        placed: MID -> (times ns, sorted; positions (n, 2), m) where its carrier was placed.
        prior: The check-points' model (RSSI at 1 m, exponent), the fit's prior mean.
        cfg: The prior's spread and the fit's limits.

    Returns:
        AP id -> its model; every AP with a position has one (the prior's when nothing was
        heard from a placed carrier).

    A maximum a-posteriori fit, robust: Huber-weighted least squares (iteratively reweighted,
    the weights from a MAD scale), Gaussian priors on both parameters. Readings whose expected
    level is within ``2 sigma_db`` of ``floor_dbm`` are left out: only the loud ones of those
    would be heard (censored), biasing the fit upwards.
    """
    rows: dict[str, list[tuple[float, float]]] = {}
    pos: dict[str, tuple[float, float]] = {}
    for scan in scans:
        p = scan.observer_position_m
        if p is None:
            continue
        pos[scan.observer] = (float(p.x), float(p.y))
        for r in scan.readings:
            got = placed.get(r.eid)
            if got is None or not len(got[0]):
                continue
            times, xy = got
            k = int(np.searchsorted(times, scan.t_ns))
            best = min(
                (j for j in (k - 1, k) if 0 <= j < len(times)),
                key=lambda j: abs(int(times[j]) - scan.t_ns),
            )
            if abs(int(times[best]) - scan.t_ns) > cfg.fit_gap_s * 1e9:
                continue
            d = max(0.3, math.hypot(xy[best, 0] - p.x, xy[best, 1] - p.y))
            rows.setdefault(scan.observer, []).append((-10 * math.log10(d), float(r.rssi_dbm)))
    out: dict[str, PathLoss] = {}
    for ap in pos:
        data = np.array(rows.get(ap, []), float).reshape(-1, 2)
        out[ap] = _fit_one(data, prior, cfg)
    return out


def _fit_one(data: np.ndarray, prior: tuple[float, float], cfg: RadioConfig) -> PathLoss:
    """One AP's MAP fit of ``r = at1 + exponent * x`` (``x = -10 log10 d``); see
    :func:`fit_path_loss`. A 2-parameter IRLS: written out, not worth a dependency."""
    theta0 = np.array(prior, float)
    keep = theta0[0] + theta0[1] * data[:, 0] > cfg.floor_dbm + 2 * cfg.sigma_db
    data = data[keep]
    if not len(data):
        return PathLoss(prior[0], prior[1], cfg.sigma_db)
    design = np.column_stack([np.ones(len(data)), data[:, 0]])
    prec0 = np.diag([cfg.fit_prior_db**-2, cfg.fit_prior_exponent**-2])
    theta, scale = theta0, cfg.sigma_db
    w = np.ones(len(data))
    for _ in range(30):
        # weights are per reading; the prior is in units of the current scale
        a = design.T @ (design * w[:, None]) / scale**2 + prec0
        b = design.T @ (data[:, 1] * w) / scale**2 + prec0 @ theta0
        new = np.linalg.solve(a, b)
        res = data[:, 1] - design @ new
        scale = max(1.4826 * float(np.median(np.abs(res - np.median(res)))), 1.0)
        z = np.abs(res) / scale
        w = np.where(z <= cfg.huber, 1.0, cfg.huber / np.maximum(z, 1e-9))
        done = bool(np.allclose(new, theta, atol=1e-4))
        theta = new
        if done:
            break
    n0, n = cfg.fit_prior_readings, len(data)
    sigma = math.sqrt((n * scale**2 + n0 * cfg.sigma_db**2) / (n + n0))
    return PathLoss(float(theta[0]), float(theta[1]), max(sigma, cfg.fit_min_db), n)


class RadioEvidence:
    """A log's RSSI scans, ready to weigh the paths of each phone.

    Args:
        frame_t: The frames' times, ns (a scan counts at its nearest frame).
        scans: The log's scans; those without an AP position are left out.
        model: The APs' path loss: RSSI at 1 m (dBm) and exponent for all, with ``sigma_db``;
            or one :class:`PathLoss` per AP id (:func:`fit_path_loss`; an AP left out has the
            first form's default, the check-points' model).
        cfg: Its weights.
    """

    def __init__(
        self,
        frame_t: np.ndarray,
        scans: Sequence[RssiScan],
        model: tuple[float, float] | Mapping[str, PathLoss],
        cfg: RadioConfig,
    ) -> None:
        self.cfg = cfg
        self._frame_t, self._scans = frame_t, scans
        default = PathLoss(-40.0, 2.5, cfg.sigma_db)
        if isinstance(model, tuple):
            default, model = PathLoss(model[0], model[1], cfg.sigma_db), {}
        self.default = default
        self.model: dict[str, PathLoss] = dict(model)
        self.n = len(frame_t)
        self.by_frame: dict[int, list[tuple[PathLoss, tuple[float, float], dict[str, float]]]] = {}
        self._dist: dict[tuple[int, tuple[float, float]], np.ndarray] = {}
        self._fields: dict[
            tuple[int, tuple[float, float], PathLoss], tuple[np.ndarray, np.ndarray, np.ndarray]
        ] = {}
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
            ap = self.model.get(scan.observer, default)
            self.by_frame.setdefault(k, []).append((ap, (float(pos.x), float(pos.y)), heard))

    def __bool__(self) -> bool:
        return bool(self.by_frame)

    def calibrated(self, placed: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> RadioEvidence:
        """The same scans under each AP's path loss fitted where the carriers were ``placed``
        (:func:`fit_path_loss`, with this evidence's default model as the prior)."""
        prior = (self.default.at1_dbm, self.default.exponent)
        fitted = fit_path_loss(self._scans, placed, prior, self.cfg)
        return RadioEvidence(self._frame_t, self._scans, fitted, self.cfg)

    def away(self, mid: str, base: float) -> np.ndarray:
        """The cost of each frame out of view: ``base`` plus ``away_heard_cost`` per AP that
        heard the phone."""
        out = np.full(self.n, base, np.float32)
        for k, seen in self.by_frame.items():
            out[k] += self.cfg.away_heard_cost * sum(mid in heard for _, _, heard in seen)
        return out

    def emissions(
        self, mid: str, grid: SiteGrid, base: Sequence[np.ndarray | float], every: int = 1
    ) -> Sequence[np.ndarray | float]:
        """``base`` (each frame's cost per cell; of every ``every``-th frame) with this phone's
        scans added (computed when a frame is read: one phone's grids are not all held)."""
        return _WithRadio(self, mid, grid, base, np.arange(len(base)), every)

    def cost(self, mid: str, grid: SiteGrid, k: int) -> np.ndarray | None:
        """The in-view cost per cell of frame ``k``'s scans of phone ``mid``; None without."""
        seen = self.by_frame.get(k)
        if not seen:
            return None
        total = np.zeros(grid.shape, np.float32)
        for model, ap, heard in seen:
            mu, unheard, log_p = self._field(grid, model, ap)
            r = heard.get(mid)
            total += unheard if r is None else _heard_cost(model, mu, log_p, r, self.cfg)
        return total

    def gain(self, mid: str, path: np.ndarray) -> np.ndarray:
        """Per frame, how much better phone ``mid``'s scans fit its carrier at ``path`` ((n, 2)
        positions; NaN: out of view, no gain) than out of view: the away state's cost of the
        frame's scans (:meth:`away`) less their in-view cost there (:meth:`cost`). A
        log-likelihood ratio, 0 at frames without scans."""
        out = np.zeros(self.n)
        for k, seen in self.by_frame.items():
            if k >= len(path) or np.isnan(path[k]).any():
                continue
            for model, ap, heard in seen:
                d = np.maximum(np.hypot(path[k, 0] - ap[0], path[k, 1] - ap[1]), 0.3)
                r = heard.get(mid)
                away = 0.0 if r is None else self.cfg.away_heard_cost
                out[k] += away - float(_scan_cost(model, np.array(d), r, self.cfg))
        return out

    def _field(
        self, grid: SiteGrid, model: PathLoss, ap: tuple[float, float]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One AP's expected level on ``grid`` (dBm), the cost of not hearing a phone there and
        the log of the chance to hear it: what :func:`_scan_cost` computes for every scan,
        the same for all of the AP's scans (computed once: it was a fifth of the
        re-tracking's time)."""
        key = (id(grid), ap, model)
        got = self._fields.get(key)
        if got is None:
            mu = model.mean(self._distance(grid, ap))
            p = _hear_prob(model, mu, self.cfg)
            got = self._fields[key] = (mu, -np.log1p(-p), np.log(p))
        return got

    def _distance(self, grid: SiteGrid, ap: tuple[float, float]) -> np.ndarray:
        key = (id(grid), ap)
        d = self._dist.get(key)
        if d is None:
            rows, cols = np.indices(grid.shape)
            x = grid.lo[0] + cols * grid.cell - ap[0]
            y = grid.lo[1] + rows * grid.cell - ap[1]
            d = np.maximum(np.hypot(x, y), 0.3).astype(np.float32)
            self._dist[key] = d
        return d


def _scan_cost(model: PathLoss, d: np.ndarray, r: float | None, cfg: RadioConfig) -> np.ndarray:
    """The in-view cost of one AP's scan at distances ``d`` from it: heard at ``r`` dBm, or
    not heard (None)."""
    mu = model.mean(d)
    p = _hear_prob(model, mu, cfg)
    if r is None:
        return np.asarray(-np.log1p(-p))
    return _heard_cost(model, mu, np.log(p), r, cfg)


def _hear_prob(model: PathLoss, mu: np.ndarray, cfg: RadioConfig) -> np.ndarray:
    """The chance that a phone where ``model`` expects ``mu`` dBm is heard."""
    return np.asarray(cfg.hear_prob * ndtr((mu - cfg.floor_dbm) / model.sigma_db))


def _heard_cost(
    model: PathLoss, mu: np.ndarray, log_p: np.ndarray, r: float, cfg: RadioConfig
) -> np.ndarray:
    """The cost of hearing a phone at ``r`` dBm where ``model`` expects ``mu`` (Huber), with
    ``log_p`` the log of the chance to hear it there."""
    z = np.abs(r - mu) / model.sigma_db
    h = cfg.huber
    return np.asarray(np.where(z < h, 0.5 * z * z, h * z - 0.5 * h * h) - log_p)


class _WithRadio(Sequence[np.ndarray | float]):
    """Frames' emissions with one phone's radio costs added as they are read (``base[j]`` is
    the emission of frame ``j * every``)."""

    def __init__(
        self,
        radio: RadioEvidence,
        mid: str,
        grid: SiteGrid,
        base: Sequence[np.ndarray | float],
        order: np.ndarray,
        every: int = 1,
    ) -> None:
        self.radio, self.mid, self.grid, self.base, self.order = radio, mid, grid, base, order
        self.every = every

    def __len__(self) -> int:
        return len(self.order)

    @overload
    def __getitem__(self, k: int) -> np.ndarray | float: ...

    @overload
    def __getitem__(self, k: slice) -> _WithRadio: ...

    def __getitem__(self, k: int | slice) -> np.ndarray | float | _WithRadio:
        if isinstance(k, slice):
            return _WithRadio(self.radio, self.mid, self.grid, self.base, self.order[k], self.every)
        j = int(self.order[k])
        extra = self.radio.cost(self.mid, self.grid, j * self.every)
        return self.base[j] if extra is None else self.base[j] + extra

    def __iter__(self) -> Iterator[np.ndarray | float]:
        return (self[k] for k in range(len(self)))
