"""Stage 7 of VM-Tracking, the report: the run's figures, the unmeasured ones null with the
reason."""

from __future__ import annotations

import math
import time

import numpy as np

from trackctl.vmtrack.binder import BindingStats
from trackctl.vmtrack.config import Mode, VmTrackConfig
from trackctl.vmtrack.frames import FrameDetector
from trackctl.vmtrack.identify import Identities
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.offline import Offline
from trackctl.vmtrack.online import OnlineTracker
from trackctl.vmtrack.retrack import Retracked, VisitReading
from trackctl.vmtrack.score import TruthScore
from trackctl.vmtrack.stitch import Publication
from trackctl.vmtrack.write import Tally

_RETRACK_ONLY = (
    "withheld_s/",
    "ambiguous_s/",
    "grouped_s/",
    "searched/",
    "visits",
    "edge_turnover",
    "occupancy_steadiness",
)


_BINDINGS = ("bindings", "checkpoint_bindings", "offline_bindings")


def unmeasured(
    metrics: dict[str, float | int | str | None], cfg: VmTrackConfig, mode: Mode
) -> dict[str, str]:
    """Why figures the configuration leaves out are null (the log's own gaps, such as no
    ground truth, are found by the runner from metrics/catalog.py). V-AF binds no phone: its
    binding counts are set to null here."""
    why: dict[str, str] = {}
    if mode is Mode.V_AF:
        for key in _BINDINGS:
            if key in metrics:
                metrics[key] = None
                why[key] = "v-af binds no phone (visual only)"
    if mode is Mode.V_AF or not cfg.refinement.enabled:
        reason = (
            "re-tracking is off (--no-retrack)" if mode is Mode.VM else "v-af re-tracks nothing"
        )
        why.update(
            {k: reason for k, v in metrics.items() if k.startswith(_RETRACK_ONLY) and v is None}
        )
    if metrics.get("tracks_reidentified", 0) is None:
        why["tracks_reidentified"] = (
            "no track has a colour signature (no camera frames in the log, or no clear view)"
        )
    return why


class StageClock:
    """Wall time of each stage (reported per frame)."""

    def __init__(self) -> None:
        self.started = self._last = time.perf_counter()
        self.laps: dict[str, float] = {}

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.laps[name] = now - self._last
        self._last = now


def timing_metrics(
    clock: StageClock, online: OnlineTracker, detector: FrameDetector | None
) -> dict[str, float]:
    n = max(online.frame_count, 1)
    return {
        "ms_per_frame": round(1000 * (time.perf_counter() - clock.started) / n, 3),
        "ms_per_frame_motion": round(1000 * clock.laps["motion"] / n, 3),
        "ms_per_frame_association": round(1000 * online.seconds / n, 3),
        "ms_per_frame_smoothing": round(1000 * clock.laps["smoothing"] / n, 3),
    }


def detector_metrics(detector: FrameDetector, frames: int) -> dict[str, float | int]:
    n = max(frames, 1)
    return {
        "ms_per_frame_decode": round(1000 * detector.seconds_decode / n, 3),
        "ms_per_frame_detection": round(1000 * detector.seconds_detect / n, 3),
        "background_s": round(detector.seconds_background, 3),
        "full_searches": detector.full_searches,
        "region_searches": detector.region_searches,
        "bad_frames": detector.bad_frames,
    }


def report_metrics(
    online: OnlineTracker,
    phones: dict[str, PhoneMotion],
    mode: Mode,
    offline: Offline,
    score: TruthScore,
    tally: Tally,
) -> dict[str, float | int | str | None]:
    """The run's figures: against the ground truth, then those a log without it can give."""
    stats = online.identity.stats
    return {
        "system": "vm-tracking",
        "mode": mode.value,
        "frames": online.frame_count,
        **score.people_metrics(len(phones)),
        **score.mot_metrics(),
        "loss_events": score.loss_events if mode is Mode.VM else stats.losses,
        **score.recovery_metrics(),
        "bindings": stats.bindings,
        "checkpoint_bindings": stats.checkpoint_bindings,
        "offline_bindings": stats.offline_bindings,
        **score.detection_metrics(),
        **_no_truth_metrics(online, tally.published, tally.coasting, tally.shown, offline.plan),
        **_identity_metrics(offline.ids, stats, phones, offline.retracked),
        **_radio_metrics(offline.retracked),
        **_visit_metrics(offline.retracked.visits),
    }


