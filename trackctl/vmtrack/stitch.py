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

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from trackctl.vmtrack.appearance import distance
from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.tracker import GroundTrack

__all__ = [
    "StitchConfig",
    "Tracklet",
    "stitch",
    "reidentify",
    "Publication",
    "plan_publication",
]


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
    reid_max_gap_s: float = 30.0
    """Longest gap across which a track's colours may re-identify it (a person who left the
    view or stood hidden and came back); needs the frames in the log."""
    reid_speed_mps: float = 1.5
    """Walking speed bounding where a re-identified person can be after the gap."""
    reid_max_distance: float = 0.3
    """Most colour difference (Bhattacharyya distance of the signatures) of the same person."""
    reid_margin: float = 0.05
    """The chosen match must be this much closer in colour than the next candidate, either way."""
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


@dataclass(frozen=True, slots=True)
class _Chain:
    """A stitched chain of tracklets as re-identification sees it: its ends and its colours."""

    head: int
    first_ns: int
    last_ns: int
    first_xy: np.ndarray
    last_xy: np.ndarray
    signature: np.ndarray


def _chains(
    tracklets: Sequence[Tracklet], heads: dict[int, int], appearance: Mapping[int, np.ndarray]
) -> list[_Chain]:
    """The chains of ``heads`` whose tracks have a colour signature (their mean)."""
    members: dict[int, list[Tracklet]] = {}
    for t in tracklets:
        members.setdefault(heads[t.key], []).append(t)
    out = []
    for head, chain in members.items():
        sigs = [appearance[t.key] for t in chain if t.key in appearance]
        if not sigs:
            continue
        a = min(chain, key=lambda t: t.first_ns)
        b = max(chain, key=lambda t: t.last_ns)
        out.append(_Chain(head, a.first_ns, b.last_ns, a.first_xy, b.last_xy, np.mean(sigs, 0)))
    return out


def _reid_costs(chains: Sequence[_Chain], cfg: StitchConfig) -> np.ndarray:
    """Colour distance of chain j continuing chain i (inf where it cannot: not after it,
    too long a gap, too far to have walked)."""
    cost = np.full((len(chains), len(chains)), np.inf)
    for i, a in enumerate(chains):
        for j, b in enumerate(chains):
            gap = (b.first_ns - a.last_ns) / 1e9
            if not 0 < gap <= cfg.reid_max_gap_s:
                continue
            reach = cfg.gate_m + cfg.reid_speed_mps * gap
            if float(np.linalg.norm(b.first_xy - a.last_xy)) <= reach:
                cost[i, j] = distance(a.signature, b.signature)
    return cost


def _unambiguous(cost: np.ndarray, i: int, j: int, margin: float) -> bool:
    """True when ``cost[i, j]`` beats every other candidate of its row and column by
    ``margin``."""
    c = cost[i, j]
    row = np.delete(cost[i], j)
    col = np.delete(cost[:, j], i)
    return bool(np.all(row >= c + margin) and np.all(col >= c + margin))


def reidentify(
    tracklets: Sequence[Tracklet],
    heads: dict[int, int],
    appearance: Mapping[int, np.ndarray],
    cfg: StitchConfig,
) -> dict[int, int]:
    """Chain heads after joining chains that the motion gate could not (a gap longer than
    ``max_gap_s``, or a return elsewhere) by their colours. A chain's end continues into
    another's start when their colours are within ``reid_max_distance``, the start is
    reachable from the end at ``reid_speed_mps``, and the pair is ``reid_margin`` closer in
    colour than any other candidate of either chain: the matches are mutual bests, so one to
    one (a global assignment would instead pair up as many chains as it can, ambiguous pairs
    included). Without signatures the heads come back unchanged."""
    chains = _chains(tracklets, heads, appearance)
    if len(chains) < 2:
        return heads
    cost = _reid_costs(chains, cfg)
    nxt: dict[int, int] = {}
    for i, j in zip(*np.nonzero(cost <= cfg.reid_max_distance), strict=True):
        if _unambiguous(cost, i, j, cfg.reid_margin):
            nxt[chains[i].head] = chains[j].head
    root = {c.head: c.head for c in chains}
    for c in sorted(chains, key=lambda c: c.first_ns):
        if c.head in nxt:
            root[nxt[c.head]] = root[c.head]
    return {key: root.get(h, h) for key, h in heads.items()}


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
    reidentified: int | None = None
    """Links (of ``links``) that the tracks' colours made across a gap the motion gate could
    not bridge; None when no track had a colour signature (no frames in the log)."""


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
    max_fill_s: float,
) -> tuple[dict[int, list[tuple[str, np.ndarray, np.ndarray]]], int]:
    """Positions interpolated across the gaps of every stitched chain up to ``max_fill_s``
    long, by frame (a longer gap, re-identified by colour, was out of view: nothing is
    published there); and the number of links."""
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
            if span > max_fill_s:
                continue
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
    keys: Iterable[int],
    tracklets: Sequence[Tracklet],
    cfg: StitchConfig,
    appearance: Mapping[int, np.ndarray],
) -> tuple[dict[int, int], set[int], int | None]:
    """Chain head of every planned track (stitched and re-identified when enabled; a track
    left without a tracklet, all its rows at clutter, heads itself); those clutter tracks;
    and how many chains colour joined to an earlier one (None without colours)."""
    clutter = {key for key in keys if key not in {t.key for t in tracklets}}
    heads = {t.key: t.key for t in tracklets}
    joined = None
    if cfg.enabled:
        moved = stitch(tracklets, cfg)
        heads = reidentify(tracklets, moved, appearance, cfg)
        if appearance:
            joined = len(set(moved.values())) - len(set(heads.values()))
    heads.update({key: key for key in clutter})
    return heads, clutter, joined


def plan_publication(
    frames: Sequence[FrameOut],
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    cfg: StitchConfig,
    all_tracks: bool = False,
    static_deaths: np.ndarray | None = None,
    appearance: Mapping[int, np.ndarray] | None = None,
) -> Publication:
    """Coasting tails, stitched (and, with the tracks' colour ``appearance``, re-identified)
    identities and short identities of visual-only tracks (of every track with
    ``all_tracks``: the offline identity stage names them afterwards)."""
    rows, tracks = _candidate_rows(frames, all_tracks)
    hidden: set[tuple[int, int]] = set()
    spots = _clutter_spots(tracks, cfg, static_deaths)
    spot_tree = cKDTree(spots) if len(spots) else None
    tracklets = []
    for key, seq in rows.items():
        kept = _hide_tail_and_parked(key, seq, tracks[key], spot_tree, cfg, hidden)
        if kept:
            tracklets.append(_tracklet(key, kept, tracks[key], positions))
    heads, clutter, joined = _chain_heads(rows, tracklets, cfg, appearance or {})
    name = {key: tracks[heads[key]].vid for key in rows}
    dropped = _short_or_still_chains(tracklets, heads, cfg) | clutter
    for key, seq in rows.items():
        if heads[key] in dropped:
            hidden.update((key, t) for t, _ in seq)
    fills, links = _gap_fills(frames, tracklets, heads, dropped, name, cfg.max_gap_s)
    head_of_name = {name[h]: h for h in set(heads.values()) if h in name}
    return Publication(name, hidden, fills, len(dropped), links, dict(heads), head_of_name, joined)
