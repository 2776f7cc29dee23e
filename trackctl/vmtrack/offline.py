"""Stage 4 of VM-Tracking, offline: the publication plan (stitching, clean-up), the offline identity
and the identity refinement, over the whole log.

The refinement is an injected part (a :class:`Refinement`): :class:`PhoneRetracking` (the
default, :mod:`~trackctl.vmtrack.retrack`) follows each identified carrier through the raw
detections by their phone's walk; :func:`no_refinement` skips it (``--no-retrack``); a library
user passes their own to :func:`~trackctl.vmtrack.pipeline.run_stages`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from trackctl.logs.messages import RssiScan
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


@dataclass(frozen=True)
class RefinementInputs:
    """What a refinement sees: the frame times, every frame's raw ground detections (before
    association), the RSSI scans, the phones' motion and the offline identity."""

    frame_t: np.ndarray
    """Frame times, ns (int64)."""
    points: Sequence[np.ndarray]
    """Per frame, the (n, 2) ground positions of its detections, metres."""
    rssi: Sequence[RssiScan]
    phones: dict[str, PhoneMotion]
    ids: Identities


class Refinement(Protocol):
    """An identity refinement: the carriers it re-finds (by MID), each with the frames it is
    seen on and its alignment. What it returns names the published tracks where it finds the
    carrier (:mod:`~trackctl.vmtrack.naming`)."""

    def __call__(self, inputs: RefinementInputs, progress: Progress) -> Retracked: ...


def no_refinement(inputs: RefinementInputs, progress: Progress) -> Retracked:
    """The refinement skipped: the offline identity names the tracks."""
    return Retracked()


class PhoneRetracking:
    """The default refinement: each identified phone's carrier re-tracked over the raw
    detections (and RSSI) by the phone's walk (:func:`~trackctl.vmtrack.retrack.retrack`)."""

    def __init__(self, cfg: VmTrackConfig) -> None:
        self.cfg = cfg

    def __call__(self, inputs: RefinementInputs, progress: Progress) -> Retracked:
        cfg = self.cfg
        model = (cfg.binding.rssi_at_1m_dbm, cfg.binding.path_loss_exponent)
        radio = RadioEvidence(inputs.frame_t, inputs.rssi, model, cfg.refinement.radio)
        return retrack(
            inputs.frame_t,
            list(inputs.points),
            inputs.phones,
            inputs.ids.known,
            cfg.align,
            cfg.refinement,
            cfg.phones_aligned,
            radio,
            progress,
            _trusted(inputs.ids, cfg.refinement.trust_clear_share),
        )


def default_refinement(cfg: VmTrackConfig) -> Refinement:
    """The refinement the configuration asks for: :class:`PhoneRetracking` unless disabled."""
    return PhoneRetracking(cfg) if cfg.refinement.enabled else no_refinement


def offline_stages(
    online: OnlineTracker,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    phones: dict[str, PhoneMotion],
    cfg: VmTrackConfig,
    mode: Mode,
    progress: Progress,
    refinement: Refinement | None = None,
    appearance: Mapping[int, np.ndarray] | None = None,
) -> Offline:
    """The offline stages: the publication plan, then (VM with the offline identity) the
    identities, then the identity refinement (``refinement``, by default the configuration's:
    :func:`default_refinement`)."""
    frames = online.frames
    offline = mode is Mode.VM and cfg.identity is Identity.OFFLINE
    deaths = np.array(online.static_death_log, float).reshape(-1, 2)
    progress(0, None, "stitching and identifying")
    plan = plan_publication(
        frames,
        positions,
        cfg.stitch,
        all_tracks=offline,
        static_deaths=deaths,
        appearance=appearance,
    )
    ids = (
        identify(frames, plan, phones, cfg.align, cfg.identify, cfg.phones_aligned)
        if offline
        else None
    )
    if ids is None:
        return Offline(plan, ids, Retracked())
    refine = refinement if refinement is not None else default_refinement(cfg)
    frame_t = np.array([fr.t_ns for fr in frames], np.int64)
    points = tuple(online.raw_points.get(int(t), np.empty((0, 2))) for t in frame_t)
    inputs = RefinementInputs(frame_t, points, tuple(online.rssi_log), phones, ids)
    retracked = refine(inputs, progress)
    _take_retrack_alignments(ids.alignments, retracked)
    return Offline(plan, ids, retracked)


def _trusted(ids: Identities, share: float | None) -> dict[str, int]:
    """The phones whose offline identity is clear in at least ``share`` of the frames it puts
    them on a chain, with an alignment fitted (:attr:`RetrackConfig.trust_clear_share`), and
    the frames it is clear in."""
    if share is None:
        return {}
    return {
        mid: clear
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
