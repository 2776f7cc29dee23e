"""S-Mirror figures (dissertation Figs. 4.6, 4.8-4.10) from a run's per-sample figures.

matplotlib is the optional ``plot`` extra: imported lazily, Agg backend.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from trackctl.plots import pyplot
from trackctl.smirror.pipeline import SmirrorResult, error_by_range

__all__ = ["require_matplotlib", "plot_result", "per_metre"]


def require_matplotlib() -> Any:
    """The pyplot module (Agg backend), or an InputError saying how to install it."""
    return pyplot()


def per_metre(
    res: SmirrorResult, values: list[float], seg_m: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``values`` per ``seg_m`` of travelled path (Figs. 4.8-4.10).

    Returns the segment starts (m) and the means.
    """
    path = np.asarray(res.path_m)
    v = np.asarray(values, float)
    if not len(path):
        return np.array([]), np.array([])
    seg = np.floor(path / seg_m).astype(int)
    starts = np.unique(seg)
    return starts * seg_m, np.array([np.nanmean(v[seg == s]) for s in starts])


def plot_result(res: SmirrorResult, out_dir: str | Path) -> list[Path]:
    """Write error/delay vs distance to the node and error/delay/rate per metre of path."""
    plt = require_matplotlib()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []

    bins = error_by_range(res)
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    ax[0].bar([b[0] + 0.5 for b in bins], [b[1] or 0 for b in bins], width=0.8)
    ax[0].set(
        xlabel="distance to node (m)", ylabel="error (m)", title="Localization error (Fig. 4.6a)"
    )
    rng = np.asarray(res.range_m)
    delay = np.asarray(res.delay_ms)
    centers, dm = [], []
    for lo in range(2, 12):
        sel = (rng >= lo) & (rng < lo + 1)
        if sel.any():
            centers.append(lo + 0.5)
            dm.append(float(delay[sel].mean()))
    ax[1].bar(centers, dm, width=0.8)
    ax[1].set(
        xlabel="distance to node (m)", ylabel="delay (ms)", title="Localization delay (Fig. 4.6b)"
    )
    fig.tight_layout()
    p = out / "smirror_distance.png"
    fig.savefig(p, dpi=80)
    plt.close(fig)
    written.append(p)

    fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    x, e = per_metre(res, res.error_m)
    _, c = per_metre(res, [float(b) for b in res.in_coverage])
    ax[0].plot(x, e, "-o", ms=2)
    ax[0].fill_between(
        x,
        0,
        max(0.05, float(np.nanmax(e)) if len(e) else 1),
        where=c < 0.5,
        color="0.85",
        label="out of coverage",
    )
    ax[0].set(ylabel="error (m)", title="Continuous localization per 1 m (Figs. 4.8-4.10)")
    ax[0].legend(loc="upper right")
    x, d = per_metre(res, res.delay_ms)
    ax[1].plot(x, d, "-o", ms=2)
    ax[1].set(ylabel="delay (ms)")
    ev = np.asarray(res.events, float).reshape(-1, 4)
    ts = np.asarray(res.t_s)
    if len(ev) and len(ts) > 1:
        idx = np.clip(np.searchsorted(ts, ev[:, 0], side="right") - 1, 0, len(ts) - 1)
        path = np.asarray(res.path_m)[idx]
        seg = np.floor(path).astype(int)
        seconds = np.bincount(np.floor(np.asarray(res.path_m)).astype(int)) * float(
            np.median(np.diff(ts))
        )
        sent = np.bincount(seg, weights=ev[:, 1], minlength=len(seconds))[: len(seconds)]
        ok = seconds > 0
        ax[2].plot(np.arange(len(seconds))[ok], sent[ok] / seconds[ok] / 1e3, "-o", ms=2)
    ax[2].set(xlabel="path (m)", ylabel="data rate (kB/s)")
    fig.tight_layout()
    p = out / "smirror_path.png"
    fig.savefig(p, dpi=80)
    plt.close(fig)
    written.append(p)
    return written
