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

import numpy as np

from trackctl.logs.messages import RssiScan, TrackState
from trackctl.vmtrack.align import AlignConfig, Alignment, CandidateTable, PairEvidence, lag_grid
from trackctl.vmtrack.config import BindingConfig
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.tracker import GroundTrack

__all__ = ["IdentityBinder", "BindingStats"]

_RSSI_WEIGHT = 0.05
"""Weight of the chi-square excess of RSSI residuals (expected 1 per reading for the right
person), in units of the rejection threshold's scale so one incompatible AP pass rejects."""


@dataclass
class BindingStats:
    """Counters of the identity stage (reported)."""

    losses: int = 0
    bindings: int = 0
    checkpoint_bindings: int = 0
    offline_bindings: int = 0
    ambiguous_frames: int = 0
    """Frames in which a phone had two or more tracks it could be on and did not guess."""


class IdentityBinder:
    """Online phone-to-track binding with loss detection, and the offline identity passes.

    Phone velocities are compared with tracks through an :class:`~trackctl.vmtrack.align.
    Alignment` (device-to-walk yaw, step scale, clock offset), never assumed: an unbound phone
    with no known alignment scores each candidate track at that pair's best alignment, and
    needs ``bind_frames_free`` frames (turns, stops and pace must single one track out); a
    phone whose alignment is known (it was bound before) scores with it and needs
    ``bind_frames``. A bound phone's alignment is re-fitted from the track's detections.

    Args:
        phones: motion of every phone, by MID (empty for the visual-only baseline).
        cfg: the binding stage's parameters.
        align: the search ranges of each phone's alignment.
        phones_aligned: every phone starts at the identity alignment (the paper's assumption).
        keep_evidence: keep every never-bound phone's whole-log evidence for
            :meth:`finish` (the online identity; the offline identity stage decides on its own).
    """

    def __init__(
        self,
        phones: dict[str, PhoneMotion],
        cfg: BindingConfig,
        align: AlignConfig,
        *,
        phones_aligned: bool = False,
        keep_evidence: bool = False,
    ) -> None:
        self.phones = phones
        self.cfg = cfg
        self.acfg = align
        self.lags = lag_grid(align)
        self._lag_ns = np.round(self.lags * 1e9).astype(np.int64)
        self.stats = BindingStats()
        self.bound: dict[str, GroundTrack] = {}
        self.align: dict[str, Alignment] = {}
        """Alignment of every bound phone (absent: bound, not yet fitted)."""
        self.last_align: dict[str, Alignment] = {}
        """The latest alignment each phone had (re-binding, back-dating, the report)."""
        self.bound_ev: dict[str, PairEvidence] = {}
        self._bound_t: dict[str, int] = {}
        self.candidates: dict[str, CandidateTable] = {}
        # whole-log evidence of (never-bound phone, track) agreement, for the online identity's
        # offline resolution
        self.evidence: dict[str, CandidateTable] | None = {} if keep_evidence else None
        self.by_vid: dict[str, GroundTrack] = {}
        self.disagreement: dict[str, list[float]] = defaultdict(list)
        self.visual_disagreement: dict[str, list[float]] = defaultdict(list)
        self.pending_rssi: list[RssiScan] = []
        self._cache_t: int | None = None
        self._cache: dict[str, np.ndarray] = {}
        if phones_aligned:
            zero = Alignment(1 + 0j, 0.0, len(self.lags) // 2)
            self.last_align.update({mid: zero for mid in phones})

    # -- queries --------------------------------------------------------------------------------
    def phone_lags(self, mid: str, t_ns: int) -> np.ndarray:
        """The phone's raw velocity (complex, device heading) at camera time ``t_ns`` under every
        candidate clock offset; NaN where the phone has no samples."""
        if t_ns != self._cache_t:
            self._cache_t, self._cache = t_ns, {}
        out = self._cache.get(mid)
        if out is None:
            v = self.phones[mid].velocities_at(t_ns + self._lag_ns)
            out = self._cache[mid] = v[:, 0] + 1j * v[:, 1]
        return out

    def _aligned(self, mid: str, t_ns: int, al: Alignment) -> np.ndarray | None:
        v = self.phones[mid].velocities_at(np.array([t_ns + self._lag_ns[al.lag_index]]))[0]
        return None if np.isnan(v).any() else al.apply(complex(v[0], v[1]))

    def streaming(self, mid: str, t_ns: int) -> bool:
        """Whether the phone reports around ``t_ns`` (any clock offset in the search range)."""
        p = self.phones.get(mid)
        return p is not None and bool((~np.isnan(self.phone_lags(mid, t_ns))).any())

    def velocity(self, mid: str | None, t_ns: int) -> np.ndarray | None:
        """The phone's walking velocity at ``t_ns`` in the site frame (its alignment applied);
        None: no such phone, not bound with a fitted alignment, or outside its samples."""
        al = self.align.get(mid) if mid else None
        if mid is None or al is None or mid not in self.bound:
            return None
        z = self.phone_lags(mid, t_ns)[al.lag_index]
        return None if np.isnan(z) else al.apply(complex(z))

    def owner(self, trk: GroundTrack) -> str | None:
        """The MID bound to ``trk`` now, if any."""
        return next((m for m, tr in self.bound.items() if tr is trk), None)

    def owners(self) -> dict[int, str]:
        """``track key -> MID`` of every bound track."""
        return {tr.key: m for m, tr in self.bound.items()}

    # -- online ---------------------------------------------------------------------------------
    def release(self, mid: str) -> None:
        """The bound track of ``mid`` was retired (lost for too long)."""
        self._unbind(mid)
        self.stats.losses += 1

    def _unbind(self, mid: str) -> None:
        del self.bound[mid]
        self.align.pop(mid, None)
        self.bound_ev.pop(mid, None)
        self.disagreement[mid].clear()
        self.visual_disagreement[mid].clear()

    def _bind_track(
        self,
        mid: str,
        trk: GroundTrack,
        t_ns: int,
        ev: PairEvidence | None = None,
        al: Alignment | None = None,
    ) -> None:
        self.bound[mid] = trk
        self.bound_ev[mid] = ev.copy() if ev is not None else PairEvidence(len(self.lags))
        self._bound_t[mid] = t_ns
        if al is not None:
            self.align[mid] = self.last_align[mid] = al
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
        ambiguous = False
        # what every unbound phone compares with, once per frame
        free_vids = {trk.vid for trk in free}
        conv = [trk for trk in free if trk.hits >= self.cfg.converge_hits]  # velocity converged
        z = np.array([complex(trk.kf.x[2, 0], trk.kf.x[3, 0]) for trk in conv])
        for mid in self.phones:
            if mid not in self.bound:
                choice, unsure = self._filter_candidates(mid, t_ns, free, free_vids, conv, z)
                ambiguous |= unsure
                if choice is not None:
                    wants[mid] = choice
        self.stats.ambiguous_frames += ambiguous
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
                    self._bind_track(mid, near[0], t_ns, al=self.last_align.get(mid))
                    free.remove(near[0])
                    self.candidates.pop(mid, None)
                    self.stats.bindings += 1
                    self.stats.checkpoint_bindings += 1

    def _rssi_evidence(self, free: list[GroundTrack]) -> None:
        """RSSI evidence for the candidate filter: people walking side by side move alike, but
        the one nearer an AP is heard louder (log-distance path loss with shadowing)."""
        if not self.pending_rssi or not free:
            return
        xy = np.array([trk.kf.x[:2, 0] for trk in free])
        for scan in self.pending_rssi:
            if scan.observer_position_m is not None:
                self._scan_evidence(scan, free, xy)

    def _scan_evidence(self, scan: RssiScan, free: list[GroundTrack], xy: np.ndarray) -> None:
        """One AP scan's evidence (:meth:`_rssi_evidence`) for the tracks within
        ``rssi_evidence_m`` of the AP, at ground positions ``xy``."""
        cfg = self.cfg
        assert scan.observer_position_m is not None
        ap = np.array([scan.observer_position_m.x, scan.observer_position_m.y])
        dist = np.hypot(xy[:, 0] - ap[0], xy[:, 1] - ap[1])
        idx = np.flatnonzero(dist < cfg.rssi_evidence_m)
        if not len(idx):
            return
        near = [free[i] for i in idx]
        vids = [trk.vid for trk in near]
        anon = [k for k, trk in enumerate(near) if trk.first_mid is None]
        expect = cfg.rssi_at_1m_dbm - 10 * cfg.path_loss_exponent * np.log10(
            np.maximum(0.3, dist[idx])
        )
        for reading in scan.readings:
            mid = reading.eid
            if mid in self.bound or mid not in self.phones:
                continue
            z2 = ((reading.rssi_dbm - expect) / cfg.shadowing_db) ** 2
            self._table(self.candidates, mid).add_rssi(vids, z2)
            if anon and self.evidence is not None:
                self._table(self.evidence, mid).add_rssi([vids[k] for k in anon], z2[anon])
                self.by_vid.update({near[k].vid: near[k] for k in anon})

    def _table(self, tables: dict[str, CandidateTable], mid: str) -> CandidateTable:
        table = tables.get(mid)
        if table is None:
            table = tables[mid] = CandidateTable(len(self.lags))
        return table

    def _refit(self, mid: str, trk: GroundTrack, t_ns: int) -> None:
        """A bound phone's alignment, re-fitted from the track's detections alone (its filter
        state already holds the phone), forgetting over ``align.forget_s``."""
        vis = trk.visual_velocity()
        ev = self.bound_ev[mid]
        dt = (t_ns - self._bound_t.get(mid, t_ns)) / 1e9
        self._bound_t[mid] = t_ns
        ev.decay(math.exp(-max(dt, 0.0) / self.acfg.forget_s))
        if vis is None:
            return
        t_c = int(np.mean(vis[1]))
        zl = self.phones[mid].velocities_at(t_c + self._lag_ns)
        ev.add(complex(vis[0][0], vis[0][1]), zl[:, 0] + 1j * zl[:, 1])
        if ev.frames >= self.cfg.bind_frames:
            al = ev.fit(self.acfg, self.lags)
            if al is not None:
                self.align[mid] = self.last_align[mid] = al

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
            if not self.streaming(mid, t_ns):
                self._unbind(mid)
                continue
            if trk.last_hit_ns != t_ns:
                continue
            self._refit(mid, trk, t_ns)
            v = self.velocity(mid, t_ns)
            al = self.align.get(mid)
            if v is None or al is None:
                continue  # not fitted yet (a check-point binding), or a gap in the samples
            blended = self.disagreement[mid]
            blended.append(float(np.sum((trk.v - v) ** 2)))
            del blended[: -cfg.bind_frames]
            lost = len(blended) == cfg.bind_frames and float(np.mean(blended)) > limit
            vis = trk.visual_velocity()
            if not lost and vis is not None:
                # the phone's velocity over the same detections' times (turns smooth alike)
                v_phone = self._mean_aligned(mid, vis[1], al)
                if v_phone is not None:
                    visual = self.visual_disagreement[mid]
                    visual.append(float(np.sum((vis[0] - v_phone) ** 2)))
                    del visual[: -cfg.bind_frames]
                    mean = float(np.mean(visual))
                    lost = (
                        len(visual) == cfg.bind_frames
                        and mean > limit
                        and (
                            mean > cfg.loss_gross * limit
                            or self._better_track(mid, al, free, cfg.loss_better * mean)
                        )
                    )
            if lost:
                self._unbind(mid)
                self.stats.losses += 1

    def _mean_aligned(self, mid: str, times: np.ndarray, al: Alignment) -> np.ndarray | None:
        v = self.phones[mid].velocities_at(np.asarray(times, np.int64) + self._lag_ns[al.lag_index])
        v = v[~np.isnan(v).any(axis=1)]
        if not len(v):
            return None
        return al.apply(complex(*v.mean(axis=0)))

    def _better_track(
        self, mid: str, al: Alignment, free: Sequence[GroundTrack], below: float
    ) -> bool:
        """Whether an unbound track's detections move with the phone (squared velocity
        disagreement under ``below``) over their last seconds."""
        for trk in free:
            vis = trk.visual_velocity()
            if vis is None:
                continue
            v = self._mean_aligned(mid, vis[1], al)
            if v is not None and float(np.sum((vis[0] - v) ** 2)) < below:
                return True
        return False

    def _filter_candidates(
        self,
        mid: str,
        t_ns: int,
        free: list[GroundTrack],
        free_vids: set[str],
        conv: list[GroundTrack],
        z: np.ndarray,
    ) -> tuple[tuple[GroundTrack, float, PairEvidence, Alignment | None] | None, bool]:
        """Candidate filtering of one unbound phone (initialization and loss recovery): the track
        it wants (with its score, evidence and alignment) once one candidate clearly beats the
        others; and whether it is ambiguous (enough evidence, two or more tracks fit). ``conv``
        are the free tracks whose velocity has converged, ``z`` their velocities (x + iy)."""
        cfg = self.cfg
        zl = self.phone_lags(mid, t_ns)
        if np.isnan(zl).all():
            self.candidates.pop(mid, None)
            return None, False
        cands = self._table(self.candidates, mid)
        cands.keep(free_vids)
        cands.add([trk.vid for trk in conv], z, zl)
        if self.evidence is not None:
            anon = [k for k, trk in enumerate(conv) if trk.first_mid is None]
            self._table(self.evidence, mid).add([conv[k].vid for k in anon], z[anon], zl)
            self.by_vid.update({conv[k].vid: conv[k] for k in anon})
        known = self.last_align.get(mid)
        if known is not None:
            # a phone seen before: its alignment is known (unless its carry changed since)
            pick, unsure = self._pick(cands, free, known, cfg.bind_frames, 3)
            if pick is not None:
                return pick, False
        pick, unsure = self._pick(cands, free, None, cfg.bind_frames_free, cfg.bind_frames)
        return pick, unsure

    def _pick(
        self,
        cands: CandidateTable,
        free: list[GroundTrack],
        known: Alignment | None,
        need: int,
        judge_after: int,
    ) -> tuple[tuple[GroundTrack, float, PairEvidence, Alignment | None] | None, bool]:
        cfg = self.cfg
        if not len(cands):
            return None, False
        score = cands.scores(self.acfg, known) + cands.rssi_penalty(_RSSI_WEIGHT)
        frames = cands.frames()
        alive = np.flatnonzero(~((frames >= judge_after) & (score > cfg.reject_mps**2)))
        order = alive[np.argsort(score[alive], kind="stable")]
        if not len(order) or frames[order[0]] < need:
            return None, False
        rivals = [i for i in order[1:] if frames[i] >= judge_after]
        best = float(score[order[0]])
        if rivals and score[rivals[0]] <= cfg.ratio * best + 0.02:
            return None, True
        vid = cands.vids[order[0]]
        trk = next(t for t in free if t.vid == vid)
        ev = cands.evidence(vid)
        al = known if known is not None else ev.fit(self.acfg, self.lags)
        return (trk, best, ev, al), False

    def _assign(
        self,
        t_ns: int,
        free: list[GroundTrack],
        wants: dict[str, tuple[GroundTrack, float, PairEvidence, Alignment | None]],
    ) -> None:
        """Bind each wanted track to the phone that wants it most."""
        taken: dict[str, tuple[str, float]] = {}
        for mid, (trk, score, _, _) in wants.items():
            if trk.vid not in taken or score < taken[trk.vid][1]:
                taken[trk.vid] = (mid, score)
        for mid, _ in taken.values():
            trk, _, ev, al = wants[mid]
            self._bind_track(mid, trk, t_ns, ev, al)
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
        ever_bound = {trk.first_mid for trk in self.by_vid.values() if trk.first_mid is not None}
        pairs = []
        for mid, cands in (self.evidence or {}).items():
            if mid not in self.phones or mid in ever_bound or not len(cands):
                continue
            best = self._clear_offline_best(cands)
            if best is not None:
                pairs.append((best[0], mid, best[1]))
        made = 0
        for _, mid, vid in sorted(pairs):
            if self.by_vid[vid].first_mid is not None:
                continue
            self._bind_offline(mid, vid)
            made += 1
        return made

    def _clear_offline_best(self, cands: CandidateTable) -> tuple[float, str] | None:
        """(score, VID) of the anonymous track that best fits a phone's whole-log evidence;
        None when it is outside the offline gate or the runner-up fits within ``ratio``."""
        cfg = self.cfg
        score = cands.scores(self.acfg) + cands.rssi_penalty(_RSSI_WEIGHT)
        frames = cands.frames()
        scored = sorted(
            (float(score[i]), vid)
            for i, vid in enumerate(cands.vids)
            if self.by_vid[vid].first_mid is None and frames[i] >= cfg.bind_frames_free
        )
        if not scored or scored[0][0] > cfg.offline_reject_mps**2:
            return None
        if len(scored) > 1 and scored[1][0] <= cfg.ratio * scored[0][0] + 0.02:
            return None  # ambiguous (people walking together): leave the phone unbound
        return scored[0]

    def _bind_offline(self, mid: str, vid: str) -> None:
        """Give track ``vid`` phone ``mid``'s identity over its whole life, and the phone the
        alignment its evidence on the track fits."""
        trk = self.by_vid[vid]
        trk.first_mid = mid
        trk.first_bound_ns = trk.t_ns + 1  # the identity covers the whole track (back-dated)
        al = (self.evidence or {})[mid].evidence(vid).fit(self.acfg, self.lags)
        if al is not None:
            self.last_align[mid] = al

    def _backdate_identity(self, trk: GroundTrack) -> None:
        """Set how far back before its binding a track carries its phone's identity.

        Walking back from the binding, the track's velocity is compared with the phone's
        (aligned) over a sliding window of ``bind_frames`` frames; where the mean disagreement
        exceeds the loss threshold the track was following somebody else (visual tracks can
        swap people before a phone anchors them), and the identity stops there.
        """
        cfg = self.cfg
        if trk.first_mid is None or trk.first_bound_ns is None or not trk.history:
            return
        al = self.last_align.get(trk.first_mid)
        if trk.first_mid not in self.phones or al is None:
            return
        limit = (1.6 * cfg.offline_reject_mps) ** 2  # whole-life evidence: the offline gate
        window: list[float] = []
        start = trk.first_bound_ns
        for t_ns, x, _, _ in reversed(trk.history):
            if t_ns >= trk.first_bound_ns:
                continue
            v = self._aligned(trk.first_mid, t_ns, al)
            if v is None:
                break
            window.append(float(np.sum((x[2:, 0] - v) ** 2)))
            del window[: -cfg.bind_frames]
            if len(window) == cfg.bind_frames and float(np.mean(window)) > limit:
                break
            start = t_ns
        trk.identity_from_ns = start
