"""How a phone's dead-reckoned velocity maps onto the walk a camera sees: carry-agnostic fusion.

A phone's PDR velocity is in the *device's* heading (a phone in a pocket or a bag points
anywhere; the rotation vector's north is not the site's x axis), scaled by a nominal step
length, and stamped by the phone's own clock. With velocities as complex numbers
``z = vx + i vy``, a track's ground velocity at camera time ``t`` is modelled as

    z_track(t) = a * z_phone(t + lag),    a = scale * exp(i * yaw)

with one unknown ``a`` (device-to-walk yaw and step-length scale) and one ``lag`` (the phone's
clock offset) per phone. For a candidate (phone, track) pair, :class:`PairEvidence` keeps, per
lag on a grid, the sums ``S = sum z_track conj(z_phone)``, ``P = sum |z_phone|^2`` and
``T = sum |z_track|^2``; the best ``a`` is then ``S / P`` in closed form (a 2-D Procrustes fit,
scale clipped to plausible step lengths) and the residual ``T - 2|a||S| + |a|^2 P``, so scoring
every lag costs a few multiplications per frame. What identifies a carrier without a known
alignment is therefore what does not depend on it: the speed profile (stops, starts, pace),
turns (a change of heading), and their timing. Once a phone is bound, its alignment is
re-estimated continuously from the track's detections and then used as known.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Alignment", "AlignConfig", "CandidateTable", "PairEvidence", "best_fit", "lag_grid"]


@dataclass(frozen=True, slots=True)
class AlignConfig:
    """Unknowns of a phone and how far to search them."""

    max_clock_offset_s: float = 2.5
    """Phone clocks may be off the cameras' by up to this (unsynchronised phones: +-2 s)."""
    lag_step_s: float = 0.25
    scale: tuple[float, float] = (0.7, 1.3)
    """Step-length scale a fit may use: 0.5-0.9 m steps against the nominal 0.7 m."""
    forget_s: float = 60.0
    """A bound phone's alignment follows changes (magnetic disturbance, heading drift) over this
    time constant; a changed carry breaks the binding and is re-fitted from scratch."""


def best_fit(
    S: np.ndarray, P: np.ndarray, T: np.ndarray, n: np.ndarray, cfg: AlignConfig
) -> tuple[np.ndarray, np.ndarray]:
    """The closed-form fit of evidence sums (any shape, element-wise): the best ``a`` (rotation
    of S, scale |S|/P clipped to ``cfg.scale``) and its mean squared residual
    (T - 2|a||S| + |a|^2 P) / n, clipped at 0. Every free fit in VM-Tracking goes through here."""
    mag = np.abs(S)
    scale = np.clip(mag / np.maximum(P, 1e-9), *cfg.scale)
    r = np.maximum(T - 2 * scale * mag + scale * scale * P, 0.0) / np.maximum(n, 1e-9)
    a = np.where(mag > 0, scale * S / np.maximum(mag, 1e-12), scale + 0j)
    return a, r


def lag_grid(cfg: AlignConfig) -> np.ndarray:
    """Candidate clock offsets, seconds (phone time = camera time + lag)."""
    n = int(round(cfg.max_clock_offset_s / cfg.lag_step_s))
    return np.arange(-n, n + 1) * cfg.lag_step_s


@dataclass(frozen=True, slots=True)
class Alignment:
    """A phone's estimated mapping onto the walk: ``z_track(t) = a z_phone(t + lag_s)``."""

    a: complex
    lag_s: float
    lag_index: int

    @property
    def yaw_deg(self) -> float:
        return math.degrees(math.atan2(self.a.imag, self.a.real))

    @property
    def scale(self) -> float:
        return abs(self.a)

    def apply(self, z_phone: complex) -> np.ndarray:
        z = self.a * z_phone
        return np.array([z.real, z.imag])


