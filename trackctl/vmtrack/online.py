"""Association stage of VM-Tracking: ground-plane detections of one instant -> visual tracks.

:class:`OnlineTracker` runs frame by frame, as the paper's real-time system did: merge the
cameras' detections, associate them with the tracks (motion-sensor prediction for tracks with a
phone), retire lost tracks, start new ones, drop duplicates, then hand the frame to the identity
stage. Every frame's output rows are kept for the offline passes (smoothing, back-dated
identities) that follow.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from trackctl.logs.messages import RssiScan, TrackState
from trackctl.vmtrack.binder import IdentityBinder
from trackctl.vmtrack.config import Identity, Mode, VmTrackConfig
from trackctl.vmtrack.cost import AssociationCost
from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.tracker import (
    GroundTrack,
    associate,
    merge_with_covariance,
    predict_many,
    update_many,
)

__all__ = ["OnlineTracker", "Prediction"]

Prediction = tuple[np.ndarray, float, bool]
"""Where a track can be: ground xy, search radius (m), undetected in the last frame."""


@dataclass(frozen=True, slots=True)
class _VisualPrediction:
    """The tracks' batched visual-only prediction: states and covariances (None without
    tracks) and the positions and per-axis variances the association scores with."""

    x: np.ndarray | None
    p: np.ndarray | None
    scored: tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True, slots=True)
class _FusedMeasurements:
    """One fused measurement per track that took detections: the tracks' indices (ascending),
    the information-weighted mean points and their covariances, row for row."""

    track_idx: list[int]
    xy: np.ndarray
    cov: np.ndarray


def _fuse_measurements(
    given: dict[int, list[int]], xy_all: np.ndarray, covs: np.ndarray | None, det_sigma_m: float
) -> _FusedMeasurements:
    """Returns each track's information-weighted mean of the points its cameras gave it."""
    # all tracks at once: sums of information matrices and vectors by track
    took_idx = sorted(given)
    slot = {i: k for k, i in enumerate(took_idx)}
    det_k = np.array([k for i in took_idx for k in given[i]], int)
    det_slot = np.array([slot[i] for i in took_idx for _ in given[i]], int)
    cov_k = (
        np.broadcast_to(np.eye(2) * det_sigma_m**2, (len(det_k), 2, 2))
        if covs is None
        else covs[det_k]
    )
    info = np.linalg.inv(cov_k)
    info_sum = np.zeros((len(took_idx), 2, 2))
    vec_sum = np.zeros((len(took_idx), 2))
    np.add.at(info_sum, det_slot, info)
    np.add.at(vec_sum, det_slot, np.einsum("nij,nj->ni", info, xy_all[det_k]))
    fused_cov = np.linalg.inv(info_sum) if len(took_idx) else info_sum
    fused = np.einsum("nij,nj->ni", fused_cov, vec_sum)
    return _FusedMeasurements(took_idx, fused, fused_cov)


