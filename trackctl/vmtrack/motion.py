"""Walking velocity of a phone carrier from its IMU (pedestrian dead reckoning).

Heading comes from the phone's orientation (rotation vector yaw; integrated gyro when absent);
speed from the step cadence found in the vertical specific force (least-squares periodogram over
a centred window, since we run offline) times a step length. At the paper's 5 Hz IMU rate the
cadence (1.4-2.2 Hz) stays below Nyquist.
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
    cadence_hz: tuple[float, float] = (0.6, 2.45)
    still_window_s: float = 1.2
    """Short centred window in which a phone whose vertical force barely varies is standing."""
    still_std_mps2: float = 0.3


class PhoneMotion:
    """Velocity estimates of one phone over the whole log (offline: arrays, 3 floats/sample)."""

    def __init__(self, mid: str, config: MotionConfig | None = None) -> None:
        self.mid = mid
        self.config = config or MotionConfig()
        self._t: list[int] = []
        self._vert: list[float] = []
        self._yaw: list[float] = []
        self._gyro_z: list[float] = []
        self.bad_samples = 0
        self.t_ns = np.empty(0, np.int64)
        self.v = np.empty((0, 2))

    def add(self, imu: Imu) -> None:
        """Add one sample (non-finite samples are skipped and counted)."""
        vals = list(imu.finite_values().values())
        if not all(math.isfinite(v) for v in vals):
            self.bad_samples += 1
            return
        if self._t and imu.t_ns <= self._t[-1]:
            self.bad_samples += 1
            return
        f = np.array(imu.accel_mps2)
        if imu.orientation is not None:
            q = imu.orientation
            rot = Rotation.from_quat([q.x, q.y, q.z, q.w])
            yaw = float(rot.as_euler("ZYX")[0])
            vert = float(rot.apply(f)[2]) - G
        else:
            yaw = math.nan
            vert = float(np.linalg.norm(f)) - G
        self._t.append(imu.t_ns)
        self._vert.append(vert)
        self._yaw.append(yaw)
        # no gyro and no orientation: the heading cannot be integrated (held constant)
        self._gyro_z.append(0.0 if imu.gyro_rps is None else imu.gyro_rps.z)

    def finish(self) -> None:
        """Compute the velocity series once every sample is in."""
        if not self._t:
            return
        t = np.asarray(self._t, np.int64)
        ts = (t - t[0]) / 1e9
        vert = np.asarray(self._vert)
        yaw = np.asarray(self._yaw)
        if np.isnan(yaw).any():
            gz = np.asarray(self._gyro_z)
            integrated = np.concatenate(([0.0], np.cumsum(np.diff(ts) * gz[1:])))
            yaw = np.where(np.isnan(yaw), integrated, yaw)
        speed = self._speeds(ts, vert)
        self.t_ns = t
        self.v = np.column_stack([speed * np.cos(yaw), speed * np.sin(yaw)])
        self._t, self._vert, self._yaw, self._gyro_z = [], [], [], []

    def _speeds(self, ts: np.ndarray, vert: np.ndarray) -> np.ndarray:
        cfg = self.config
        freqs = np.arange(cfg.cadence_hz[0], cfg.cadence_hz[1], 0.05)
        half = cfg.window_s / 2
        out = np.zeros(len(ts))
        lo = hi = 0
        for k, tk in enumerate(ts):
            while ts[lo] < tk - half:
                lo += 1
            while hi < len(ts) and ts[hi] <= tk + half:
                hi += 1
            w_t, w_v = ts[lo:hi], vert[lo:hi] - vert[lo:hi].mean()
            if len(w_t) < 6:
                continue
            # least-squares sinusoid amplitude per candidate frequency (Lomb-Scargle-like)
            ph = 2 * np.pi * freqs[:, None] * w_t[None, :]
            c, s = np.cos(ph), np.sin(ph)
            amp = 2 * np.sqrt((c @ w_v) ** 2 + (s @ w_v) ** 2) / len(w_t)
            best = int(np.argmax(amp))
            if amp[best] >= cfg.min_bounce_mps2:
                out[k] = freqs[best] * cfg.step_length_m
        # the cadence window (3 s) smears short stops; a quiet short window means standing still
        if len(ts) > 2:
            rate = (len(ts) - 1) / max(ts[-1] - ts[0], 1e-9)
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
