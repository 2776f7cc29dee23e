"""Hand-offs between VM-Tracking's stages, below every stage that uses them (rosbags'
``interfaces/`` is the model): the online stage's per-frame output, read by the offline
clean-up (:mod:`~trackctl.vmtrack.stitch`), the offline identity
(:mod:`~trackctl.vmtrack.identify`) and the writer (:mod:`~trackctl.vmtrack.write`); and the
run's result, :class:`VmResult`."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from trackctl.logs.messages import MetricReport, Tracks, TrackState
from trackctl.vmtrack.tracker import GroundTrack

__all__ = ["FrameOut", "VmResult"]


@dataclass(frozen=True, slots=True)
class FrameOut:
    """One frame's tracks: (track, MID bound now, state, index into the track's history)."""

    t_ns: int
    rows: Sequence[tuple[GroundTrack, str | None, TrackState, int]]


@dataclass(frozen=True, slots=True)
class VmResult:
    """What a VM-Tracking run gives a library user (evo's ``Result`` is the model): the
    published tracks of every frame, as written to ``/vmtrack/tracks``, and the report, so
    nobody needs to read the output log back."""

    tracks: tuple[Tracks, ...]
    report: MetricReport

    def table(self) -> pd.DataFrame:
        """The tracks as one row per (frame, track): ``t_ns``, ``track_id`` (a phone's MID
        where identified, else a visual id), ``visual_id``, ``x_m``, ``y_m``, ``vx_mps``,
        ``vy_mps``, ``state``."""
        rows = [
            (
                fr.t_ns,
                t.track_id,
                t.visual_id,
                t.position_m.x,
                t.position_m.y,
                t.velocity_mps.x if t.velocity_mps else math.nan,
                t.velocity_mps.y if t.velocity_mps else math.nan,
                t.state.value,
            )
            for fr in self.tracks
            for t in fr.tracks
        ]
        cols = ["t_ns", "track_id", "visual_id", "x_m", "y_m", "vx_mps", "vy_mps", "state"]
        return pd.DataFrame(rows, columns=cols)
