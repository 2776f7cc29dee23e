"""Appearance-free ground-plane tracking with optional motion-sensor fusion (VM-Tracking §3.1.2).

Every track is a constant-velocity Kalman filter (filterpy; a frame steps all tracks at once
with :func:`predict_many` and :func:`update_many`) over (x, y, vx, vy) in the world
frame. A track bound to a phone (MID) also takes the phone's PDR velocity as a measurement, and is
associated with detections by the paper's fused probability

    p_ij = q_ij ** (sv2 / (sv2 + sm2)) * r_ij ** (sm2 / (sv2 + sm2))

where q_ij is the likelihood of detection j under the visual-only prediction (variance sv2) and
r_ij under the motion-sensor prediction (variance sm2). Assignment is global and one-to-one
(scipy's Hungarian solver) with a probability gate. Tracks that are not bound to a phone (non-users,
and everyone in V-AF mode) are associated by q_ij alone. The probabilities are the injected
cost's (:mod:`~trackctl.vmtrack.cost`: :class:`~trackctl.vmtrack.cost.VisualMotionCost` is
this fusion, :class:`~trackctl.vmtrack.cost.VisualCost` q_ij alone).
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from filterpy.kalman import KalmanFilter
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from trackctl.logs.messages import TrackState
from trackctl.vmtrack.cost import AssociationCost

__all__ = [
    "TrackerConfig",
    "GroundTrack",
    "associate",
    "merge_detections",
    "merge_with_covariance",
]


@dataclass(frozen=True, slots=True)
class TrackerConfig:
    """Tracker parameters (metres, seconds)."""

    det_sigma_m: float = 0.28
    """Per-axis std of a detection's ground point (0.35 m mean error = 0.28 m per axis)."""
    accel_sigma_mps2: float = 1.0
    """Process noise: white acceleration of a walking person."""
    pdr_sigma_mps: float = 0.25
    """Std of the phone's PDR velocity, per axis."""
    gate_p: float = 1e-3
    """Associations with a fused probability below this are not made."""
    confirm_hits: int = 3
    drop_unbound_after_s: float = 2.0
    lose_bound_after_s: float = 6.0


_H_POS = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
_H_VEL = np.array([[0, 0, 1.0, 0], [0, 0, 0, 1.0]])
_H_POS.flags.writeable = False
_H_VEL.flags.writeable = False


