"""Stage 6 of VM-Tracking, writing: each frame's published tracks, 3-D scene and the cameras'
track overlays."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from trackctl.logs.messages import (
    Track,
    Tracks,
    TrackState,
)
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress
from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.naming import frame_tracks
from trackctl.vmtrack.offline import Offline
from trackctl.vmtrack.overlay import TrackOverlay
from trackctl.vmtrack.scene import scene_update
from trackctl.vmtrack.score import TruthScore

TRACKS_TOPIC = "/vmtrack/tracks"


SCENE_TOPIC = "/vmtrack/scene"


@dataclass
class Tally:
    """The tracks written: frames published per id, track-frames coasting, track-frames."""

    published: dict[str, int] = field(default_factory=dict)
    coasting: int = 0
    shown: int = 0
    written: list[Tracks] = field(default_factory=list)
    """Every frame's published tracks, as written (the run's result for library users)."""

    def add(self, tracks: list[Track]) -> None:
        """Count one frame's published tracks."""
        for msg in tracks:
            self.published[msg.track_id] = self.published.get(msg.track_id, 0) + 1
            self.coasting += msg.state is TrackState.PREDICTED
        self.shown += len(tracks)


def write_frames(
    writer: LogWriter,
    frames: list[FrameOut],
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    offline: Offline,
    phones: dict[str, PhoneMotion],
    gate_m: float,
    progress: Progress,
    score: TruthScore,
    overlay: TrackOverlay,
) -> Tally:
    """Each frame's published tracks, 3-D scene and track boxes per camera written, counted
    and scored; returns the count."""
    tally = Tally()
    for k_fr, fr in enumerate(frames):
        progress(k_fr, len(frames), "writing tracks")
        placed = (offline.retracked, k_fr, gate_m) if offline.retracked else None
        tracks = frame_tracks(fr, offline.plan, positions, offline.ids, placed)
        tally.add(tracks)
        msg = Tracks(fr.t_ns, tuple(tracks))
        tally.written.append(msg)
        writer.write(TRACKS_TOPIC, msg)
        writer.write(SCENE_TOPIC, scene_update(fr.t_ns, tracks, set(phones)), fr.t_ns)
        overlay.write(writer, fr.t_ns, tracks)
        score.add_frame(fr.t_ns, tracks)
    return tally