class PairEvidence:
    """Sums over frames of one (phone, track) pair, per candidate lag; see the module doc."""

    __slots__ = ("S", "P", "T", "n", "rssi_n", "rssi_z2")

    def __init__(self, n_lags: int) -> None:
        self.S = np.zeros(n_lags, complex)
        self.P = np.zeros(n_lags)
        self.T = np.zeros(n_lags)
        self.n = np.zeros(n_lags)
        self.rssi_n = 0
        self.rssi_z2 = 0.0

    def copy(self) -> PairEvidence:
        out = PairEvidence(len(self.S))
        out.S, out.P, out.T, out.n = self.S.copy(), self.P.copy(), self.T.copy(), self.n.copy()
        out.rssi_n, out.rssi_z2 = self.rssi_n, self.rssi_z2
        return out

    @property
    def frames(self) -> int:
        """Frames of evidence (at the best-covered lag)."""
        return int(self.n.max()) if len(self.n) else 0

    def add(self, z_track: complex, z_phone: np.ndarray, weight: float = 1.0) -> None:
        """One frame: the track's velocity and the phone's at every lag (NaN: no sample)."""
        ok = ~np.isnan(z_phone)
        zp = z_phone[ok]
        self.S[ok] += weight * z_track * np.conj(zp)
        self.P[ok] += weight * np.abs(zp) ** 2
        self.T[ok] += weight * abs(z_track) ** 2
        self.n[ok] += weight

    def decay(self, factor: float) -> None:
        """Forget old evidence (a bound phone's alignment follows slow changes)."""
        self.S *= factor
        self.P *= factor
        self.T *= factor
        self.n *= factor

    def add_rssi(self, z2: float) -> None:
        self.rssi_n += 1
        self.rssi_z2 += z2

    def _residuals(self, cfg: AlignConfig, known: Alignment | None) -> np.ndarray:
        """Mean squared disagreement (m/s)^2 per lag: with ``known``'s ``a`` at its lag, or with
        the best ``a`` of each lag."""
        n = np.maximum(self.n, 1e-9)
        out = np.full(len(self.S), np.inf)
        enough = self.n >= 0.8 * self.n.max() if self.n.max() > 0 else self.n > 0
        if known is not None:
            k = known.lag_index
            a = known.a
            r = self.T[k] - 2 * (np.conj(a) * self.S[k]).real + abs(a) ** 2 * self.P[k]
            out[k] = max(r, 0.0) / n[k]
            return out
        _, r = best_fit(self.S, self.P, self.T, self.n, cfg)
        out[enough] = r[enough]
        return out

    def score(self, cfg: AlignConfig, known: Alignment | None = None) -> float:
        """Mean squared velocity disagreement at the best alignment, (m/s)^2 (inf: none)."""
        return float(self._residuals(cfg, known).min()) if self.n.max() > 0 else math.inf

    def fit(self, cfg: AlignConfig, lags: np.ndarray) -> Alignment | None:
        """The alignment that best explains this pair (None without evidence)."""
        if self.n.max() <= 0:
            return None
        res = self._residuals(cfg, None)
        k = int(np.argmin(res))
        if not math.isfinite(res[k]) or self.P[k] <= 0:
            return None
        a, _ = best_fit(self.S[k], self.P[k], self.T[k], self.n[k], cfg)
        return Alignment(complex(a), float(lags[k]), k)


