"""Offline track clean-up: what a published track is, once the whole log has been seen.

The online tracker (:mod:`~trackctl.vmtrack.online`) must coast a track through missed
detections without knowing whether the person comes back, and starts a new track when they
reappear too far from the coasting prediction. Offline we know both ends, so for tracks without
a phone (non-users, and everyone in ``v-af`` mode):

* **coasting tails are not published**: after a track's last detection its positions are pure
  prediction (a ghost walking on where nobody is); coasting *between* detections stays, smoothed;
* **fragments are stitched**: a track that ends and one that starts later near where the first
  would have walked become one identity; the links are chosen together by a global one-to-one
  assignment (scipy's ``linear_sum_assignment``) over a motion-gated cost, and the gap between
  them is filled by linear interpolation (published as ``predicted``);
* **short tracks are dropped**: an identity with fewer than ``min_hits`` detections in all is
  clutter (a car boot, a shadow), not a person;
* **recurring static clutter is dropped**: never-moving tracks that keep being born at one spot
  (``clutter_min``) are a poster or a plant the detector fires on.

Tracks bound to a phone keep the identity stage's decisions (their coasting is the paper's
motion-sensor prediction and is published).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.tracker import GroundTrack

__all__ = ["StitchConfig", "Tracklet", "stitch", "Publication", "plan_publication"]


@dataclass(frozen=True, slots=True)
class StitchConfig:
    """Offline clean-up parameters (metres, seconds)."""

    enabled: bool = True
    max_gap_s: float = 4.0
    """Longest gap between a track's end and another's start that may be the same person."""
    gate_m: float = 1.0
    """Distance allowed between the extrapolated end and the start, on top of ``speed_sigma``."""
    speed_sigma_mps: float = 0.5
    """Growth of the allowed distance with the gap (walking speed uncertainty)."""
    min_hits: int = 5
    """Identities with fewer detections than this are dropped."""
    min_motion_m: float = 0.7
    """Identities that never get this far from where they were first seen are dropped: a
    poster, a plant, or floor revealed where the starting background held a person."""
    publish_coasting_tails: bool = False
    """Publish positions after a track's last detection (the online prediction)."""
    clutter_radius_m: float = 0.5
    clutter_hold_s: float = 2.0
    """A track whose detections stay at a clutter spot this long either side is parked there."""
    clutter_min: int = 3
    """Clutter spots (see :func:`_clutter_spots`): a track parked at one is not published
    there. A person standing still makes one or two never-moving tracks, not a recurring spot
    (but one standing at a poster for a while is hidden with it)."""


@dataclass(frozen=True, slots=True)
class Tracklet:
    """A track reduced to what stitching needs: its first and last detected states."""

    key: int
    hits: int
    first_ns: int
    last_ns: int
    first_xy: np.ndarray
    last_xy: np.ndarray
    first_v: np.ndarray
    last_v: np.ndarray
    moved_m: float = np.inf


def _link_cost(a: Tracklet, b: Tracklet, cfg: StitchConfig) -> float:
    """Normalised squared miss distance of ``b`` continuing ``a`` (inf when gated out): the
    least of ``a`` walking on, ``b`` walking back, and the person having stood still."""
    gap = (b.first_ns - a.last_ns) / 1e9
    if not 0 < gap <= cfg.max_gap_s:
        return np.inf
    # both extrapolations (a forward, b backward), capped at a brisk walk each way
    va = a.last_v * min(1.0, 2.0 / max(1e-9, float(np.linalg.norm(a.last_v))))
    vb = b.first_v * min(1.0, 2.0 / max(1e-9, float(np.linalg.norm(b.first_v))))
    fwd = float(np.linalg.norm(a.last_xy + va * gap - b.first_xy))
    back = float(np.linalg.norm(b.first_xy - vb * gap - a.last_xy))
    still = float(np.linalg.norm(b.first_xy - a.last_xy))  # people stop, too
    miss = min(fwd, back, still)
    allowed = cfg.gate_m + cfg.speed_sigma_mps * gap
    if miss > allowed:
        return np.inf
    return (miss / allowed) ** 2 + 0.05 * gap


def stitch(tracklets: Sequence[Tracklet], cfg: StitchConfig) -> dict[int, int]:
    """Chain head of every tracklet (its own key when not continued from another).

    Links are one-to-one (an end continues into at most one start and vice versa) and chosen
    together to minimise the summed cost.
    """
    heads = {t.key: t.key for t in tracklets}
    if not cfg.enabled or len(tracklets) < 2:
        return heads
    big = 1e6
    cost = np.full((len(tracklets), len(tracklets)), big)
    for i, a in enumerate(tracklets):
        for j, b in enumerate(tracklets):
            if i != j:
                c = _link_cost(a, b, cfg)
                if np.isfinite(c):
                    cost[i, j] = c
    rows, cols = linear_sum_assignment(cost)
    nxt = {
        tracklets[i].key: tracklets[j].key
        for i, j in zip(rows, cols, strict=True)
        if cost[i, j] < big
    }
    prev = {b: a for a, b in nxt.items()}
    for t in tracklets:
        if t.key in prev:
            continue
        k = t.key
        seen = {k}
        while k in nxt and nxt[k] not in seen:  # links go forward in time: no cycles
            k = nxt[k]
            seen.add(k)
            heads[k] = t.key
    return heads


