"""BridgeLoc figures from an ``bridgeloc eval`` output log (matplotlib, the ``plot`` extra)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from trackctl.errors import InputError
from trackctl.logs import topics
from trackctl.logs.reader import LogReader

__all__ = ["plot_run"]


def _plt():  # noqa: ANN202
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:
        raise InputError("--plot needs matplotlib: pip install 'trackctl[plot]'") from err
    return plt


def plot_run(log: str | Path, out_dir: str | Path) -> list[Path]:
    """Path (truth vs estimate, tags, cameras) and error over time; returns the PNGs written."""
    plt = _plt()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    reader = LogReader(log)
    meta = reader.metadata().get("bridgeloc", {})
    robot = meta.get("robot", "r1")
    truth: dict[int, tuple[float, float]] = {}
    est: dict[int, tuple[float, float]] = {}
    for msg in reader.messages([topics.GROUND_TRUTH, "/bridgeloc/pose"]):
        if msg.topic == topics.GROUND_TRUTH:
            for e in msg.message.entities:
                if e.entity_id == robot:
                    truth[msg.log_time_ns] = (e.position_m.x, e.position_m.y)
        else:
            p = msg.message.pose.position
            est[msg.log_time_ns] = (p.x, p.y)
    fig, ax = plt.subplots(figsize=(8, 5))
    if truth:
        t = np.array(list(truth.values()))
        ax.plot(t[:, 0], t[:, 1], "-", color="0.3", lw=1.5, label="ground truth")
    if est:
        e = np.array(list(est.values()))
        ax.plot(e[:, 0], e[:, 1], ".", color="tab:red", ms=3, label="BridgeLoc (localized)")
    for tag in json.loads(meta.get("tags_truth", "[]")):
        c = tag["center_m"]
        ax.plot(c[0], c[1], "s", color="k", ms=6)
        ax.annotate(
            tag["tag_id"], (c[0], c[1]), fontsize=7, xytext=(3, 3), textcoords="offset points"
        )
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"BridgeLoc path ({meta.get('field', '?')})")
    p1 = out / "bridgeloc_path.png"
    fig.savefig(p1, dpi=110, bbox_inches="tight")
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(8, 3))
    ts = sorted(set(truth) & set(est))
    if ts:
        t0 = min(truth)
        err = [math.dist(truth[k], est[k]) for k in ts]
        ax.plot([(k - t0) / 1e9 for k in ts], err, ".", ms=3)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("error (m)")
    ax.set_title("Localization error (localized positions only)")
    p2 = out / "bridgeloc_error.png"
    fig.savefig(p2, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return [p1, p2]
