"""Stage 4 of VM-Tracking, offline: the publication plan (stitching, clean-up), the offline identity
and the identity refinement (re-tracking), over the whole log.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackctl.processing.base import Progress
from trackctl.vmtrack.align import Alignment
from trackctl.vmtrack.config import Identity, Mode, VmTrackConfig
from trackctl.vmtrack.identify import Identities, identify
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.online import OnlineTracker
from trackctl.vmtrack.radio import RadioEvidence
from trackctl.vmtrack.retrack import PhoneTrack, Retracked, retrack
from trackctl.vmtrack.stitch import Publication, plan_publication


@dataclass(frozen=True)
class Offline:
    """What the offline stages give the writing: the publication plan (stitching, clean-up),
    the offline identity (None unless asked) and the re-tracked carriers (empty unless run)."""

    plan: Publication
    ids: Identities | None
    retracked: Retracked


def offline_stages(
    online: OnlineTracker,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    phones: dict[str, PhoneMotion],
    cfg: VmTrackConfig,
    mode: Mode,
    progress: Progress,
) -> Offline:
    """The offline stages: the publication plan, then (VM with the offline identity) the
    identities, then (when enabled) the re-tracking."""
    frames = online.frames
    offline = mode is Mode.VM and cfg.identity is Identity.OFFLINE
    deaths = np.array(online.static_death_log, float).reshape(-1, 2)
    progress(0, None, "stitching and identifying")
    plan = plan_publication(frames, positions, cfg.stitch, all_tracks=offline, static_deaths=deaths)
    ids = (
        identify(frames, plan, phones, cfg.align, cfg.identify, cfg.phones_aligned)
        if offline
        else None
    )
    if ids is None or not cfg.retrack.enabled:
        return Offline(plan, ids, Retracked())
    return Offline(plan, ids, _retrack(online, ids, phones, cfg, progress))


def _retrack(
    online: OnlineTracker,
    ids: Identities,
    phones: dict[str, PhoneMotion],
    cfg: VmTrackConfig,
    progress: Progress,
) -> Retracked:
    """The identified phones' carriers re-tracked over the raw detections (and RSSI); their
    alignments replace the identity's in ``ids`` (for the report)."""
    frame_t = np.array([fr.t_ns for fr in online.frames], np.int64)
    points = [online.raw_points.get(int(t), np.empty((0, 2))) for t in frame_t]
    model = (cfg.rssi_at_1m_dbm, cfg.path_loss_exponent)
    radio = RadioEvidence(frame_t, online.rssi_log, model, cfg.retrack.radio)
    retracked = retrack(
        frame_t,
        points,
        phones,
        ids.known,
        cfg.align,
        cfg.retrack,
        cfg.phones_aligned,
        radio,
        progress,
        _trusted(ids, cfg.retrack.trust_clear_share),
    )
    _take_retrack_alignments(ids.alignments, retracked)
    return retracked


def _trusted(ids: Identities, share: float | None) -> set[str]:
    """The phones whose offline identity is clear in at least ``share`` of the frames it puts
    them on a chain, with an alignment fitted (:attr:`RetrackConfig.trust_clear_share`)."""
    if share is None:
        return set()
    return {
        mid
        for mid, (on, clear) in ids.clear.items()
        if on and clear >= share * on and mid in ids.known
    }


def _take_retrack_alignments(
    alignments: dict[str, Alignment], retracked: dict[str, PhoneTrack]
) -> None:
    """Each re-tracked phone's alignment into ``alignments`` (for the report): its clock
    offset, and the circular mean of its yaw and the median of its scale over the frames it was
    seen. A phone seen nowhere (its carrier never in view, or every frame withheld) has none:
    the search's guess there has nothing behind it, and the report says so rather than give
    it."""
    for mid, pt in retracked.items():
        seen = np.array(sorted(pt.seen), int)
        a = pt.a[seen]
        a = a[~np.isnan(a)]
        if not len(a):
            alignments.pop(mid, None)
            continue
        yaw = np.angle(np.mean(a / np.abs(a)))
        scale = float(np.median(np.abs(a)))
        alignments[mid] = Alignment(complex(scale * np.exp(1j * yaw)), pt.lag_s, -1)