class CandidateTable:
    """:class:`PairEvidence` of one phone with many tracks, one row per track (vectorised: a
    frame updates every candidate in a few array operations, whatever the crowd)."""

    _FIELDS = ("S", "P", "T", "n", "rssi_n", "rssi_z2")

    def __init__(self, n_lags: int) -> None:
        self.n_lags = n_lags
        self.vids: list[str] = []
        self.index: dict[str, int] = {}
        self.S = np.zeros((0, n_lags), complex)
        self.P = np.zeros((0, n_lags))
        self.T = np.zeros((0, n_lags))
        self.n = np.zeros((0, n_lags))
        self.rssi_n = np.zeros(0)
        self.rssi_z2 = np.zeros(0)
        # the arrays are views of the first rows of these (room to grow without copying)
        self._base = {name: getattr(self, name) for name in self._FIELDS}
        self._cap = 0

    def __len__(self) -> int:
        return len(self.vids)

    def _rows(self, vids: list[str]) -> np.ndarray:
        new = [v for v in dict.fromkeys(vids) if v not in self.index]
        if new:
            for v in new:
                self.index[v] = len(self.vids)
                self.vids.append(v)
            m = len(self.vids)
            if m > self._cap:
                cap = max(2 * self._cap, m, 16)
                for name in self._FIELDS:
                    old = getattr(self, name)
                    base = np.zeros((cap, *old.shape[1:]), old.dtype)
                    base[: len(old)] = old
                    self._base[name] = base
                self._cap = cap
            for name in self._FIELDS:
                setattr(self, name, self._base[name][:m])
        return np.array([self.index[v] for v in vids], int)

    def add(self, vids: list[str], z_tracks: np.ndarray, z_phone: np.ndarray) -> None:
        """One frame: each track's velocity (complex) against the phone's at every lag."""
        if not vids:
            return
        # every row, in order (the usual frame): whole arrays instead of gather and scatter
        sel: slice | np.ndarray = slice(None) if vids == self.vids else self._rows(vids)
        ok = ~np.isnan(z_phone)
        zp = np.where(ok, z_phone, 0)
        z = np.asarray(z_tracks, complex)[:, None]
        self.S[sel] += z * np.conj(zp)[None, :]
        self.P[sel] += (np.abs(zp) ** 2)[None, :]
        self.T[sel] += np.abs(z) ** 2 * ok[None, :]
        self.n[sel] += ok[None, :]

    def add_rssi(self, vids: list[str], z2: np.ndarray) -> None:
        """One RSSI reading's squared standardized residual for each of the (distinct) tracks."""
        rows = self._rows(vids)
        self.rssi_n[rows] += 1
        self.rssi_z2[rows] += z2

    def keep(self, live: set[str]) -> None:
        """Drop the rows of tracks that are gone."""
        if self.index.keys() <= live:
            return
        rows = [i for i, v in enumerate(self.vids) if v in live]
        self.vids = [self.vids[i] for i in rows]
        self.index = {v: i for i, v in enumerate(self.vids)}
        self.S, self.P, self.T, self.n = self.S[rows], self.P[rows], self.T[rows], self.n[rows]
        self.rssi_n, self.rssi_z2 = self.rssi_n[rows], self.rssi_z2[rows]
        self._base = {name: getattr(self, name) for name in self._FIELDS}
        self._cap = len(rows)

    def frames(self) -> np.ndarray:
        return self.n.max(axis=1) if len(self.vids) else np.zeros(0)

    def scores(self, cfg: AlignConfig, known: Alignment | None = None) -> np.ndarray:
        """Mean squared disagreement of every row at its best alignment (or at ``known``), as
        :meth:`PairEvidence.score`, plus nothing for RSSI (see :meth:`rssi_penalty`)."""
        if not len(self.vids):
            return np.zeros(0)
        n = np.maximum(self.n, 1e-9)
        if known is not None:
            k, a = known.lag_index, known.a
            r = self.T[:, k] - 2 * (np.conj(a) * self.S[:, k]).real + abs(a) ** 2 * self.P[:, k]
            out = np.maximum(r, 0.0) / n[:, k]
            return np.where(self.n.max(axis=1) > 0, out, np.inf)
        _, r = best_fit(self.S, self.P, self.T, self.n, cfg)
        top = self.n.max(axis=1, keepdims=True)
        enough = (self.n >= 0.8 * top) & (self.n > 0)
        return np.where(enough, r, np.inf).min(axis=1)

    def rssi_penalty(self, weight: float) -> np.ndarray:
        """Chi-square excess of each row's RSSI residuals (0 with fewer than 2 readings)."""
        excess = np.maximum(0.0, self.rssi_z2 / np.maximum(self.rssi_n, 1) - 1.0)
        return np.where(self.rssi_n >= 2, weight * excess, 0.0)

    def evidence(self, vid: str) -> PairEvidence:
        """One row as a :class:`PairEvidence` (to fit or to keep)."""
        i = self.index[vid]
        ev = PairEvidence(self.n_lags)
        ev.S, ev.P = self.S[i].copy(), self.P[i].copy()
        ev.T, ev.n = self.T[i].copy(), self.n[i].copy()
        ev.rssi_n, ev.rssi_z2 = int(self.rssi_n[i]), float(self.rssi_z2[i])
        return ev
