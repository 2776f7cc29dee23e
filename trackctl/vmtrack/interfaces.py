"""Hand-offs between VM-Tracking's stages, below every stage that uses them (rosbags'
``interfaces/`` is the model): the online stage's per-frame output, read by the offline
clean-up (:mod:`~trackctl.vmtrack.stitch`), the offline identity
(:mod:`~trackctl.vmtrack.identify`) and the writer (:mod:`~trackctl.vmtrack.pipeline`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from trackctl.logs.messages import TrackState
from trackctl.vmtrack.tracker import GroundTrack

__all__ = ["FrameOut"]


@dataclass(frozen=True, slots=True)
class FrameOut:
    """One frame's tracks: (track, MID bound now, state, index into the track's history)."""

    t_ns: int
    rows: Sequence[tuple[GroundTrack, str | None, TrackState, int]]