@dataclass
class Publication:
    """What the writer publishes for visual-only tracks (the result of the clean-up)."""

    name: dict[int, str]
    """Published id of a track (by track key): its chain head's visual id."""
    hidden: set[tuple[int, int]]
    """(track key, frame ns) rows not published (coasting tails, dropped identities)."""
    fills: dict[int, list[tuple[str, np.ndarray, np.ndarray]]]
    """Frame ns -> (id, position, velocity) interpolated across stitched gaps."""
    dropped: int = 0
    """Identities dropped as too short."""
    links: int = 0
    """Fragments joined to an earlier one."""
    head: dict[int, int] = field(default_factory=dict)
    """Chain head (key of its first track) of every track in the plan."""
    head_of_name: dict[str, int] = field(default_factory=dict)
    """Chain head of every published name."""


def _clutter_spots(
    tracks: dict[int, GroundTrack], cfg: StitchConfig, deaths: np.ndarray | None = None
) -> np.ndarray:
    """Places where never-moving tracks keep appearing: a poster or a plant the detector fires
    on, whose tracks break and restart all day (and capture passers-by's tracks when their
    detections miss). Evidence: tracks whose first two or more detections stayed at their
    birth place, and ``deaths`` (where tracks that never moved died during tracking); a spot
    is an evidence point with ``clutter_min`` others within ``clutter_radius_m``."""
    r2 = cfg.clutter_radius_m**2
    stayed = []
    for trk in tracks.values():
        if trk.born_xy is None or len(trk.hits_log) < 2:
            continue
        first = np.array(trk.hits_log[:2], float)[:, 1:]
        if np.all(np.sum((first - trk.born_xy) ** 2, axis=1) <= r2):
            stayed.append(trk.born_xy)
    pts = [np.array(stayed, float).reshape(-1, 2)]
    if deaths is not None:
        pts.append(np.asarray(deaths, float).reshape(-1, 2))
    evidence = np.vstack(pts)
    if len(evidence) <= cfg.clutter_min:
        return np.empty((0, 2))
    near = cKDTree(evidence).query_ball_point(evidence, cfg.clutter_radius_m)
    counts = np.array([len(n) - 1 for n in near])
    return evidence[counts >= cfg.clutter_min]


def _parked_at_clutter(
    trk: GroundTrack, times: np.ndarray, spots: cKDTree | None, cfg: StitchConfig
) -> np.ndarray:
    """Per time in ``times``: the track sits at a clutter spot (every detection within
    ``clutter_hold_s`` around it is at a spot)."""
    if spots is None or not trk.hits_log:
        return np.zeros(len(times), bool)
    hits = np.array(trk.hits_log, float)
    d, _ = spots.query(hits[:, 1:])
    away = np.concatenate([[0], np.cumsum(d > cfg.clutter_radius_m)])
    half = cfg.clutter_hold_s * 1e9
    lo = np.searchsorted(hits[:, 0], times - half, side="left")
    hi = np.searchsorted(hits[:, 0], times + half, side="right")
    return (hi > lo) & (away[hi] - away[lo] == 0)


