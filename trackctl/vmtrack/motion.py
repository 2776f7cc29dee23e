"""Walking velocity of a phone carrier from its IMU (pedestrian dead reckoning).

Heading comes from the phone's orientation (the rotation vector; integrated gyro when absent):
the horizontal direction of the device axis that lies most level over the last seconds, so a
phone upright in a pocket has a heading as well as one held flat. That heading is the
*device's*, not the walk's: how far the two differ (the carry, the site frame's rotation from
magnetic north) and the phone's clock offset are estimated by the identity stage
(:mod:`~trackctl.vmtrack.align`), never assumed. Speed comes from the step cadence found in the
vertical specific force (least-squares periodogram over a centred window, since we run offline,
evaluated every ``hop_s``) times a nominal step length (the per-person scale is estimated with
the heading offset). Cadences from a slow walk to a jog (0.6-3.5 Hz) are searched, up to just
below the phone's Nyquist frequency: at the paper's 5 Hz IMU rate a walker's 1.4-2.2 Hz stays
below it, a jogger's 3 Hz does not and is read as its alias. "Vertical" is along the
orientation's world z; a phone without one projects on its own mean specific force (gravity),
not the norm, whose forward and sideways swings peak at twice the step rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from trackctl.logs.messages import Imu

__all__ = ["MotionConfig", "PhoneMotion"]

G = 9.80665


@dataclass(frozen=True, slots=True)
class MotionConfig:
    """PDR parameters."""

    step_length_m: float = 0.7
    window_s: float = 3.0
    min_bounce_mps2: float = 0.35
    cadence_hz: tuple[float, float] = (0.6, 3.5)
    """Step rates searched: slow walking to jogging. The top is held below the phone's Nyquist
    frequency (0.49 x its sample rate: 2.45 Hz at the paper's 5 Hz), where a faster cadence
    cannot be told from its alias."""
    gravity_window_s: float = 2.0
    """Without an orientation, "up" is the specific force averaged over this centred window."""
    still_window_s: float = 1.2
    """Short centred window in which a phone whose vertical force barely varies is standing."""
    still_std_mps2: float = 0.3
    hop_s: float = 0.2
    """The cadence is evaluated every ``hop_s`` and interpolated (fast at 50-200 Hz)."""
    axis_window_s: float = 4.0
    """The heading's device axis is the one most level over this centred window."""
    attitude_change_deg: float = 30.0
    """The phone was moved to another carry (taken out of a pocket, put in a bag) where its
    "up" direction, in the device's own frame, turns by more than this between the
    ``attitude_window_s`` before and after: its heading offset from the walk is new there."""
    attitude_window_s: float = 2.0
    flip_deg: float = 80.0
    """The phone was turned in its carry (put back in a pocket the other way round, or
    turned a quarter) where its heading turns by more than this within ``flip_window_s``
    (270 deg/s held over the window) while it walks on: faster than a walker turns (an
    about-turn while walking takes a second or more, a sharp corner half a second: 180
    deg/s), above the sway of a pocket's heading with each step (up to 30 deg from one 5 Hz
    sample to the next), and unseen by ``attitude_change_deg`` when the phone goes back in
    the same attitude (a yaw the alignment fitted before it is wrong after it: PETS footage
    with phones, `n` seed 2, a front-pocket phone turned by 138 deg and 161 deg, lost its
    carrier for 51 s; seed 57, a phone moved from a back to a front pocket turned by 92 deg,
    unseen at 120 deg, and its carrier was unnamed for 23 s). Over the 300 phones of the 60
    `n` logs, 120 deg found 57 of the 87 carry changes, 80 deg 61, and neither a change that
    was not there. Of the 26 still missed, 16 turn the phone by less than 45 deg and 4 by
    45-85 deg; of the six larger, two turn it while the carrier turns too (seeds 12 and 26)
    and one while he stands (seed 50)."""
    flip_window_s: float = 0.3
    flip_walk_s: float = 1.0
    """A flip counts only where the phone walks for this long before and after it."""
    flip_dv_share: float = 1 / 3
    """...and where the body's velocity changed over that time by less than this share of
    what the turn needs of a walk (:meth:`PhoneMotion._flips`): the PDR's speed may be half
    off (an unknown step, a 3 s cadence window), and the walk's own turns within the window
    add some (PETS footage with phones: phones turned in their pockets 0.10-0.29 of it, paths
    that reverse 0.9-1.3, a simulated walker's corner 0.43)."""


class PhoneMotion:
    """Velocity estimates of one phone over the whole log (offline: arrays, 3 floats/sample)."""

    def __init__(self, mid: str, config: MotionConfig | None = None) -> None:
        self.mid = mid
        self.config = config or MotionConfig()
        self._t: list[int] = []
        self._vert: list[float] = []
        self._quat: list[tuple[float, float, float, float]] = []
        self._acc: list[tuple[float, float, float]] = []
        self._gyro_z: list[float] = []
        self.bad_samples = 0
        self.t_ns = np.empty(0, np.int64)
        self.v = np.empty((0, 2))
        self.heading = np.empty(0)
        self.speed = np.empty(0)
        self.carry_changes = np.empty(0, np.int64)
        """Phone-clock times (ns) at which the phone changed carry (its device attitude or its
        heading axis changed): the device-to-walk yaw before and after are unrelated."""

    def add(self, imu: Imu) -> None:
        """Add one sample (non-finite samples are skipped and counted)."""
        vals = list(imu.finite_values().values())
        if not all(math.isfinite(v) for v in vals):
            self.bad_samples += 1
            return
        if self._t and imu.t_ns <= self._t[-1]:
            self.bad_samples += 1
            return
        self._t.append(imu.t_ns)
        a = imu.accel_mps2
        self._acc.append((a.x, a.y, a.z))
        q = imu.orientation
        self._quat.append((math.nan,) * 4 if q is None else (q.x, q.y, q.z, q.w))
        # no gyro and no orientation: the heading cannot be integrated (held constant)
        self._gyro_z.append(0.0 if imu.gyro_rps is None else imu.gyro_rps.z)

    def finish(self) -> None:
        """Compute the velocity series once every sample is in."""
        if not self._t:
            return
        t = np.asarray(self._t, np.int64)
        ts = (t - t[0]) / 1e9
        acc = np.asarray(self._acc, float)
        quat = np.asarray(self._quat, float)
        known = np.isfinite(quat).all(axis=1)
        rate = _rate(ts)
        # the projection on the mean specific force only where some sample has no orientation
        vert = np.empty(len(t)) if known.all() else self._vertical_without_orientation(acc, rate)
        heading = np.full(len(t), math.nan)
        # "up" in the device frame: the orientation's world z, else the mean specific force
        up = acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-9)
        axis = np.zeros(len(t), int)
        # the horizontal specific force in the world frame (the body's acceleration)
        level = np.full((len(t), 2), np.nan)
        if known.any():
            rot = Rotation.from_quat(quat[known]).as_matrix()  # device -> world, (n, 3, 3)
            vert[known] = np.einsum("nj,nj->n", rot[:, 2, :], acc[known]) - G
            level[known] = np.einsum("nij,nj->ni", rot[:, :2, :], acc[known])
            heading[known], axis[known] = self._axis_heading(ts[known], rot)
            up[known] = rot[:, 2, :]
        speed = self._speeds(ts, vert, rate)
        # a heading only while walking on for a second each side: one that stops or starts
        # turns where its walk does (a path reversed on the spot)
        n = max(1, int(round(2 * self.config.flip_walk_s * rate))) | 1
        walking = pd.Series(speed > 0).rolling(n, center=True, min_periods=1).min().to_numpy()
        flips = self._flips(ts, np.where(walking > 0, heading, np.nan), speed, level)
        self.carry_changes = t[self._carry_changes(ts, up, axis, flips)]
        if np.isnan(heading).any():
            gz = np.asarray(self._gyro_z)
            integrated = np.concatenate(([0.0], np.cumsum(np.diff(ts) * gz[1:])))
            heading = np.where(np.isnan(heading), integrated, heading)
        self.t_ns = t
        self.heading = heading
        self.speed = speed
        self.v = np.column_stack([speed * np.cos(heading), speed * np.sin(heading)])
        self._t, self._acc, self._quat, self._gyro_z = [], [], [], []

    def _carry_changes(
        self, ts: np.ndarray, up: np.ndarray, axis: np.ndarray, flips: np.ndarray
    ) -> np.ndarray:
        """Sample indices where the phone changed carry: its heading axis changed, its
        device-frame "up" (``up``, (n, 3) unit vectors) turned by more than
        ``attitude_change_deg`` between the windows before and after, or it was turned in
        its carry (``flips``, per sample: :meth:`_flips`); one index per change."""
        cfg = self.config
        if len(ts) < 3:
            return np.empty(0, int)
        half = cfg.attitude_window_s
        cum = np.vstack([np.zeros(3), np.cumsum(up, axis=0)])
        lo = np.searchsorted(ts, ts - half, side="left")
        hi = np.searchsorted(ts, ts + half, side="right")
        mid = np.arange(len(ts))
        before = cum[mid + 1] - cum[lo]
        after = cum[hi] - cum[mid]
        nb = np.linalg.norm(before, axis=1) * np.linalg.norm(after, axis=1)
        cos = np.einsum("ij,ij->i", before, after) / np.maximum(nb, 1e-12)
        moved = cos < math.cos(math.radians(cfg.attitude_change_deg))
        # a window cut short by the log's start or end compares a few samples: no evidence
        moved &= (ts >= ts[0] + half) & (ts <= ts[-1] - half)
        moved[1:] |= axis[1:] != axis[:-1]
        moved |= flips
        # one change per run of flagged samples: its middle
        edges = np.flatnonzero(np.diff(np.r_[0, moved.astype(np.int8), 0]))
        return ((edges[0::2] + edges[1::2] - 1) // 2).astype(int)

    def _flips(
        self, ts: np.ndarray, heading: np.ndarray, speed: np.ndarray, level: np.ndarray
    ) -> np.ndarray:
        """Samples where the phone was turned in its carry: its heading (NaN where unknown or
        standing: a standing phone's heading says nothing of a walk) is more than
        ``flip_deg`` from that of the first sample within ``flip_window_s`` before (the sample
        before, at least), and the body did not turn with it. A walker who turns by theta at
        speed v changes velocity by 2 v sin(theta / 2), which the accelerometer feels (the
        horizontal specific force ``level``, world frame, integrated over ``flip_walk_s``
        either side): a turn that changes it by much less (``flip_dv_share``) is the phone's,
        not the walk's (a simulated path that reverses in a fraction of a second turns as fast)."""
        cfg = self.config
        k = np.arange(len(ts))
        lo = np.maximum(np.minimum(np.searchsorted(ts, ts - cfg.flip_window_s), k - 1), 0)
        turn = np.abs(np.angle(np.exp(1j * (heading - heading[lo]))))
        close = ts - ts[lo] <= cfg.flip_window_s + 1e-6
        out = (np.nan_to_num(turn, nan=0.0) > math.radians(cfg.flip_deg)) & close
        if not out.any():
            return out
        a = np.nan_to_num(level[:, 0] + 1j * level[:, 1])
        v = np.r_[0, np.cumsum(np.diff(ts) * (a[1:] + a[:-1]) / 2)]  # velocity change so far
        w = cfg.flip_walk_s
        ks = np.flatnonzero(out)
        dv = np.interp(ts[ks] + w, ts, v.real) - np.interp(ts[ks] - w, ts, v.real)
        dv = dv + 1j * (np.interp(ts[ks] + w, ts, v.imag) - np.interp(ts[ks] - w, ts, v.imag))
        need = 2 * speed[ks] * np.sin(turn[ks] / 2)
        out[ks] = np.abs(dv) < cfg.flip_dv_share * need
        return out

    def _axis_heading(self, ts: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Heading (rad) of the device axis that lies most level over a centred window: the
        x or y axis of a phone held flat, the z axis (out of the screen) of one upright in a
        pocket; and that axis per sample. A change of axis (the phone was moved) is a jump the
        identity stage re-fits."""
        rate = (len(ts) - 1) / max(ts[-1] - ts[0], 1e-9) if len(ts) > 1 else 1.0
        n = max(1, int(round(self.config.axis_window_s * rate)))
        tilt = (
            pd.DataFrame(np.abs(rot[:, 2, :])).rolling(n, center=True, min_periods=1).mean()
        ).to_numpy()
        # hysteresis: keep the axis until another is clearly more level (a flat phone's x and y
        # are both level; flipping between them would turn the heading by 90 deg)
        axis = np.empty(len(ts), int)
        cur = int(np.argmin(tilt[0]))
        for k in range(len(ts)):
            if tilt[k, cur] > tilt[k].min() + 0.25:
                cur = int(np.argmin(tilt[k]))
            axis[k] = cur
        rows = np.arange(len(ts))
        return np.arctan2(rot[rows, 1, axis], rot[rows, 0, axis]), axis

    def _vertical_without_orientation(self, acc: np.ndarray, rate: float) -> np.ndarray:
        """Specific force along "up" (minus g), up being its own centred mean direction: the
        norm would add the walk's forward and sideways swings, whose second harmonic outgrows
        the step in a back pocket (a quarter of the Oxford back-pocket walk's 3 s windows peak
        there on the norm, 1 % on this projection)."""
        n = max(1, int(round(self.config.gravity_window_s * rate)))
        mean = pd.DataFrame(acc).rolling(n, center=True, min_periods=1).mean().to_numpy()
        up = mean / np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-9)
        return np.einsum("nj,nj->n", up, acc) - G

    def _speeds(self, ts: np.ndarray, vert: np.ndarray, rate: float) -> np.ndarray:
        cfg = self.config
        freqs = np.arange(cfg.cadence_hz[0], min(cfg.cadence_hz[1], 0.49 * rate), 0.05)
        half = cfg.window_s / 2
        grid = np.arange(ts[0], ts[-1] + cfg.hop_s, cfg.hop_s)
        lo_idx = np.searchsorted(ts, grid - half, side="left")
        hi_idx = np.searchsorted(ts, grid + half, side="right")
        on_grid = np.zeros(len(grid))
        for k in range(len(grid)):
            lo, hi = lo_idx[k], hi_idx[k]
            if hi - lo < 6:
                continue
            w_t, w_v = ts[lo:hi], vert[lo:hi] - vert[lo:hi].mean()
            # least-squares sinusoid amplitude per candidate frequency (Lomb-Scargle-like)
            ph = 2 * np.pi * freqs[:, None] * w_t[None, :]
            c, s = np.cos(ph), np.sin(ph)
            amp = 2 * np.sqrt((c @ w_v) ** 2 + (s @ w_v) ** 2) / len(w_t)
            best = int(np.argmax(amp))
            if amp[best] >= cfg.min_bounce_mps2:
                on_grid[k] = freqs[best] * cfg.step_length_m
        out = np.interp(ts, grid, on_grid)
        # the cadence window (3 s) smears short stops; a quiet short window means standing still
        if len(ts) > 2:
            n = max(3, int(round(cfg.still_window_s * rate)))
            local = pd.Series(vert).rolling(n, center=True, min_periods=3).std().to_numpy()
            out[np.nan_to_num(local, nan=np.inf) < cfg.still_std_mps2] = 0.0
        return out

    def velocity_at(self, t_ns: int) -> np.ndarray | None:
        """Velocity (m/s, world x/y) at ``t_ns``, or None outside the phone's samples."""
        if (
            len(self.t_ns) == 0
            or t_ns < self.t_ns[0] - 500_000_000
            or (t_ns > self.t_ns[-1] + 500_000_000)
        ):
            return None
        vx = np.interp(t_ns, self.t_ns, self.v[:, 0])
        vy = np.interp(t_ns, self.t_ns, self.v[:, 1])
        return np.array([vx, vy])

    def velocities_at(self, t_ns: np.ndarray) -> np.ndarray:
        """Velocities (n, 2) at many times; NaN rows outside the phone's samples (+-0.5 s)."""
        t_ns = np.asarray(t_ns, np.int64)
        out = np.full((len(t_ns), 2), np.nan)
        if len(self.t_ns) == 0:
            return out
        ok = (t_ns >= self.t_ns[0] - 500_000_000) & (t_ns <= self.t_ns[-1] + 500_000_000)
        x = (t_ns[ok] - self.t_ns[0]).astype(float)
        xp = (self.t_ns - self.t_ns[0]).astype(float)
        out[ok, 0] = np.interp(x, xp, self.v[:, 0])
        out[ok, 1] = np.interp(x, xp, self.v[:, 1])
        return out


def _rate(ts: np.ndarray) -> float:
    """Sample rate (Hz) of sorted stamps (s): the median spacing's, so dropouts do not lower it."""
    if len(ts) < 2:
        return 1.0
    return float(1.0 / max(np.median(np.diff(ts)), 1e-9))
