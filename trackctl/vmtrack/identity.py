"""Identity stage of VM-Tracking: which phone (MID) the person of each visual track (VID) carries.

Online, :class:`IdentityBinder` binds a phone to the one track whose velocity keeps agreeing with
the phone's motion sensors (Theorem 1), helped by RSSI check-points (a phone heard very loudly next
to an AP) and RSSI path-loss evidence, and notices when a bound track stops agreeing (loss).
Offline, :meth:`IdentityBinder.finish` names still-anonymous tracks after phones that were never
bound and back-dates every identity along its track as far as the motion agreed.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from trackctl.logs.messages import RssiScan, TrackState
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.tracker import GroundTrack

if TYPE_CHECKING:
    from trackctl.vmtrack.config import VmTrackConfig

__all__ = ["Candidate", "IdentityBinder", "BindingStats"]

_RSSI_WEIGHT = 0.05


@dataclass
class Candidate:
    """Evidence that a phone (MID) is carried by the person of one visual track (VID)."""

    n: int = 0
    d2: float = 0.0
    """Sum of squared velocity disagreements (m/s)^2 over ``n`` frames."""
    rssi_n: int = 0
    rssi_z2: float = 0.0
    """Sum of squared normalised RSSI residuals (observed - path loss at the track's distance)."""

    @property
    def mean(self) -> float:
        """Mean squared velocity disagreement plus the RSSI penalty, in (m/s)^2."""
        return (self.d2 / self.n if self.n else 0.0) + self.rssi_penalty

    @property
    def rssi_penalty(self) -> float:
        """Chi-square excess of the RSSI residuals (expected 1 per reading for the right person),
        in units of the rejection threshold's scale so one incompatible AP pass rejects."""
        if self.rssi_n < 2:
            return 0.0
        return _RSSI_WEIGHT * max(0.0, self.rssi_z2 / self.rssi_n - 1.0)

    def add_rssi(self, z2: float) -> None:
        """Add one squared normalised RSSI residual."""
        self.rssi_n += 1
        self.rssi_z2 += z2

    def add_motion(self, d2: float) -> None:
        """Add one frame's squared velocity disagreement."""
        self.n += 1
        self.d2 += d2


@dataclass
class BindingStats:
    """Counters of the identity stage (reported)."""

    losses: int = 0
    bindings: int = 0
    checkpoint_bindings: int = 0
    offline_bindings: int = 0


class IdentityBinder:
    """Online phone-to-track binding with loss detection, and the offline identity passes.

    Args:
        phones: motion of every phone, by MID (empty for the visual-only baseline).
        cfg: the run's configuration.
    """

    def __init__(self, phones: dict[str, PhoneMotion], cfg: VmTrackConfig) -> None:
        self.phones = phones
        self.cfg = cfg
        self.stats = BindingStats()
        self.bound: dict[str, GroundTrack] = {}
        self.candidates: dict[str, dict[str, Candidate]] = defaultdict(dict)
        # whole-log evidence of (never-bound phone, track) agreement, for the offline resolution
        self.evidence: dict[str, dict[str, Candidate]] = defaultdict(dict)
        self.by_vid: dict[str, GroundTrack] = {}
        self.disagreement: dict[str, list[float]] = defaultdict(list)
        self.visual_disagreement: dict[str, list[float]] = defaultdict(list)
        self.pending_rssi: list[RssiScan] = []

    # -- queries --------------------------------------------------------------------------------
    def velocity(self, mid: str | None, t_ns: int) -> np.ndarray | None:
        """The phone's walking velocity at ``t_ns`` (None: no such phone or outside its span)."""
        p = self.phones.get(mid) if mid else None
        return None if p is None else p.velocity_at(t_ns)

    def owner(self, trk: GroundTrack) -> str | None:
        """The MID bound to ``trk`` now, if any."""
        return next((m for m, tr in self.bound.items() if tr is trk), None)

    def owners(self) -> dict[int, str]:
        """``id(track) -> MID`` of every bound track."""
        return {id(tr): m for m, tr in self.bound.items()}

    # -- online ---------------------------------------------------------------------------------
    def release(self, mid: str) -> None:
        """The bound track of ``mid`` was retired (lost for too long)."""
        del self.bound[mid]
        self.stats.losses += 1

    def _bind_track(self, mid: str, trk: GroundTrack, t_ns: int) -> None:
        self.bound[mid] = trk
        if trk.first_mid is None:
            trk.first_mid, trk.first_bound_ns = mid, t_ns

    def step(self, t_ns: int, tracks: Sequence[GroundTrack]) -> None:
        """One frame of the identity stage, after the tracks were updated with ``t_ns``'s
        detections: check-points, RSSI evidence, loss detection, candidate filtering, binding."""
        free = [
            trk
            for trk in tracks
            if trk.state is TrackState.TRACKED
            and trk.last_hit_ns == t_ns
            and trk not in self.bound.values()
        ]
        self._checkpoints(t_ns, free)
        self._rssi_evidence(free)
        self.pending_rssi.clear()
        self._detect_losses(t_ns, free)
        wants = {}
        for mid in self.phones:
            if mid not in self.bound:
                choice = self._filter_candidates(mid, t_ns, free)
                if choice is not None:
                    wants[mid] = choice
        self._assign(t_ns, free, wants)

    def _checkpoints(self, t_ns: int, free: list[GroundTrack]) -> None:
        """A phone heard very strongly by an AP belongs to the person next to it."""
        cfg = self.cfg
        for scan in self.pending_rssi:
            if scan.observer_position_m is None:
                continue
            ap = np.array([scan.observer_position_m.x, scan.observer_position_m.y])
            for reading in scan.readings:
                mid = reading.eid
                if (
                    mid in self.bound
                    or mid not in self.phones
                    or reading.rssi_dbm < cfg.checkpoint_dbm
                ):
                    continue
                near = [
                    trk for trk in free if np.linalg.norm(trk.xy - ap) < cfg.checkpoint_radius_m
                ]
                if len(near) == 1:
                    self._bind_track(mid, near[0], t_ns)
                    free.remove(near[0])
                    self.candidates.pop(mid, None)
                    self.stats.bindings += 1
                    self.stats.checkpoint_bindings += 1

    def _rssi_evidence(self, free: list[GroundTrack]) -> None:
        """RSSI evidence for the candidate filter: people walking side by side move alike, but
        the one nearer an AP is heard louder (log-distance path loss with shadowing)."""
        cfg = self.cfg
        for scan in self.pending_rssi:
            if scan.observer_position_m is None:
                continue
            ap = np.array([scan.observer_position_m.x, scan.observer_position_m.y])
            near = [trk for trk in free if np.linalg.norm(trk.xy - ap) < cfg.rssi_evidence_m]
            for reading in scan.readings:
                mid = reading.eid
                if mid in self.bound or mid not in self.phones:
                    continue
                for trk in near:
                    d = max(0.3, float(np.linalg.norm(trk.xy - ap)))
                    expect = cfg.rssi_at_1m_dbm - 10 * cfg.path_loss_exponent * math.log10(d)
                    z2 = ((reading.rssi_dbm - expect) / cfg.shadowing_db) ** 2
                    self.candidates[mid].setdefault(trk.vid, Candidate()).add_rssi(z2)
                    if trk.first_mid is None:
                        self.evidence[mid].setdefault(trk.vid, Candidate()).add_rssi(z2)
                        self.by_vid[trk.vid] = trk

    def _detect_losses(self, t_ns: int, free: Sequence[GroundTrack] = ()) -> None:
        """A bound track whose motion keeps disagreeing with its phone, or whose phone stopped
        reporting (its carrier left, or the app was closed), loses its identity.

        Two tests, each over ``bind_frames`` checks. The track's filter velocity (which takes
        the phone's velocity in, so it only drifts away when the detections pull hard), as the
        paper does; and the track's detections alone (:meth:`GroundTrack.visual_velocity`
        against the phone's mean velocity at the same times), which notices a phone bound to
        somebody else. The second needs a gross disagreement (``loss_gross`` times the limit) or
        a better explanation — another unbound track whose detections move with the phone —
        since one person's detections and phone briefly disagree at turns and stops.
        """
        cfg = self.cfg
        limit = (1.6 * cfg.reject_mps) ** 2
        for mid, trk in list(self.bound.items()):
            v = self.velocity(mid, t_ns)
            if v is None:
                del self.bound[mid]
                continue
            if trk.last_hit_ns != t_ns:
                continue
            blended = self.disagreement[mid]
            blended.append(float(np.sum((trk.v - v) ** 2)))
            del blended[: -cfg.bind_frames]
            lost = len(blended) == cfg.bind_frames and float(np.mean(blended)) > limit
            vis = trk.visual_velocity()
            if not lost and vis is not None:
                # the phone's velocity over the same detections' times (turns smooth alike)
                phone = self.phones[mid]
                at = [phone.velocity_at(int(t)) for t in vis[1]]
                v_phone = np.mean([a for a in at if a is not None], axis=0)
                visual = self.visual_disagreement[mid]
                visual.append(float(np.sum((vis[0] - v_phone) ** 2)))
                del visual[: -cfg.bind_frames]
                mean = float(np.mean(visual))
                lost = (
                    len(visual) == cfg.bind_frames
                    and mean > limit
                    and (
                        mean > cfg.loss_gross * limit
                        or self._better_track(phone, free, cfg.loss_better * mean)
                    )
                )
            if lost:
                del self.bound[mid]
                blended.clear()
                self.visual_disagreement[mid].clear()
                self.stats.losses += 1

    @staticmethod
    def _better_track(phone: PhoneMotion, free: Sequence[GroundTrack], below: float) -> bool:
        """Whether an unbound track's detections move with ``phone`` (squared velocity
        disagreement under ``below``) over their last seconds."""
        for trk in free:
            vis = trk.visual_velocity()
            if vis is None:
                continue
            at = [v for v in (phone.velocity_at(int(t)) for t in vis[1]) if v is not None]
            if at and float(np.sum((vis[0] - np.mean(at, axis=0)) ** 2)) < below:
                return True
        return False

    def _filter_candidates(
        self, mid: str, t_ns: int, free: list[GroundTrack]
    ) -> tuple[GroundTrack, float] | None:
        """Candidate filtering of one unbound phone (initialization and loss recovery): the track
        it wants, with its score, once one candidate clearly beats the others."""
        cfg = self.cfg
        v = self.velocity(mid, t_ns)
        if v is None:
            self.candidates.pop(mid, None)
            return None
        cands = self.candidates[mid]
        live = {trk.vid for trk in free}
        for vid in list(cands):
            if vid not in live:
                del cands[vid]
        for trk in free:
            if trk.hits < cfg.converge_hits:
                continue  # its velocity estimate has not converged yet
            d2 = float(np.sum((trk.v - v) ** 2))
            cands.setdefault(trk.vid, Candidate()).add_motion(d2)
            if trk.first_mid is None:
                self.evidence[mid].setdefault(trk.vid, Candidate()).add_motion(d2)
                self.by_vid[trk.vid] = trk
        alive = sorted(
            (
                (c.mean, vid, c)
                for vid, c in cands.items()
                if not (c.n >= 3 and c.mean > cfg.reject_mps**2)
            ),
            key=lambda a: a[0],
        )
        if not alive or alive[0][2].n < cfg.bind_frames:
            return None
        rivals = [a for a in alive[1:] if a[2].n >= 3]
        if not rivals or rivals[0][0] > cfg.ratio * alive[0][0] + 0.02:
            trk = next(t for t in free if t.vid == alive[0][1])
            return trk, alive[0][0]
        return None

    def _assign(
        self, t_ns: int, free: list[GroundTrack], wants: dict[str, tuple[GroundTrack, float]]
    ) -> None:
        """Bind each wanted track to the phone that wants it most."""
        taken: dict[str, tuple[str, float]] = {}
        for mid, (trk, score) in wants.items():
            if trk.vid not in taken or score < taken[trk.vid][1]:
                taken[trk.vid] = (mid, score)
        for vid, (mid, _) in taken.items():
            trk = next(t for t in free if t.vid == vid)
            self._bind_track(mid, trk, t_ns)
            self.candidates.pop(mid, None)
            self.disagreement[mid].clear()
            self.visual_disagreement[mid].clear()
            self.stats.bindings += 1

    # -- offline --------------------------------------------------------------------------------
    def finish(self) -> None:
        """The offline passes: resolve never-bound phones, then back-date every identity."""
        self.stats.offline_bindings = self._resolve_offline()
        for trk in self.by_vid.values():
            self._backdate_identity(trk)
        for m_trk in self.bound.values():
            self._backdate_identity(m_trk)

    def _resolve_offline(self) -> int:
        """Name still-anonymous tracks after phones that were never bound online.

        Online binding waits until one candidate clearly beats the others within a tight gate
        (Theorem 1); in a short visit, or with noisy motion, it may never happen. Offline we know
        every track's whole life: each never-bound phone whose best anonymous track clearly beats
        the runner-up (the online ratio test) and stays within a wider gate takes it, the most
        consistent pairs first; a track goes to at most one phone. The identity then holds back
        along the track as far as its motion agreed with the phone (:meth:`_backdate_identity`).
        """
        cfg, by_vid = self.cfg, self.by_vid
        ever_bound = {trk.first_mid for trk in by_vid.values() if trk.first_mid is not None}
        pairs = []
        for mid, cands in self.evidence.items():
            if mid not in self.phones or mid in ever_bound:
                continue
            scored = sorted(
                (c.mean, vid)
                for vid, c in cands.items()
                if by_vid[vid].first_mid is None and c.n >= cfg.bind_frames
            )
            if not scored or scored[0][0] > cfg.offline_reject_mps**2:
                continue
            if len(scored) > 1 and scored[1][0] <= cfg.ratio * scored[0][0] + 0.02:
                continue  # ambiguous (people walking together): leave the phone unbound
            pairs.append((scored[0][0], mid, scored[0][1]))
        made = 0
        for _, mid, vid in sorted(pairs):
            trk = by_vid[vid]
            if trk.first_mid is not None:
                continue
            trk.first_mid = mid
            trk.first_bound_ns = trk.t_ns + 1  # the identity covers the whole track (back-dated)
            made += 1
        return made

    def _backdate_identity(self, trk: GroundTrack) -> None:
        """Set how far back before its binding a track carries its phone's identity.

        Walking back from the binding, the track's velocity is compared with the phone's over a
        sliding window of ``bind_frames`` frames; where the mean disagreement exceeds the loss
        threshold the track was following somebody else (visual tracks can swap people before a
        phone anchors them), and the identity stops there.
        """
        cfg = self.cfg
        if trk.first_mid is None or trk.first_bound_ns is None or not trk.history:
            return
        phone = self.phones.get(trk.first_mid)
        if phone is None:
            return
        limit = (1.6 * cfg.offline_reject_mps) ** 2  # whole-life evidence: the offline gate
        window: list[float] = []
        start = trk.first_bound_ns
        for t_ns, x, _, _ in reversed(trk.history):
            if t_ns >= trk.first_bound_ns:
                continue
            v = phone.velocity_at(t_ns)
            if v is None:
                break
            window.append(float(np.sum((x[2:, 0] - v) ** 2)))
            del window[: -cfg.bind_frames]
            if len(window) == cfg.bind_frames and float(np.mean(window)) > limit:
                break
            start = t_ns
        trk.identity_from_ns = start