class OnlineTracker:
    """Frame-by-frame association and track management, with the identity stage plugged in.

    Args:
        cfg: the run's configuration.
        identity: the identity stage (its phones give tracks with a phone their prediction).
        mode: ``vm`` runs the identity stage every frame; ``v-af`` only tracks.
        cost: the association's cost (:mod:`~trackctl.vmtrack.cost`): how likely each track
            is to have made each detection, and the gate.
    """

    def __init__(
        self, cfg: VmTrackConfig, identity: IdentityBinder, mode: Mode, cost: AssociationCost
    ) -> None:
        self.cfg = cfg
        self.acfg = cfg.association
        self.tcfg = cfg.association.tracker
        self.identity = identity
        self.mode = mode
        self.cost = cost
        self.tracks: list[GroundTrack] = []
        self.frames: list[FrameOut] = []
        self.raw_points: dict[int, np.ndarray] = {}
        self.rssi_log: list[RssiScan] = []
        """Every RSSI scan of the log, for the offline re-tracking."""
        self.frame_count = 0
        self.frame_index = 0
        self.seconds = 0.0
        self._next_vid = 0
        # unmatched detections of the current frame, with their covariances
        self._pending_new: list[tuple[np.ndarray, np.ndarray | None]] = []
        # where tracks that never moved died, and when (the clutter map)
        self._static_deaths: deque[tuple[int, float, float]] = deque()
        self.static_death_log: list[tuple[float, float]] = []
        """Every never-moving track's birth place, for the offline clutter rule."""
        self.clutter_suppressed = 0

    @property
    def tracks_started(self) -> int:
        """Tracks started so far (tentative ones included)."""
        return self._next_vid

    def _new_vid(self) -> str:
        self._next_vid += 1
        return f"v{self._next_vid}"

    def process_frame(
        self,
        t_ns: int,
        points: list[tuple[str, np.ndarray]],
        covs: list[np.ndarray] | None = None,
    ) -> None:
        """Update the tracks with one instant's ground points (camera, xy) and, when known, their
        2x2 covariances (from the camera geometry; None: ``det_sigma_m`` for all)."""
        t0 = time.perf_counter()
        self.frame_count += 1
        cov_arr = None if covs is None else np.array(covs, float).reshape(-1, 2, 2)
        self.raw_points[t_ns] = np.array([xy for _, xy in points]).reshape(-1, 2)
        self._associate(t_ns, points, cov_arr)
        self._retire(t_ns)
        self._prune_duplicates()
        if self.mode is Mode.VM:
            self.identity.step(t_ns, self.tracks)
        self._snapshot(t_ns)
        self.seconds += time.perf_counter() - t0

    def _associate(
        self, t_ns: int, points: list[tuple[str, np.ndarray]], covs: np.ndarray | None
    ) -> None:
        """Each camera's detections are assigned to the predicted tracks on their own (one
        detection per track and camera: a camera does not see one person twice); a track then
        takes the information-weighted fusion of what its cameras gave it. Detections no track
        took are merged across cameras into candidates for new tracks.

        Merging the cameras' detections first and then associating the merged points (the
        former design) is blind to the tracks: in a crowd, with each camera's calibration a
        few decimetres off, it fuses two people walking a metre apart into one point between
        them, and the tracks swap on it. Assigned per camera, the tracks' predictions decide
        which detection is whose."""
        tracks = self.tracks
        xy_all = np.array([xy for _, xy in points], float).reshape(-1, 2)
        owner = self.identity.owners()
        v_m = [self.identity.velocity(owner.get(trk.key), t_ns) for trk in tracks]
        dts = [(t_ns - trk.t_ns) / 1e9 for trk in tracks]
        pred = self._predict_visual(dts)
        given, left = self._assign_per_camera(points, xy_all, dts, v_m, covs, pred.scored)
        meas = _fuse_measurements(given, xy_all, covs, self.tcfg.det_sigma_m)
        lost_idx = [i for i in range(len(tracks)) if i not in given]
        rest = [points[k] for k in left]
        dets, new_covs = merge_with_covariance(
            rest, None if covs is None else covs[left], self.acfg.merge_m
        )
        self._step_filters(t_ns, v_m, pred)
        self._correct_with(t_ns, meas)
        for i in lost_idx:
            if tracks[i].state is not TrackState.TENTATIVE:
                tracks[i].state = TrackState.PREDICTED
        self._pending_new = [
            (dets[j], None if new_covs is None else new_covs[j]) for j in range(len(dets))
        ]

    def _predict_visual(self, dts: list[float]) -> _VisualPrediction:
        """Returns every track's visual-only prediction, all filters stepped at once."""
        # every track's filter steps at once (a crowd is many tracks): the visual-only
        # prediction scores the association and is the new state of tracks without a phone
        tracks = self.tracks
        if not tracks:
            return _VisualPrediction(None, None, (np.empty((0, 2)), np.empty(0)))
        x0 = np.stack([trk.kf.x for trk in tracks])
        p0 = np.stack([trk.kf.P for trk in tracks])
        x_pred, p_pred = predict_many(x0, p0, np.array(dts), self.tcfg.accel_sigma_mps2)
        sv2 = (p_pred[:, 0, 0] + p_pred[:, 1, 1]) / 2
        return _VisualPrediction(x_pred, p_pred, (x_pred[:, :2, 0], sv2))

    def _assign_per_camera(
        self,
        points: list[tuple[str, np.ndarray]],
        xy_all: np.ndarray,
        dts: list[float],
        v_m: list[np.ndarray | None],
        covs: np.ndarray | None,
        predicted: tuple[np.ndarray, np.ndarray],
    ) -> tuple[dict[int, list[int]], list[int]]:
        """Returns the detections (indices into ``points``) each track took, camera by camera,
        and the detections no track took."""
        by_cam: dict[str, list[int]] = {}
        for k, (cam, _) in enumerate(points):
            by_cam.setdefault(cam, []).append(k)
        given: dict[int, list[int]] = {}
        left: list[int] = []
        for cam in sorted(by_cam):
            idx = by_cam[cam]
            cam_pairs, _, cam_new = associate(
                self.tracks,
                xy_all[idx],
                dts,
                v_m,
                self.tcfg,
                self.cost,
                None if covs is None else covs[idx],
                predicted,
            )
            for i, j, _ in cam_pairs:
                given.setdefault(i, []).append(idx[j])
            left.extend(idx[j] for j in cam_new)
        return given, left

    def _step_filters(
        self, t_ns: int, v_m: list[np.ndarray | None], pred: _VisualPrediction
    ) -> None:
        """Move every track to ``t_ns``: the visual-only prediction for tracks without a
        phone, the phone's velocity fused first for the others."""
        for i, trk in enumerate(self.tracks):
            # no copies: filterpy's predict and update (and the batched step) assign new state
            # arrays, never write into them
            trk.history.append((trk.t_ns, trk.kf.x, trk.kf.P, False))
            if v_m[i] is None:
                assert pred.x is not None and pred.p is not None
                trk.kf.x, trk.kf.P = pred.x[i], pred.p[i]
                trk.t_ns = t_ns
            else:
                trk.advance(t_ns, self.tcfg, v_m[i])

    def _correct_with(self, t_ns: int, meas: _FusedMeasurements) -> None:
        """Correct the tracks that took detections with their fused measurements (all at
        once), count the hits and confirm tracks with enough of them."""
        pairs = [(i, k) for k, i in enumerate(meas.track_idx)]
        if not pairs:
            return
        took = [self.tracks[i] for i, _ in pairs]
        cols = [j for _, j in pairs]
        x1, p1 = update_many(
            np.stack([trk.kf.x for trk in took]),
            np.stack([trk.kf.P for trk in took]),
            meas.xy[cols][:, :, None],
            meas.cov[cols],
            took[0].kf.H,
        )
        for k, (trk, j) in enumerate(zip(took, cols, strict=True)):
            trk.kf.x, trk.kf.P = x1[k], p1[k]
            trk.took(meas.xy[j])
            trk.hits += 1
            trk.last_hit_ns = t_ns
            trk.hit_ns.append(t_ns)
            if trk.hits >= self.tcfg.confirm_hits:
                trk.state = TrackState.TRACKED

    def _retire(self, t_ns: int) -> None:
        """Drop tentative tracks that missed, and tracks unseen for too long; then start tracks
        on unmatched detections that are not a duplicate view (overlapping cameras) of a track."""
        keep = []
        owner = self.identity.owners()
        for trk in self.tracks:
            mid = owner.get(trk.key)
            if self._is_lost(trk, t_ns, mid):
                self._bury(trk, t_ns, mid)
                continue
            keep.append(trk)
        self.tracks[:] = keep
        memory = int(self.acfg.clutter_memory_s * 1e9)
        while self._static_deaths and self._static_deaths[0][0] < t_ns - memory:
            self._static_deaths.popleft()
        if self._pending_new:
            self._spawn(t_ns, len(keep))

    def _is_lost(self, trk: GroundTrack, t_ns: int, mid: str | None) -> bool:
        """Returns whether the track ends now: tentative and missed, or unseen for longer than
        its limit (longer for a track with a phone)."""
        age = (t_ns - trk.last_hit_ns) / 1e9
        limit = self.tcfg.lose_bound_after_s if mid else self.tcfg.drop_unbound_after_s
        return (trk.state is TrackState.TENTATIVE and trk.last_hit_ns != t_ns) or age > limit

    def _bury(self, trk: GroundTrack, t_ns: int, mid: str | None) -> None:
        """End a track: release its phone; a track that never moved marks its birth place in
        the clutter map."""
        if mid:
            self.identity.release(mid)
        if trk.moved_m < self.acfg.clutter_radius_m and trk.born_xy is not None:
            bx, by = float(trk.born_xy[0]), float(trk.born_xy[1])
            self._static_deaths.append((t_ns, bx, by))
            self.static_death_log.append((float(trk.born_xy[0]), float(trk.born_xy[1])))

    def _spawn(self, t_ns: int, n_kept: int) -> None:
        """Start tracks on the pending detections that are neither a duplicate view of a track
        (the first ``n_kept`` are the surviving ones) nor in clutter."""
        kept = self.tracks[:n_kept]
        tree = cKDTree(np.array([trk.kf.x[:2, 0] for trk in kept])) if kept else None
        deaths = np.array([d[1:] for d in self._static_deaths]).reshape(-1, 2)
        for det, cov in self._pending_new:
            # a detection near a track (or near one started just now) is a duplicate view
            if tree is not None and tree.query_ball_point(det, self.acfg.spawn_m):
                continue
            # a spot where tracks keep being born and dying without moving is clutter (a
            # poster, a plant): no new track there; people walking past keep their own tracks
            if self._in_clutter(det, deaths):
                self.clutter_suppressed += 1
                continue
            if any(
                np.linalg.norm(trk.xy - det) <= self.acfg.spawn_m for trk in self.tracks[n_kept:]
            ):
                continue
            self.tracks.append(
                GroundTrack.start(self._new_vid(), det, t_ns, self.tcfg, cov, key=self._next_vid)
            )

    def _in_clutter(self, det: np.ndarray, deaths: np.ndarray) -> bool:
        """Returns whether enough never-moving tracks died near ``det`` (rows of ``deaths``)."""
        near = np.sum(np.sum((deaths - det) ** 2, axis=1) < self.acfg.clutter_radius_m**2)
        return bool(near >= self.acfg.clutter_min)

    def _prune_duplicates(self) -> None:
        """Two tracks on one person: keep the bound one, else the older one."""
        tracks = self.tracks
        owner = self.identity.owners()
        doomed: set[int] = set()
        if len(tracks) < 2:
            return
        xy = np.array([trk.kf.x[:2, 0] for trk in tracks])
        # only pairs closer than duplicate_m (k-d tree), in the order a full scan would meet them
        pairs = cKDTree(xy).query_pairs(self.acfg.duplicate_m, output_type="ndarray")
        for a, b in sorted(map(tuple, pairs.tolist())):
            ta, tb = tracks[a], tracks[b]
            if ta.key in doomed or tb.key in doomed:
                continue
            if ta.key in owner and tb.key in owner:
                continue  # two phones side by side: both stay
            loser = tb if (ta.key in owner or (tb.key not in owner and ta.hits >= tb.hits)) else ta
            doomed.add(loser.key)
        if doomed:
            tracks[:] = [tr for tr in tracks if tr.key not in doomed]

    def _snapshot(self, t_ns: int) -> None:
        owner = self.identity.owners()
        lead_in = self.cfg.identity is Identity.OFFLINE
        rows = [
            (trk, owner.get(trk.key), _row_state(trk, t_ns), len(trk.history))
            for trk in self.tracks
            if lead_in or trk.state is not TrackState.TENTATIVE
        ]
        self.frames.append(FrameOut(t_ns, rows))

    def close(self) -> None:
        """The log ended: snapshot every live track's final state into its history, and settle
        the frames' rows. Offline, a confirmed track is published from its first detection
        (its *lead-in*: the frames before ``confirm_hits`` made it a track, which the online
        output could not know yet); the rows of tracks that were never confirmed go."""
        for trk in self.tracks:
            trk.history.append((trk.t_ns, trk.kf.x.copy(), trk.kf.P.copy(), True))
        if self.cfg.identity is Identity.OFFLINE:
            need = self.tcfg.confirm_hits
            self.frames = [
                FrameOut(fr.t_ns, [r for r in fr.rows if r[0].hits >= need]) for fr in self.frames
            ]

    # -- search planning for camera frames --------------------------------------------------------
    def predictions(self, t_ns: int, moved_only: bool = False) -> list[Prediction]:
        """Where each live track can be at ``t_ns`` (ground xy, radius m, undetected in the last
        frame): motion sensors for tracks with a phone, the visual velocity otherwise.
        ``moved_only`` keeps the tracks that have walked ``frames.protect_moved_m`` from where
        they were born (people the background must not absorb; not ghosts)."""
        fcfg = self.cfg.frames
        owner = self.identity.owners()
        out = []
        for trk in self.tracks:
            if moved_only and trk.moved_m < fcfg.protect_moved_m and trk.key not in owner:
                continue
            dt = max(0.0, (t_ns - trk.t_ns) / 1e9)
            v = self.identity.velocity(owner.get(trk.key), t_ns)
            sigma = self.tcfg.pdr_sigma_mps if v is not None else fcfg.visual_speed_sigma_mps
            v = trk.v if v is None else v
            var = float(np.trace(trk.kf.P[:2, :2]) / 2) + (sigma * dt) ** 2
            missed = trk.state is not TrackState.TENTATIVE and trk.last_hit_ns != trk.t_ns
            out.append((trk.xy + v * dt, fcfg.region_m + 2.0 * math.sqrt(var), missed))
        return out

    def plan_search(self) -> bool:
        """True for a full search of the next frame: to initialize, and periodically for people
        entering the views; in between only predicted regions. A track that went undetected keeps
        being predicted; its region grows with its uncertainty and is searched at more pyramid
        levels (recovery)."""
        if not self.cfg.frames.predicted or not self.tracks:
            return True
        return self.frame_index % max(1, self.cfg.frames.full_search_every) == 0


def _row_state(trk: GroundTrack, t_ns: int) -> TrackState:
    """A row's published state: a tentative track's row is its lead-in (tracked where it took
    a detection, else predicted)."""
    if trk.state is not TrackState.TENTATIVE:
        return trk.state
    return TrackState.TRACKED if trk.last_hit_ns == t_ns else TrackState.PREDICTED