def _visit_metrics(reading: VisitReading | None) -> dict[str, float | int | str | None]:
    """The visit model the re-tracking read from the log and what it read it from (null: not
    read; an edge turnover is null too where no walk begins or ends inside, unbounded)."""
    if reading is None:
        return dict.fromkeys(("visits", "edge_turnover", "occupancy_steadiness"))
    turnover = reading.edge_turnover
    finite = turnover is not None and math.isfinite(turnover)
    steady = reading.steadiness
    return {
        "visits": "one" if reading.one_visit else "throughout",
        "edge_turnover": round(turnover, 1) if finite and turnover is not None else None,
        "occupancy_steadiness": round(steady, 2) if steady is not None else None,
    }


def _radio_metrics(retracked: Retracked) -> dict[str, float | int | None]:
    """Each AP's path loss as the re-tracking fitted it (a site's calibration, from the log)."""
    out: dict[str, float | int | None] = {}
    for ap, model in sorted(retracked.calibration.items()):
        out[f"rssi_at_1m_dbm/{ap}"] = round(model.at1_dbm, 1)
        out[f"path_loss_exponent/{ap}"] = round(model.exponent, 2)
        out[f"rssi_sigma_db/{ap}"] = round(model.sigma_db, 1)
        out[f"rssi_readings/{ap}"] = model.readings
    if retracked.calibration:
        out["searched_again"] = len(retracked.searched_again)
    return out


def _identity_metrics(
    ids: Identities | None,
    stats: BindingStats,
    phones: dict[str, PhoneMotion],
    retracked: Retracked | None = None,
) -> dict[str, float | int | None]:
    """Identity figures a log without ground truth can give: ambiguity, each phone's
    estimated alignment (clock offset, device-to-walk yaw, step scale), the share of its
    identity that is clear and whether the re-tracking searched its alignment (1) or started
    from its identity's (0)."""
    if not phones:
        return {}
    out: dict[str, float | int | None] = {
        "ambiguous_frames": ids.ambiguous_frames if ids else stats.ambiguous_frames,
        "unanchored_frames": ids.unanchored_frames if ids else None,
    }
    for mid in sorted(phones):
        out.update(_phone_figures(mid, ids, retracked))
    return out


def _phone_figures(
    mid: str, ids: Identities | None, retracked: Retracked | None
) -> dict[str, float | int | None]:
    """One phone's figures of :func:`_identity_metrics` (null where the stage that gives them
    did not run)."""
    al = ids.alignments.get(mid) if ids else None
    pt = retracked.get(mid) if retracked else None
    on, clear = ids.clear.get(mid, (0, 0)) if ids else (0, 0)
    searched = int(mid in retracked.searched) if pt and retracked else None
    if al is None:
        aligned: dict[str, float | int | None] = dict.fromkeys(
            (f"clock_offset_s/{mid}", f"yaw_offset_deg/{mid}", f"step_scale/{mid}")
        )
    else:
        aligned = {
            f"clock_offset_s/{mid}": round(al.lag_s, 3),
            f"yaw_offset_deg/{mid}": round(al.yaw_deg, 1),
            f"step_scale/{mid}": round(al.scale, 3),
        }
    return {
        **aligned,
        f"withheld_s/{mid}": round(pt.withheld_s, 1) if pt else None,
        f"ambiguous_s/{mid}": round(pt.ambiguous_s, 1) if pt else None,
        f"grouped_s/{mid}": round(pt.grouped_s, 1) if pt else None,
        f"clear_share/{mid}": round(clear / on, 3) if on else None,
        f"searched/{mid}": searched,
    }


def _no_truth_metrics(
    online: OnlineTracker, published: dict[str, int], coasting: int, shown: int, plan: Publication
) -> dict[str, float | int | None]:
    """What a log without ground truth can say: detections, tracks and their lengths."""
    counts = np.array([len(p) for p in online.raw_points.values()] or [0])
    lengths = np.array(sorted(published.values()) or [0])
    return {
        "detections_per_frame_mean": round(float(counts.mean()), 3),
        "detections_per_frame_max": int(counts.max()),
        "tracks_started": online.tracks_started,
        "tracks_published": len(published),
        "tracks_stitched": plan.links,
        "tracks_reidentified": plan.reidentified,
        "tracks_dropped_short": plan.dropped,
        "track_frames_median": float(np.median(lengths)),
        "track_frames_p10": float(np.percentile(lengths, 10)),
        "track_frames_p90": float(np.percentile(lengths, 90)),
        "coasting_share": round(coasting / shown, 4) if shown else None,
    }