@lru_cache(maxsize=64)
def _transition(dt: float, accel_sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity transition and white-acceleration process noise over ``dt`` (state
    x, y, vx, vy); cached, since every track of a frame steps by the same ``dt``."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    s2 = accel_sigma**2
    pp, pv, vv = dt**4 / 4 * s2, dt**3 / 2 * s2, dt**2 * s2
    q = np.array([[pp, 0, pv, 0], [0, pp, 0, pv], [pv, 0, vv, 0], [0, pv, 0, vv]])
    f.flags.writeable = False
    q.flags.writeable = False
    return f, q


def predict_many(
    x: np.ndarray, p: np.ndarray, dts: np.ndarray, accel_sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity predictions of many tracks at once: states ``x`` (n, 4, 1), covariances
    ``p`` (n, 4, 4), steps ``dts`` (n,) seconds.

    filterpy's ``KalmanFilter.predict`` equations, batched with numpy's stacked matmul:
    filterpy has no batched filter, and one call per track (6 us to predict, 18 us to update,
    measured) for every track of every frame was most of a crowd's frame time."""
    # the tracks of a frame share one or two steps: each distinct one is the cached transition
    steps, which = np.unique(dts, return_inverse=True)
    fq = [_transition(float(dt), accel_sigma) for dt in steps]
    f = np.stack([a for a, _ in fq])[which]
    q = np.stack([b for _, b in fq])[which]
    return f @ x, (f @ p) @ f.transpose(0, 2, 1) + q


def update_many(
    x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray, h: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Kalman updates of many tracks at once: filterpy's ``KalmanFilter.update`` equations
    (Joseph form), batched as :func:`predict_many`. ``z`` (n, 2, 1), ``r`` (n, 2, 2), ``h``
    (2, 4)."""
    y = z - h @ x
    pht = p @ h.T
    k = pht @ np.linalg.inv(h @ pht + r)
    i_kh = np.eye(4) - k @ h
    return x + k @ y, (i_kh @ p) @ i_kh.transpose(0, 2, 1) + (k @ r) @ k.transpose(0, 2, 1)


@dataclass
class GroundTrack:
    """One tracked person on the ground plane."""

    vid: str
    kf: KalmanFilter
    t_ns: int
    key: int = 0
    """The track's serial number in its run: what the stages key their data by."""
    hits: int = 1
    last_hit_ns: int = 0
    state: TrackState = TrackState.TENTATIVE
    first_mid: str | None = None
    """The phone this track was first bound to; offline, it names the track from its birth."""
    first_bound_ns: int | None = None
    identity_from_ns: int = 0
    """Offline: from when before its binding the track carries ``first_mid``."""
    history: list[tuple[int, np.ndarray, np.ndarray, bool]] = field(default_factory=list)
    hit_ns: list[int] = field(default_factory=list)
    """Times of the frames in which a detection corrected this track."""
    recent: deque[tuple[int, float, float]] = field(default_factory=lambda: deque(maxlen=16))
    """The last detections this track took (time, x, y): its visual-only evidence."""
    hits_log: list[tuple[int, float, float]] = field(default_factory=list)
    """Every detection this track took (time, x, y): the offline identity stage's evidence."""
    born_xy: np.ndarray | None = None
    moved_m: float = 0.0
    """Farthest the track's corrected position has been from where it was born: a track that
    never moves is clutter or a ghost (revealed background), not a person who walked there."""

    @classmethod
    def start(
        cls,
        vid: str,
        xy: np.ndarray,
        t_ns: int,
        cfg: TrackerConfig,
        cov: np.ndarray | None = None,
        key: int = 0,
    ) -> GroundTrack:
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.x = np.array([[xy[0]], [xy[1]], [0.0], [0.0]])
        kf.P = np.diag([cfg.det_sigma_m**2] * 2 + [1.0, 1.0])
        if cov is not None:
            kf.P[:2, :2] = cov
        kf.H = _H_POS.copy()
        kf.R = np.eye(2) * cfg.det_sigma_m**2
        return cls(
            vid,
            kf,
            t_ns,
            key=key,
            last_hit_ns=t_ns,
            hit_ns=[t_ns],
            born_xy=np.array(xy[:2], float),
            hits_log=[(t_ns, float(xy[0]), float(xy[1]))],
        )

    @property
    def xy(self) -> np.ndarray:
        return self.kf.x[:2, 0].copy()

    @property
    def v(self) -> np.ndarray:
        return self.kf.x[2:, 0].copy()

    def visual_velocity(
        self, window_s: float = 2.5, min_hits: int = 4
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Velocity from the detections alone (least-squares slope of the last ``window_s`` of
        hits) and the hit times it spans (ns), None with fewer than ``min_hits``. A track bound to
        a phone also takes the phone's velocity into its filter state, so only this can tell
        that the phone left it."""
        if len(self.recent) < min_hits:
            return None
        pts = np.array(self.recent, float)
        pts = pts[pts[:, 0] >= pts[-1, 0] - window_s * 1e9]
        if len(pts) < min_hits:
            return None
        t = (pts[:, 0] - pts[:, 0].mean()) / 1e9
        den = float(np.sum(t * t))
        if den <= 0:
            return None
        slope = np.array(
            [np.sum(t * (pts[:, 1] - pts[:, 1].mean())), np.sum(t * (pts[:, 2] - pts[:, 2].mean()))]
        )
        return slope / den, pts[:, 0].astype(np.int64)

    def transition(self, dt: float, cfg: TrackerConfig) -> tuple[np.ndarray, np.ndarray]:
        """Transition and process noise over ``dt`` (read-only arrays)."""
        return _transition(dt, cfg.accel_sigma_mps2)

    def predicted(self, dt: float, cfg: TrackerConfig) -> tuple[np.ndarray, float]:
        """Visual-only prediction of the position and its per-axis variance."""
        f, q = self.transition(dt, cfg)
        x = f @ self.kf.x
        p = f @ self.kf.P @ f.T + q
        return x[:2, 0], float(np.trace(p[:2, :2]) / 2)

    def motion_predicted(
        self, dt: float, v_m: np.ndarray, pdr_sigma_mps: float
    ) -> tuple[np.ndarray, float]:
        """Motion-sensor prediction: last position + PDR velocity x dt (its std
        ``pdr_sigma_mps`` per axis)."""
        var = float(np.trace(self.kf.P[:2, :2]) / 2) + (pdr_sigma_mps * dt) ** 2
        return self.xy + v_m * dt, var

    def advance(self, t_ns: int, cfg: TrackerConfig, v_m: np.ndarray | None) -> None:
        """Predict to ``t_ns``, fusing the PDR velocity first when the track has a phone."""
        dt = (t_ns - self.t_ns) / 1e9
        f, q = self.transition(dt, cfg)
        if v_m is not None:
            self.kf.update(v_m.reshape(2, 1), R=np.eye(2) * cfg.pdr_sigma_mps**2, H=_H_VEL)
        self.kf.predict(F=f, Q=q)
        self.t_ns = t_ns

    def correct(self, xy: np.ndarray, cov: np.ndarray | None = None) -> None:
        """Update with a ground point; ``cov`` is its 2x2 covariance (None: ``det_sigma_m``)."""
        self.kf.update(np.asarray(xy, float).reshape(2, 1), R=cov)
        self.took(xy)

    def took(self, xy: np.ndarray) -> None:
        """Record a detection the filter has just been corrected with (its evidence, how far the
        track has moved from its birth)."""
        x, y = float(xy[0]), float(xy[1])
        hit = (self.t_ns, x, y)
        self.recent.append(hit)
        self.hits_log.append(hit)
        if self.born_xy is not None:
            st = self.kf.x
            d = math.hypot(float(st[0, 0]) - self.born_xy[0], float(st[1, 0]) - self.born_xy[1])
            self.moved_m = max(self.moved_m, d)


def associate(
    tracks: list[GroundTrack],
    dets: np.ndarray,
    dt: list[float],
    v_m: list[np.ndarray | None],
    cfg: TrackerConfig,
    cost: AssociationCost,
    covs: np.ndarray | None = None,
    predicted: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[list[tuple[int, int, float]], list[int], list[int]]:
    """Global one-to-one association of tracks and detections, scored by ``cost``.

    ``covs`` (N, 2, 2) are the detections' ground covariances (from the camera geometry); None
    takes ``det_sigma_m`` for every detection. ``predicted`` are the tracks' visual-only
    predicted positions (n, 2) and per-axis variances (n,) when the caller has them. The
    probabilities of all pairs are the cost's (computed at once); the assignment is scipy's
    Hungarian solver, gated by the cost's ``gate_p``.

    Returns:
        (track index, detection index, probability) pairs, unmatched track and detection indices.
    """
    if not tracks or len(dets) == 0:
        return [], list(range(len(tracks))), list(range(len(dets)))
    if covs is None:
        covs = np.broadcast_to(np.eye(2) * cfg.det_sigma_m**2, (len(dets), 2, 2))
    pred = predicted if predicted is not None else _visual_predictions(tracks, dt, cfg)
    prob = cost.probabilities(tracks, dets, covs, pred, dt, v_m)
    pairs = _gated_assignment(prob, cost.gate_p)
    mt = {i for i, _, _ in pairs}
    md = {j for _, j, _ in pairs}
    return (
        pairs,
        [i for i in range(len(tracks)) if i not in mt],
        [j for j in range(len(dets)) if j not in md],
    )


def _visual_predictions(
    tracks: list[GroundTrack], dt: list[float], cfg: TrackerConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Returns the tracks' visual-only predicted positions (n, 2) and per-axis variances (n,)."""
    preds = [trk.predicted(dt[i], cfg) for i, trk in enumerate(tracks)]
    return np.array([p for p, _ in preds]), np.array([v for _, v in preds])


def _gated_assignment(prob: np.ndarray, gate_p: float) -> list[tuple[int, int, float]]:
    """Returns the Hungarian assignment's (track, detection, probability) pairs that pass the
    probability gate."""
    cost = np.where(prob >= gate_p, -np.log(np.maximum(prob, 1e-300)), 1e6)
    rows, cols = linear_sum_assignment(cost)
    return [
        (int(i), int(j), float(prob[i, j]))
        for i, j in zip(rows, cols, strict=True)
        if cost[i, j] < 1e6
    ]


def merge_detections(points: list[tuple[str, np.ndarray]], merge_m: float) -> np.ndarray:
    """Merge detections of one instant seen by several cameras (overlapping views): points from
    different cameras closer than ``merge_m`` are averaged (greedy, nearest pairs first)."""
    return merge_with_covariance(points, None, merge_m)[0]


_Candidate = tuple[float, int, int, int, int]
"""A heap entry of the agglomeration: distance, lower index, higher index, their versions."""


@dataclass(slots=True)
class _Clusters:
    """The agglomeration's clusters, keyed by their first point, as Python numbers: linked
    neighbours, versions (bumped by each merge), cameras as bits, fused centroids (cx, cy),
    information matrices (a, b; b, d) and vectors (s, t)."""

    nb: dict[int, set[int]]
    ver: dict[int, int]
    bits: dict[int, int]
    cx: dict[int, float]
    cy: dict[int, float]
    im: dict[int, tuple[float, float, float]]
    iv: dict[int, tuple[float, float]]

    @classmethod
    def linked(
        cls,
        pairs: np.ndarray,
        cent: np.ndarray,
        sums: np.ndarray,
        info: np.ndarray,
        codes: list[int],
    ) -> _Clusters:
        """Returns one cluster per point that ``pairs`` links, with its neighbours."""
        nb: dict[int, set[int]] = {}
        for i, j in pairs.tolist():
            nb.setdefault(i, set()).add(j)
            nb.setdefault(j, set()).add(i)
        return cls(
            nb,
            dict.fromkeys(nb, 0),
            {i: 1 << codes[i] for i in nb},
            {i: float(cent[i, 0]) for i in nb},
            {i: float(cent[i, 1]) for i in nb},
            {i: (float(info[i, 0, 0]), float(info[i, 0, 1]), float(info[i, 1, 1])) for i in nb},
            {i: (float(sums[i, 0]), float(sums[i, 1])) for i in nb},
        )

    def first_candidates(
        self, pairs: np.ndarray, cent: np.ndarray, merge_m: float
    ) -> list[_Candidate]:
        """Returns the linked pairs of points closer than ``merge_m`` from different cameras,
        as heap entries (all at once)."""
        bits = self.bits
        lo, hi = pairs.min(axis=1), pairs.max(axis=1)
        d0 = np.hypot(cent[lo, 0] - cent[hi, 0], cent[lo, 1] - cent[hi, 1])
        return [
            (d, i, j, 0, 0)
            for d, i, j in zip(d0.tolist(), lo.tolist(), hi.tolist(), strict=True)
            if d < merge_m and not bits[i] & bits[j]  # not one camera's two people
        ]

    def merge(self, a: int, b: int) -> None:
        """Fold cluster ``b`` into ``a``: sum their information, solve for the centroid, join
        their cameras and neighbours."""
        (p, q, r), (p2, q2, r2) = self.im[a], self.im[b]
        (s_, t_), (s2, t2) = self.iv[a], self.iv[b]
        p, q, r, s_, t_ = p + p2, q + q2, r + r2, s_ + s2, t_ + t2
        self.im[a], self.iv[a] = (p, q, r), (s_, t_)
        det = p * r - q * q
        self.cx[a], self.cy[a] = (r * s_ - q * t_) / det, (p * t_ - q * s_) / det  # 2x2 solve
        self.bits[a] |= self.bits[b]
        self.ver[a] += 1
        nb = self.nb
        nb[a] = (nb[a] | nb.pop(b)) - {a, b}
        for k in nb[a]:
            nb[k].discard(b)
            nb[k].add(a)

    def candidates_of(self, a: int, merge_m: float) -> list[_Candidate]:
        """Returns heap entries for the neighbours of cluster ``a`` (ascending) it may merge
        with: closer than ``merge_m`` and seen by none of its cameras."""
        xa, ya, ba, v = self.cx[a], self.cy[a], self.bits[a], self.ver[a]
        out = []
        for k in sorted(self.nb[a]):
            if ba & self.bits[k]:
                continue  # same camera: two people
            d = math.hypot(xa - self.cx[k], ya - self.cy[k])
            if d < merge_m:
                out.append((d, a, k, v, self.ver[k]) if a < k else (d, k, a, self.ver[k], v))
        return out

    def write_back(self, cent: np.ndarray, info: np.ndarray, alive: np.ndarray) -> None:
        """Put the merged clusters' centroids and information matrices into the arrays."""
        for i in self.nb:
            if alive[i] and self.ver[i]:
                cent[i] = self.cx[i], self.cy[i]
                p, q, r = self.im[i]
                info[i] = ((p, q), (q, r))


def _agglomerate(
    pairs: np.ndarray,
    cent: np.ndarray,
    sums: np.ndarray,
    info: np.ndarray,
    codes: list[int],
    alive: np.ndarray,
    merge_m: float,
) -> None:
    """Merge clusters nearest fused centroids first while they share no camera and are closer
    than ``merge_m``; only clusters linked by ``pairs`` (or by their members' pairs) are
    compared. ``codes`` are the points' camera numbers. The arrays are updated in place.

    A heap of candidate distances, entries made stale by a merge skipped by version: each merge
    costs its cluster's neighbours, not all pairs (the merge of a dense crowd seen by six
    cameras is a single linked group of ~100 points). The loop runs on Python numbers (the 2x2
    information solve in closed form), several times cheaper than numpy scalars and LAPACK
    calls one at a time; the clusters' centroids and information go back into the arrays."""
    clusters = _Clusters.linked(pairs, cent, sums, info, codes)
    heap = clusters.first_candidates(pairs, cent, merge_m)
    heapq.heapify(heap)
    while heap:
        _, a, b, va, vb = heapq.heappop(heap)
        if not (alive[a] and alive[b]) or va != clusters.ver[a] or vb != clusters.ver[b]:
            continue
        clusters.merge(a, b)
        alive[b] = False
        for entry in clusters.candidates_of(a, merge_m):
            heapq.heappush(heap, entry)
    clusters.write_back(cent, info, alive)


def merge_with_covariance(
    points: list[tuple[str, np.ndarray]], covs: np.ndarray | None, merge_m: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`merge_detections` with each point's 2x2 covariance: merged points are fused by
    their information (the plain average when no covariances are given, or they are equal).

    Hand-written agglomeration because it needs a cannot-link rule (two detections of one camera
    are two people) that scipy's hierarchical clustering does not take. The two clusters with the
    nearest fused centroids merge first, as long as they share no camera and are closer than
    ``merge_m``. Only points with a neighbour from another camera within ``2 merge_m`` can take
    part (a k-d tree finds them: scipy's ``cKDTree``), and a cluster is compared only with its
    members' such neighbours, through a heap (:func:`_agglomerate`).
    """
    if not points:
        return np.empty((0, 2)), None if covs is None else np.empty((0, 2, 2))
    cam_bit: dict[str, int] = {}
    codes = [cam_bit.setdefault(cam, len(cam_bit)) for cam, _ in points]
    xy = np.array([p for _, p in points], float).reshape(-1, 2)
    info = (
        np.broadcast_to(np.eye(2), (len(xy), 2, 2)).copy() if covs is None else np.linalg.inv(covs)
    )
    sums = np.einsum("nij,nj->ni", info, xy)  # information vectors
    cent = xy.copy()  # fused position of each cluster, kept at the cluster's first point
    alive = np.ones(len(xy), bool)
    if len(cam_bit) > 1 and len(xy) > 1:
        # a fused centroid moves at most half-way to its partner: 2 x merge_m bounds the reach
        pairs = cKDTree(xy).query_pairs(2 * merge_m, output_type="ndarray")
        codes_arr = np.array(codes)
        if len(pairs):
            pairs = pairs[codes_arr[pairs[:, 0]] != codes_arr[pairs[:, 1]]]
        if len(pairs):
            _agglomerate(pairs, cent, sums, info, codes, alive, merge_m)
    idx = np.flatnonzero(alive)
    return cent[idx], None if covs is None else np.linalg.inv(info[idx])
