"""Stage 3 of VM-Tracking: every track's states RTS-smoothed over the whole log (filterpy)."""

from __future__ import annotations

import numpy as np
from filterpy.kalman import rts_smoother

from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.tracker import GroundTrack, TrackerConfig


def smoothed_positions(
    frames: list[FrameOut], smooth: bool, cfg: TrackerConfig
) -> dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]:
    """State (x, y, vx, vy) and covariance of every (track, history index): RTS-smoothed when
    asked (filterpy; the offline advantage the paper's real-time system did not have)."""
    out: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
    seen: dict[int, GroundTrack] = {}
    for fr in frames:
        for trk, _, _, _ in fr.rows:
            seen[trk.key] = trk
    for key, trk in seen.items():
        hist = trk.history
        if not hist:
            continue
        xs = np.array([h[1] for h in hist])
        ps = np.array([h[2] for h in hist])
        if smooth and len(hist) > 2:
            fs, qs = [], []
            for k in range(len(hist)):
                dt = (hist[k + 1][0] - hist[k][0]) / 1e9 if k + 1 < len(hist) else 0.0
                f, q = trk.transition(dt, cfg)
                fs.append(f)
                qs.append(q)
            xs, ps, _, _ = rts_smoother(xs, ps, np.array(fs), np.array(qs))
        for k in range(len(hist)):
            out[(key, k)] = (xs[k][:, 0], ps[k])
    return out