def _gap_fills(
    frames: Sequence[FrameOut],
    tracklets: Sequence[Tracklet],
    heads: dict[int, int],
    dropped: set[int],
    name: dict[int, str],
) -> tuple[dict[int, list[tuple[str, np.ndarray, np.ndarray]]], int]:
    """Positions interpolated across the gaps of every stitched chain, by frame; and the
    number of links."""
    times = [fr.t_ns for fr in frames]
    fills: dict[int, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    members: dict[int, list[Tracklet]] = {}
    for tl in tracklets:
        members.setdefault(heads[tl.key], []).append(tl)
    links = 0
    for head, chain in members.items():
        if head in dropped:
            continue
        chain.sort(key=lambda t: t.first_ns)
        for a, b in zip(chain, chain[1:], strict=False):
            links += 1
            span = (b.first_ns - a.last_ns) / 1e9
            v = (b.first_xy - a.last_xy) / span
            lo = int(np.searchsorted(times, a.last_ns, side="right"))
            hi = int(np.searchsorted(times, b.first_ns, side="left"))
            for t_ns in times[lo:hi]:
                w = (t_ns - a.last_ns) / (b.first_ns - a.last_ns)
                xy = (1 - w) * a.last_xy + w * b.first_xy
                fills.setdefault(t_ns, []).append((name[head], xy, v))
    return fills, links


def _candidate_rows(
    frames: Sequence[FrameOut], all_tracks: bool
) -> tuple[dict[int, list[tuple[int, int]]], dict[int, GroundTrack]]:
    """(frame ns, row key) of every track the clean-up plans, by track key; and the tracks."""
    rows: dict[int, list[tuple[int, int]]] = {}
    tracks: dict[int, GroundTrack] = {}
    for fr in frames:
        for trk, mid_now, _, k in fr.rows:
            if all_tracks or (mid_now is None and trk.first_mid is None):
                rows.setdefault(trk.key, []).append((fr.t_ns, k))
                tracks[trk.key] = trk
    return rows, tracks


def _hide_tail_and_parked(
    key: int,
    seq: list[tuple[int, int]],
    trk: GroundTrack,
    spot_tree: cKDTree | None,
    cfg: StitchConfig,
    hidden: set[tuple[int, int]],
) -> list[tuple[int, int]]:
    """The rows of ``seq`` not parked at clutter; adds the coasting tail (unless published)
    and the parked rows to ``hidden``."""
    last_hit = trk.hit_ns[-1]
    if not cfg.publish_coasting_tails:
        hidden.update((key, t) for t, _ in seq if t > last_hit)
    parked = _parked_at_clutter(trk, np.array([t for t, _ in seq], float), spot_tree, cfg)
    if not parked.any():
        return seq
    hidden.update((key, t) for (t, _), p in zip(seq, parked, strict=True) if p)
    return [row for row, p in zip(seq, parked, strict=True) if not p]


def _tracklet(
    key: int,
    seq: list[tuple[int, int]],
    trk: GroundTrack,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
) -> Tracklet:
    """The tracklet of a track's rows ``seq``: from its first to its last detected row (its
    first row when none is), states from ``positions`` (else the filter's state)."""
    last_hit = trk.hit_ns[-1]
    shown = [(t, k) for t, k in seq if t <= last_hit] or seq[:1]

    def state(t_k: tuple[int, int]) -> np.ndarray:
        est = positions.get((trk.key, t_k[1]))
        return trk.kf.x[:, 0] if est is None else est[0]

    s0, s1 = state(shown[0]), state(shown[-1])
    hits = sum(1 for t in trk.hit_ns if shown[0][0] <= t <= shown[-1][0])
    return Tracklet(
        key, hits, shown[0][0], shown[-1][0], s0[:2], s1[:2], s0[2:4], s1[2:4], trk.moved_m
    )


def _short_or_still_chains(
    tracklets: Sequence[Tracklet], heads: dict[int, int], cfg: StitchConfig
) -> set[int]:
    """Chain heads whose chain has fewer than ``min_hits`` detections or never got
    ``min_motion_m`` from where it started."""
    chain_hits: dict[int, int] = {}
    chain_moved: dict[int, float] = {}
    chain_start: dict[int, np.ndarray] = {}
    for t in sorted(tracklets, key=lambda tl: tl.first_ns):
        h = heads[t.key]
        chain_hits[h] = chain_hits.get(h, 0) + t.hits
        start = chain_start.setdefault(h, t.first_xy)
        far = max(t.moved_m, float(np.linalg.norm(t.last_xy - start)))
        chain_moved[h] = max(chain_moved.get(h, 0.0), far)
    return {
        h for h, n in chain_hits.items() if n < cfg.min_hits or chain_moved[h] < cfg.min_motion_m
    }


def _chain_heads(
    keys: Iterable[int], tracklets: Sequence[Tracklet], cfg: StitchConfig
) -> tuple[dict[int, int], set[int]]:
    """Chain head of every planned track (stitched when enabled; a track left without a
    tracklet, all its rows at clutter, heads itself); and those clutter tracks."""
    clutter = {key for key in keys if key not in {t.key for t in tracklets}}
    heads = stitch(tracklets, cfg) if cfg.enabled else {t.key: t.key for t in tracklets}
    heads.update({key: key for key in clutter})
    return heads, clutter


def plan_publication(
    frames: Sequence[FrameOut],
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    cfg: StitchConfig,
    all_tracks: bool = False,
    static_deaths: np.ndarray | None = None,
) -> Publication:
    """Coasting tails, stitched identities and short identities of visual-only tracks (of every
    track with ``all_tracks``: the offline identity stage names them afterwards)."""
    rows, tracks = _candidate_rows(frames, all_tracks)
    hidden: set[tuple[int, int]] = set()
    spots = _clutter_spots(tracks, cfg, static_deaths)
    spot_tree = cKDTree(spots) if len(spots) else None
    tracklets = []
    for key, seq in rows.items():
        kept = _hide_tail_and_parked(key, seq, tracks[key], spot_tree, cfg, hidden)
        if kept:
            tracklets.append(_tracklet(key, kept, tracks[key], positions))
    heads, clutter = _chain_heads(rows, tracklets, cfg)
    name = {key: tracks[heads[key]].vid for key in rows}
    dropped = _short_or_still_chains(tracklets, heads, cfg) | clutter
    for key, seq in rows.items():
        if heads[key] in dropped:
            hidden.update((key, t) for t, _ in seq)
    fills, links = _gap_fills(frames, tracklets, heads, dropped, name)
    head_of_name = {name[h]: h for h in set(heads.values()) if h in name}
    return Publication(name, hidden, fills, len(dropped), links, dict(heads), head_of_name)
