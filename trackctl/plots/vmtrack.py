"""VM-Tracking figures from a vm-track output log: error over time (like Fig. 3.7) and the CDF
of successful tracking time (like Fig. 3.9)."""

from __future__ import annotations

import math
import os
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trackctl.errors import InputError
from trackctl.logs import topics
from trackctl.logs.messages import GroundTruthEntity
from trackctl.logs.reader import LogMessage, LogReader
from trackctl.metrics.tracking import InitialIdentity
from trackctl.plots import pyplot
from trackctl.vmtrack.pipeline import TRACKS_TOPIC

__all__ = ["user_errors", "tracking_segments", "plot_vmtrack", "plot_run"]


@dataclass(frozen=True, slots=True)
class _VmLog:
    """What the VM figures read of a vm-track output log."""

    tracks: dict[int, dict[str, tuple[float, float]]]
    """Per track message (log time ns): track id -> position (x, y) m."""
    truth: list[LogMessage]
    """The ground-truth messages, in log order."""
    mids: set[str]
    """EIDs (phone MIDs) the ground truth carries."""
    t0: int | None
    """Log time of the first message read."""


def _read_vm_log(log: str | os.PathLike[str]) -> _VmLog:
    """The tracks and the ground truth of a vm-track output log.

    Raises:
        InputError: the log lacks the tracks or the ground truth.
    """
    reader = LogReader(log)
    present = reader.topics()
    for needed in (TRACKS_TOPIC, topics.GROUND_TRUTH):
        if needed not in present:
            raise InputError(f"{reader.path}: {needed} is missing; the VM figures need it")
    tracks: dict[int, dict[str, tuple[float, float]]] = {}
    t0: int | None = None
    pending = []
    mid_of: set[str] = set()
    for msg in reader.messages([TRACKS_TOPIC, topics.GROUND_TRUTH]):
        if t0 is None:
            t0 = msg.log_time_ns
        if msg.topic == TRACKS_TOPIC:
            tracks[msg.log_time_ns] = {
                t.track_id: (t.position_m.x, t.position_m.y) for t in msg.message.tracks
            }
        else:
            pending.append(msg)
            mid_of.update(e.electronic_id for e in msg.message.entities if e.electronic_id)
    return _VmLog(tracks, pending, mid_of, t0)


def _carrier_error(
    ent: GroundTruthEntity,
    mid: str,
    hyp: dict[str, tuple[float, float]],
    named: bool,
    followed: InitialIdentity,
) -> float:
    """A phone carrier's error (m) against the tracks of one instant: the track named by the
    phone's MID ``mid``, else the track they were first seen with; NaN when that track is
    absent."""
    xy_true = (ent.position_m.x, ent.position_m.y)
    if named:
        xy = hyp.get(mid)
        return math.nan if xy is None else math.dist(xy, xy_true)
    found = followed.error(ent.entity_id, xy_true, hyp)
    return math.nan if found is None else found


def user_errors(
    log: str | os.PathLike[str],
) -> dict[str, list[tuple[float, float]]]:
    """Per phone carrier: (time s, error m or NaN when the phone's track is absent)."""
    vm = _read_vm_log(log)
    out: dict[str, list[tuple[float, float]]] = defaultdict(list)
    # identified tracks carry the phone's MID; a visual-only run names nobody, so each carrier
    # follows the track they were first seen with (InitialIdentity, as the paper scores V-AF)
    named = any(k in vm.mids for frame in vm.tracks.values() for k in frame)
    followed = InitialIdentity()
    for msg in vm.truth:
        hyp = vm.tracks.get(msg.log_time_ns, {})
        t_s = (msg.log_time_ns - (vm.t0 or 0)) / 1e9
        for e in msg.message.entities:
            mid = e.electronic_id
            if mid:
                out[mid].append((t_s, _carrier_error(e, mid, hyp, named, followed)))
    return dict(out)


def tracking_segments(
    errors: dict[str, list[tuple[float, float]]], threshold_m: float = 1.0
) -> list[float]:
    """Durations (s) of the stretches in which a user's track stays within ``threshold_m``."""
    out = []
    for series in errors.values():
        start = prev = None
        for t, err in series:
            ok = not math.isnan(err) and err < threshold_m
            if ok and start is None:
                start = t
            if not ok and start is not None:
                out.append((prev if prev is not None else t) - start)
                start = None
            prev = t
        if start is not None and prev is not None:
            out.append(prev - start)
    return out


def plot_vmtrack(log: str | os.PathLike[str], folder: str | os.PathLike[str]) -> list[Path]:
    """Write ``error_over_time.png`` and ``tracking_time_cdf.png`` into ``folder``."""
    plt = pyplot()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    errors = user_errors(log)
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for mid, series in sorted(errors.items()):
        arr = np.array(series)
        ax.plot(arr[:, 0], arr[:, 1], lw=0.8, label=mid)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("tracking error (m)")
    ax.set_title("Tracking error of each phone carrier (cf. Fig. 3.7)")
    ax.legend(fontsize=6, ncol=3)
    ax.grid(alpha=0.3)
    first = folder / "error_over_time.png"
    fig.tight_layout()
    fig.savefig(first, dpi=110)
    plt.close(fig)
    seg = np.sort(np.array(tracking_segments(errors)))
    fig, ax = plt.subplots(figsize=(5, 3.5))
    if len(seg):
        ax.step(seg, np.arange(1, len(seg) + 1) / len(seg), where="post")
    ax.set_xlabel("successful tracking time (s)")
    ax.set_ylabel("CDF")
    ax.set_title("CDF of successful tracking time (cf. Fig. 3.9)")
    ax.grid(alpha=0.3)
    second = folder / "tracking_time_cdf.png"
    fig.tight_layout()
    fig.savefig(second, dpi=110)
    plt.close(fig)
    return [first, second]


plot_run = plot_vmtrack
"""The uniform name every system's figure module exports (``cli.process.figures_from_output``)."""
