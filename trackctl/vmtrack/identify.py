"""Offline identity: which phone each published track carries, decided over the whole log.

The online stage (:mod:`~trackctl.vmtrack.binder`) binds phones as the paper's real-time system
did, frame by frame. Offline we have every track's whole life and every phone's whole motion, so
identity becomes a global problem, solved here in five steps:

1. **Evidence per (phone, track, frame)**: the track's velocity from its *detections alone*
   (a centred least-squares slope over ``velocity_window_s``: never the filter state, which
   holds the phone's velocity once bound) against the phone's PDR velocity, under the best
   alignment (device yaw, step scale, clock offset; :mod:`~trackctl.vmtrack.align`) of a
   centred ``window_s`` window. Without a known alignment, what tells two walkers apart is
   what does not depend on it: pace, stops and starts, turns and their timing.
2. **A path per phone** (Viterbi): at each frame the phone is on one track or on none; staying
   costs the evidence, switching tracks costs ``switch_cost``, being on no track costs
   ``none_cost`` (a track that fits worse than that is not the carrier). Where two chains
   pass within ``encounter_m`` the tracker may have swapped the people (position alone cannot
   tell them apart), so moving the phone between them costs only ``handover_cost``. People walking
   together fit alike for a while; the path keeps the phone where the evidence before and after
   puts it, and frames where two tracks fit within ``ratio`` are counted as ambiguous.
3. **Refinement** (``refine_passes``): from the frames where the path names a track clearly,
   the phone's clock offset and step scale (one each) and its yaw over time are fitted; every
   track is re-scored under that alignment (direction counts again) and the path re-run.
4. **Bridging**: a short gap in the path (``bridge_s``) between two chains that connect (the
   same chain throughout, or a handover where the two are within ``bridge_m``) is the same
   carrier: a person moves continuously, while a fit over a window can fail for a while
   (a chain's first seconds, a merged detection).
5. **Publication**: a stretch on one track with too few clear frames (``min_clear_frames``,
   ``min_clear_share``) is a guess and is not published (the report counts it); where two
   phones' paths meet on one track, the better fit keeps it.

Per phone, the report gives the alignment fitted over all frames it was assigned.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from trackctl.vmtrack.align import AlignConfig, Alignment, PairEvidence, best_fit, lag_grid
from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.stitch import Publication
from trackctl.vmtrack.tracker import GroundTrack

__all__ = ["IdentifyConfig", "Identities", "dead_reckoned", "identify", "visual_velocity"]


@dataclass(frozen=True, slots=True)
class IdentifyConfig:
    """Offline identity parameters (seconds, (m/s)^2 per frame)."""

    window_s: float = 16.0
    """Centred window over which one alignment is fitted per (phone, track) pair."""
    min_window_frames: int = 8
    """Frames of evidence a window needs to score a pair."""
    velocity_window_s: float = 7.0
    """Centred window of detections whose least-squares slope is a track's velocity."""
    min_speed_mps: float = 0.3
    """A window in which track and phone together move slower than this holds no evidence."""
    none_cost: float = 0.2
    """Cost per frame of the phone being on no track: a worse fit is not its carrier (the
    online stage's rejection threshold, 0.45 m/s, squared)."""
    switch_cost: float = 2.0
    """Cost of moving the phone from one live track to another (10 frames at the none cost)."""
    ratio: float = 2.0
    """A frame is ambiguous when another track fits within this factor of the chosen one."""
    min_clear_share: float = 0.1
    """...and this share of its frames (a crowd offers chance clear frames: a stretch that is
    mostly ambiguous is a guess however long it is)."""
    min_clear_frames: int = 1
    """Frames of clear evidence a stretch on one chain needs to be published."""
    refine_passes: int = 2
    """Passes that re-score every chain under the phone's alignment found by the last path."""
    align_window_frames: int = 180
    """A phone's alignment is fitted over this many frames around each frame (30 s at 3 fps:
    it follows a changed carry within seconds of the window, not the noise)."""
    known_window_s: float = 6.0
    """Centred window of the disagreement under a known alignment."""
    yaw_slack_deg: float = 10.0
    """Under a known alignment, a window's yaw may still differ this much from the local fit
    (indoor magnetic disturbance is 10-20 deg)."""
    bridge_s: float = 10.0
    """A gap in a phone's path (on no track) no longer than this is bridged when the chains
    before and after it connect through published chains: the same chain throughout (a person
    does not leave their track and come back to it), or hand-overs between chains within
    ``bridge_m`` of each other (a carrier moves continuously), the fewest and closest."""
    bridge_m: float = 1.0
    encounter_m: float = 1.0
    """Two chains closer than this may have swapped people (no tracker tells two people a
    metre apart by position alone, without appearance)..."""
    handover_cost: float = 0.3
    """...so the phone moves between them for this much (1.5 frames at the none cost) instead
    of ``switch_cost``: after a swap, a few frames of evidence put it back on its carrier."""
    unseen_s: float = 10.0
    """A gap of at most this between two published stretches of a phone is walked on the
    phone's dead reckoning (:func:`_carry_through_unseen`; 0: never)..."""
    unseen_m: float = 1.0
    """...when it ends within this (+ 15 % of the walk) of where the next stretch starts."""
    coast_grace_s: float = 1.0
    coast_cost: float = 0.2
    """A chain without a detection for longer than ``coast_grace_s`` is only its filter's guess
    of where the person went: each such frame costs this much more, what a frame on no track
    costs (a chain that took the person's detections meanwhile is where the phone is)."""


@dataclass
class Identities:
    """The offline identity decisions."""

    mid_at: dict[tuple[int, int], str] = field(default_factory=dict)
    """(chain head key, frame ns) -> MID."""
    ambiguous_frames: int = 0
    """Frames in which some phone could be on two or more tracks alike."""
    unanchored_frames: int = 0
    """Phone-frames left unpublished: a stretch with no unambiguous frame."""
    alignments: dict[str, Alignment] = field(default_factory=dict)
    unseen: dict[int, list[tuple[str, tuple[float, float], tuple[float, float]]]] = field(
        default_factory=dict
    )
    """frame ns -> (MID, xy, velocity) of carriers no chain showed, walked on their phone."""
    known: dict[str, tuple[float, np.ndarray]] = field(default_factory=dict)
    """MID -> (clock offset s, ``a`` per frame: device-to-walk rotation and step scale, NaN
    where not fitted): each phone's alignment over time, as its path implies."""
    placed: dict[str, list[tuple[int, float, float]]] = field(default_factory=dict)
    """MID -> (frame ns, x, y) where the identity put its carrier, in time order."""
    clear: dict[str, tuple[int, int]] = field(default_factory=dict)
    """MID -> (frames its path puts the phone on a chain, of them clear: the chain fits, and by
    ``ratio`` better than any other)."""


@dataclass
class _Chain:
    key: int
    times: np.ndarray
    """Frame times (ns) at which the chain is published."""
    z: np.ndarray
    """Detection-only velocity (complex) per frame, NaN without enough detections."""
    hits: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    """The detections the chain took (t_ns, x, y), in time order."""

    def xy_at(self, t_ns: int) -> tuple[float, float]:
        """Where the chain's detections put it at ``t_ns`` (linear between detections)."""
        h = self.hits
        if not len(h):
            return math.nan, math.nan
        return float(np.interp(t_ns, h[:, 0], h[:, 1])), float(np.interp(t_ns, h[:, 0], h[:, 2]))


def visual_velocity(hits: np.ndarray, times: np.ndarray, half_s: float) -> np.ndarray:
    """Centred least-squares velocity (complex) of detections ``hits`` (t_ns, x, y) at
    ``times``; NaN where fewer than 3 detections span the window (cumulative sums: O(n))."""
    out = np.full(len(times), np.nan, complex)
    if len(hits) < 3:
        return out
    t0 = hits[0, 0]
    t = (hits[:, 0] - t0) / 1e9
    x, y = hits[:, 1], hits[:, 2]
    cols = np.column_stack([np.ones_like(t), t, t * t, x, y, t * x, t * y])
    cum = np.vstack([np.zeros(7), np.cumsum(cols, axis=0)])
    tq = (times - t0) / 1e9
    lo = np.searchsorted(t, tq - half_s, side="left")
    hi = np.searchsorted(t, tq + half_s, side="right")
    s = cum[hi] - cum[lo]
    n, st, stt, sx, sy, stx, sty = s.T
    den = n * stt - st * st
    ok = (n >= 3) & (den > 1e-9 * np.maximum(n, 1) ** 2)
    vx = (n * stx - st * sx)[ok] / den[ok]
    vy = (n * sty - st * sy)[ok] / den[ok]
    out[ok] = vx + 1j * vy
    return out


def dead_reckoned(phone: PhoneMotion, rate_hz: float = 10.0) -> np.ndarray:
    """The phone's dead-reckoned path (t_ns, x, y) on a uniform grid: its velocity integrated
    (device heading; the alignment rotates it). Gaps longer than 2 s break the path."""
    if len(phone.t_ns) < 2:
        return np.empty((0, 3))
    step = int(1e9 / rate_hz)
    grid = np.arange(phone.t_ns[0], phone.t_ns[-1], step, dtype=np.int64)
    v = phone.velocities_at(grid)
    gap = np.diff(phone.t_ns) > 2_000_000_000
    if gap.any():
        for a, b in zip(phone.t_ns[:-1][gap], phone.t_ns[1:][gap], strict=True):
            v[(grid > a) & (grid < b)] = np.nan
    ok = ~np.isnan(v).any(axis=1)
    xy = np.cumsum(np.where(ok[:, None], v, 0.0), axis=0) / rate_hz
    return np.column_stack([grid[ok].astype(float), xy[ok]])


def _chains(frames: Sequence[FrameOut], plan: Publication, velocity_half_s: float) -> list[_Chain]:
    """Every published chain (stitched track) with its frame times and visual velocity."""
    times: dict[int, list[int]] = {}
    hits: dict[int, list[tuple[int, float, float]]] = {}
    members: dict[int, dict[int, GroundTrack]] = {}
    for fr in frames:
        for trk, _, _, _ in fr.rows:
            key = trk.key
            if (key, fr.t_ns) in plan.hidden:
                continue
            head = plan.head.get(key, key)
            times.setdefault(head, []).append(fr.t_ns)
            members.setdefault(head, {})[key] = trk
    for head, tracks in members.items():
        hits[head] = sorted(h for trk in tracks.values() for h in trk.hits_log)
    for t_ns, fills in plan.fills.items():
        for name, _, _ in fills:
            filled = plan.head_of_name.get(name)
            if filled is not None and filled in times:
                times[filled].append(t_ns)
    out = []
    for head, ts in times.items():
        t = np.array(sorted(set(ts)), np.int64)
        h = np.array(hits[head], float).reshape(-1, 3)
        out.append(_Chain(head, t, visual_velocity(h, t, velocity_half_s), h))
    return out


def _encounters(
    chains: list[_Chain], rows: list[np.ndarray], frame_t: np.ndarray, within_m: float
) -> list[np.ndarray]:
    """Per frame, the pairs of chains (indices, (k, 2)) closer than ``within_m`` by their
    detections (k-d tree per frame)."""
    n_f = len(frame_t)
    pos = np.full((n_f, len(chains), 2), np.nan)
    for c, chain in enumerate(chains):
        h = chain.hits
        if len(h):
            pos[rows[c], c, 0] = np.interp(chain.times, h[:, 0], h[:, 1])
            pos[rows[c], c, 1] = np.interp(chain.times, h[:, 0], h[:, 2])
    out = []
    none = np.empty((0, 2), int)
    for f in range(n_f):
        live = np.flatnonzero(~np.isnan(pos[f, :, 0]))
        if len(live) < 2:
            out.append(none)
            continue
        pairs = cKDTree(pos[f, live]).query_pairs(within_m, output_type="ndarray")
        out.append(live[pairs] if len(pairs) else none)
    return out


def _window_sums(
    times: np.ndarray, z_track: np.ndarray, z_phone: np.ndarray, half_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Evidence sums S, P, T, n over a centred window of ``half_s`` around each of ``times``
    (cumulative sums: O(frames)); ``z_phone`` is (frames,) or (frames, lags), NaN: no sample."""
    zt = z_track if z_phone.ndim == 1 else z_track[:, None]
    ok = ~(np.isnan(z_phone) | np.isnan(zt))
    zp0, zt0 = np.where(ok, z_phone, 0), np.where(ok, zt, 0)
    parts = [zt0 * np.conj(zp0), np.abs(zp0) ** 2, np.abs(zt0) ** 2, ok.astype(float)]
    cums = [
        np.concatenate([np.zeros((1, *q.shape[1:]), q.dtype), np.cumsum(q, axis=0)]) for q in parts
    ]
    half = int(half_s * 1e9)
    lo = np.searchsorted(times, times - half, side="left")
    hi = np.searchsorted(times, times + half, side="right")
    sw, pw, tw, nw = (c[hi] - c[lo] for c in cums)
    return sw, pw.real, tw.real, nw.real


def _window_scores(
    chain: _Chain,
    zl: np.ndarray,
    acfg: AlignConfig,
    cfg: IdentifyConfig,
) -> np.ndarray:
    """Mean squared disagreement (m/s)^2 per chain frame at the best alignment of the centred
    window (inf where the window holds too little evidence). ``zl``: (frames, lags) phone
    velocities."""
    s, p, t, n = _window_sums(chain.times, chain.z, zl, cfg.window_s / 2)
    _, r = best_fit(s, p, t, n, acfg)
    enough = (n >= cfg.min_window_frames) & (n >= 0.8 * n.max(axis=1, keepdims=True))
    # two people standing still agree whatever the alignment: no evidence, not a match
    moving = (t + p) / np.maximum(n, 1e-9) >= cfg.min_speed_mps**2
    r = np.where(enough & moving, r, np.inf)
    return r.min(axis=1)


def identify(
    frames: Sequence[FrameOut],
    plan: Publication,
    phones: dict[str, PhoneMotion],
    acfg: AlignConfig,
    cfg: IdentifyConfig,
    aligned: bool = False,
) -> Identities:
    """Decide which phone each published chain carries at each frame (see the module doc).
    ``aligned``: every phone's heading is the walking direction in the site frame and its
    clock is the cameras' (the paper's assumption; only when the phones' app guarantees it)."""
    out = Identities()
    if not phones or not frames:
        return out
    lags = lag_grid(acfg)
    lag_ns = np.round(lags * 1e9).astype(np.int64)
    chains = _chains(frames, plan, cfg.velocity_window_s / 2)
    frame_t = np.array([fr.t_ns for fr in frames], np.int64)
    rows = _chain_rows(chains, frame_t)
    walks = {mid: dead_reckoned(phone) for mid, phone in phones.items()}
    paths, costs, known = _phone_paths(
        phones, walks, chains, rows, frame_t, lags, lag_ns, acfg, cfg, aligned
    )
    ambiguous = np.zeros(len(frame_t), bool)
    for mid, path in paths.items():
        cost = costs[mid]
        out.clear[mid] = (int((path >= 0).sum()), int((_clear_path(path, cost, cfg) >= 0).sum()))
        ambiguous |= _ambiguous_frames(path, cost, cfg)
        _drop_unanchored(path, cost, cfg, out)
    _place_owners(paths, costs, chains, frame_t, out)
    out.ambiguous_frames = int(ambiguous.sum())
    out.alignments = _alignments(out, chains, walks, lags, lag_ns, acfg, cfg.velocity_window_s / 2)
    _publish_known(known, out, chains, frame_t, walks, lags, cfg)
    return out


def _chain_rows(chains: list[_Chain], frame_t: np.ndarray) -> list[np.ndarray]:
    """Per chain, the index in ``frame_t`` of each of its frame times."""
    index = {int(t): i for i, t in enumerate(frame_t)}
    return [np.array([index[int(t)] for t in c.times], int) for c in chains]


def _phone_paths(
    phones: dict[str, PhoneMotion],
    walks: dict[str, np.ndarray],
    chains: list[_Chain],
    rows: list[np.ndarray],
    frame_t: np.ndarray,
    lags: np.ndarray,
    lag_ns: np.ndarray,
    acfg: AlignConfig,
    cfg: IdentifyConfig,
    aligned: bool,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, tuple[int, np.ndarray] | None]]:
    """Per phone (in MID order): its bridged path over the chains, its cost matrix and its
    alignment (:func:`_phone_path`)."""
    n_f = len(frame_t)
    present = np.zeros((n_f, len(chains)), bool)
    for c, r in enumerate(rows):
        present[r, c] = True
    frame_s = float(np.median(np.diff(frame_t))) / 1e9 if n_f > 1 else 1.0
    near = _encounters(chains, rows, frame_t, cfg.encounter_m)
    coast = _coasting(chains, rows, n_f, cfg)  # the chains' own: the same for every phone
    paths: dict[str, np.ndarray] = {}
    costs: dict[str, np.ndarray] = {}
    known: dict[str, tuple[int, np.ndarray] | None] = {}
    for mid in sorted(phones):
        paths[mid], costs[mid], known[mid] = _phone_path(
            walks[mid],
            chains,
            rows,
            frame_t,
            lags,
            lag_ns,
            acfg,
            cfg,
            aligned,
            near,
            phones[mid].carry_changes,
            coast,
        )
        _bridge(paths[mid], present, chains, frame_t, int(cfg.bridge_s / frame_s), cfg.bridge_m)
    return paths, costs, known


def _ambiguous_frames(path: np.ndarray, cost: np.ndarray, cfg: IdentifyConfig) -> np.ndarray:
    """Per frame: the path puts the phone on a chain that fits, and another fits within
    ``ratio`` of it."""
    out = np.zeros(len(path), bool)
    for f in np.flatnonzero(path >= 0):
        row = cost[f]
        mine = row[path[f]]
        rivals = np.delete(row, path[f])
        if len(rivals) and np.min(rivals) <= cfg.ratio * mine + 0.02 and mine < cfg.none_cost:
            out[f] = True
    return out


def _place_owners(
    paths: dict[str, np.ndarray],
    costs: dict[str, np.ndarray],
    chains: list[_Chain],
    frame_t: np.ndarray,
    out: Identities,
) -> None:
    """Fills ``out.mid_at`` and ``out.placed``: one phone per chain and frame, the better fit
    keeps it."""
    keys = [c.key for c in chains]
    for fi in range(len(frame_t)):
        owner: dict[int, tuple[float, str]] = {}
        for mid, path in paths.items():
            c = int(path[fi])
            if c < 0:
                continue
            score = float(costs[mid][fi, c])
            if c not in owner or score < owner[c][0]:
                owner[c] = (score, mid)
        for c, (_, mid) in owner.items():
            t_ns = int(frame_t[fi])
            out.mid_at[(keys[c], t_ns)] = mid
            out.placed.setdefault(mid, []).append((t_ns, *chains[c].xy_at(t_ns)))


def _publish_known(
    known: dict[str, tuple[int, np.ndarray] | None],
    out: Identities,
    chains: list[_Chain],
    frame_t: np.ndarray,
    walks: dict[str, np.ndarray],
    lags: np.ndarray,
    cfg: IdentifyConfig,
) -> None:
    """Fills ``out.known`` with each phone's fitted alignment (in MID order) and, with
    ``unseen_s``, walks its carrier through the gaps no chain shows."""
    for mid in sorted(known):
        al = known[mid]
        if al is None:
            continue
        out.known[mid] = (float(lags[al[0]]), al[1])
        if cfg.unseen_s > 0:
            _carry_through_unseen(mid, out, chains, frame_t, walks[mid], lags, al, cfg)


def _carry_through_unseen(
    mid: str,
    out: Identities,
    chains: list[_Chain],
    frame_t: np.ndarray,
    path_pts: np.ndarray,
    lags: np.ndarray,
    known: tuple[int, np.ndarray],
    cfg: IdentifyConfig,
) -> None:
    """Where a phone's published chains stop for at most ``unseen_s`` and start again (the
    carrier went where no camera sees, or nobody detected them), its carrier walked what the
    phone dead-reckoned: the aligned path from where the chain before left them, with the
    misfit at the chain after spread over the gap. A gap whose dead-reckoned walk misses the
    chain after by more than ``unseen_m`` (+ 15 % of the walk) is not the same carrier's and is
    left empty. Positions go to ``out.unseen`` (published as ``predicted``)."""
    if len(path_pts) < 2:
        return
    k, a = known
    by_key: dict[int, _Chain] = {c.key: c for c in chains}
    key_at = _chain_keys(mid, out, frame_t)
    on = key_at >= 0
    # the phone's dead-reckoned position (complex) at each frame, in phone time
    lag_ns = int(round(float(lags[k]) * 1e9))
    dr = np.interp(frame_t + lag_ns, path_pts[:, 0], path_pts[:, 1]) + 1j * np.interp(
        frame_t + lag_ns, path_pts[:, 0], path_pts[:, 2]
    )
    inside = (frame_t + lag_ns >= path_pts[0, 0]) & (frame_t + lag_ns <= path_pts[-1, 0])
    step = np.r_[0, np.diff(dr)] * np.nan_to_num(a, nan=0.0)
    max_frames = int(cfg.unseen_s / (float(np.median(np.diff(frame_t))) / 1e9 or 1.0))
    f = 1
    n = len(frame_t)
    while f < n:
        if on[f] or not on[f - 1]:
            f += 1
            continue
        g = f
        while g < n and not on[g]:
            g += 1
        walkable = g < n and g - f <= max_frames and inside[f - 1 : g + 1].all()
        if walkable and not np.isnan(a[f - 1 : g + 1]).any():
            pa = complex(*by_key[int(key_at[f - 1])].xy_at(int(frame_t[f - 1])))
            pb = complex(*by_key[int(key_at[g])].xy_at(int(frame_t[g])))
            _walk_gap(mid, out, frame_t[f:g], step[f : g + 1], (pa, pb), cfg)
        f = g


def _chain_keys(mid: str, out: Identities, frame_t: np.ndarray) -> np.ndarray:
    """The key of the chain the identity publishes phone ``mid`` on at each frame (-1: none)."""
    key_at = np.full(len(frame_t), -1, np.int64)
    index = {int(t): i for i, t in enumerate(frame_t)}
    for (key, t_ns), m in out.mid_at.items():
        if m == mid:
            key_at[index[t_ns]] = key
    return key_at


def _walk_gap(
    mid: str,
    out: Identities,
    gap_t: np.ndarray,
    step: np.ndarray,
    ends: tuple[complex, complex],
    cfg: IdentifyConfig,
) -> None:
    """One gap of :func:`_carry_through_unseen`: the frames ``gap_t`` between the chain that
    left the carrier at ``ends[0]`` and the one that finds them at ``ends[1]``, walked on the
    phone's aligned ``step`` s (into each gap frame and the one after), the misfit spread over
    the gap; nothing when it misses by more than ``unseen_m`` (+ 15 % of the walk)."""
    pa, pb = ends
    walk = np.cumsum(step)  # displacement from the frame before the gap
    miss = pb - (pa + walk[-1])
    if abs(miss) > cfg.unseen_m + 0.15 * abs(walk[-1]):
        return
    m = len(gap_t)
    share = np.arange(1, m + 1) / (m + 1)
    xy = pa + walk[:-1] + share * miss
    v = np.gradient(xy, gap_t / 1e9) if m > 1 else np.zeros(1, complex)
    for i, t_ns in enumerate(gap_t):
        out.unseen.setdefault(int(t_ns), []).append(
            (mid, (xy[i].real, xy[i].imag), (v[i].real, v[i].imag))
        )


def _clear_path(path: np.ndarray, cost: np.ndarray, cfg: IdentifyConfig) -> np.ndarray:
    """The path where it is unambiguous (its chain fits, and clearly better than any other);
    -1 elsewhere: a phone's alignment is learnt only from frames that name its carrier."""
    out = np.full(len(path), -1)
    for f in np.flatnonzero(path >= 0):
        row = cost[f]
        mine = row[path[f]]
        rival = np.min(np.delete(row, path[f])) if len(row) > 1 else np.inf
        if mine < cfg.none_cost and rival > cfg.ratio * mine + 0.02:
            out[f] = path[f]
    return out


def _phone_path(
    path_pts: np.ndarray,
    chains: list[_Chain],
    rows: list[np.ndarray],
    frame_t: np.ndarray,
    lags: np.ndarray,
    lag_ns: np.ndarray,
    acfg: AlignConfig,
    cfg: IdentifyConfig,
    aligned: bool,
    near: list[np.ndarray] | None = None,
    carry_changes: np.ndarray | None = None,
    coast: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, tuple[int, np.ndarray] | None]:
    """One phone's path over the chains (chain index per frame, -1: none), its cost matrix and
    its alignment (lag index, ``a`` per frame; None when never fitted): the free fit first,
    then ``refine_passes`` under the alignment the last path implies.
    ``path_pts``: the phone's dead-reckoned path (:func:`dead_reckoned`); ``carry_changes``:
    phone-clock times at which its carry changed (its alignment is fitted between them);
    ``coast``: :func:`_coasting` of the chains (computed here when not given)."""
    n_f = len(frame_t)
    if coast is None:
        coast = _coasting(chains, rows, n_f, cfg)
    zls = []
    free = np.full((n_f, len(chains)), np.inf)
    for c, chain in enumerate(chains):
        # the phone's velocity through the same centred least-squares slope as the track's
        # detections: both sides see the walk through one filter
        at = (chain.times[:, None] + lag_ns[None, :]).ravel()
        zl = visual_velocity(path_pts, at, cfg.velocity_window_s / 2)
        zls.append(zl.reshape(len(chain.times), len(lags)))
        if np.isnan(zls[-1]).all():
            continue
        r = _window_scores(chain, zls[-1], acfg, cfg)
        # a published frame without evidence costs what "no track" costs
        free[rows[c], c] = np.where(np.isfinite(r), r, cfg.none_cost)
    if aligned:
        # the paper's setting, declared by the user: heading = walk, one clock, 0.7 m steps
        known0 = (len(lags) // 2, np.ones(n_f, complex))
        cost = _known_costs(free, known0, chains, rows, zls, cfg)
        return _viterbi(cost + coast, cfg, near), cost, known0
    cost = free
    path = _viterbi(cost + coast, cfg, near)
    found: tuple[int, np.ndarray] | None = None
    for _ in range(cfg.refine_passes):
        # the phone's alignment over time, from where the path names its carrier clearly; then
        # every chain is scored under it (direction counts again), the free fit elsewhere
        known = _alignment_track(
            _clear_path(path, cost, cfg), chains, rows, zls, frame_t, lags, acfg, cfg, carry_changes
        )
        if known is None:
            break
        found = known
        cost = _known_costs(free, known, chains, rows, zls, cfg)
        path = _viterbi(cost + coast, cfg, near)
    return path, cost, found


def _coasting(
    chains: list[_Chain], rows: list[np.ndarray], n_f: int, cfg: IdentifyConfig
) -> np.ndarray:
    """``coast_cost`` at each (frame, chain) where the chain has had no detection for longer
    than ``coast_grace_s``; 0 elsewhere."""
    out = np.zeros((n_f, len(chains)))
    grace = int(cfg.coast_grace_s * 1e9)
    for c, chain in enumerate(chains):
        if not len(chain.hits):
            continue
        hit_t = np.unique(chain.hits[:, 0]).astype(np.int64)
        last = hit_t[np.clip(np.searchsorted(hit_t, chain.times, side="right") - 1, 0, None)]
        out[rows[c], c] = np.where(chain.times - last > grace, cfg.coast_cost, 0.0)
    return out


def _alignment_track(
    path: np.ndarray,
    chains: list[_Chain],
    rows: list[np.ndarray],
    zls: list[np.ndarray],
    frame_t: np.ndarray,
    lags: np.ndarray,
    acfg: AlignConfig,
    cfg: IdentifyConfig,
    carry_changes: np.ndarray | None = None,
) -> tuple[int, np.ndarray] | None:
    """The phone's lag (one over the log: the one its local fits explain best) and its ``a``
    per frame (a centred ``align_window_frames`` fit over the assigned frames, within the
    carry the frame is in; NaN where too few): None when the path holds too little evidence."""
    n_f = len(frame_t)
    n_l = len(lags)
    s = np.zeros((n_f, n_l), complex)
    p = np.zeros((n_f, n_l))
    t = np.zeros((n_f, n_l))
    n = np.zeros((n_f, n_l))
    for c, chain in enumerate(chains):
        on = path[rows[c]] == c
        if not on.any():
            continue
        f = rows[c][on]
        zt = chain.z[on][:, None]
        zl = zls[c][on]
        ok = ~(np.isnan(zl) | np.isnan(zt))
        zp, z0 = np.where(ok, zl, 0), np.where(ok, zt, 0)
        s[f] += z0 * np.conj(zp)
        p[f] += np.abs(zp) ** 2
        t[f] += np.abs(z0) ** 2
        n[f] += ok
    if n.sum(0).max() < cfg.min_window_frames * 2:
        return None
    # frames are uniform enough: the window in frames from the median frame interval
    half = max(1, int(round(cfg.align_window_frames / 2)))
    cum = [
        np.concatenate([np.zeros((1, n_l), q.dtype), np.cumsum(q, axis=0)]) for q in (s, p, t, n)
    ]
    idx = np.arange(n_f)

    def windows(lag_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # each frame's centred window, within its carry (the changes in camera time: phone
        # time - lag)
        cuts = np.empty(0, int)
        if carry_changes is not None and len(carry_changes):
            cuts = np.unique(np.searchsorted(frame_t, carry_changes - int(round(lag_s * 1e9))))
        seg = np.searchsorted(cuts, idx, side="right")
        lo = np.maximum(idx - half, np.r_[0, cuts][seg])
        hi = np.minimum(idx + half + 1, np.r_[cuts, n_f][seg])
        return lo, hi, seg

    # the lag (one clock offset per phone) that the local fits explain best: a single yaw
    # over the whole log would judge lags by how well they survive the carry's changes
    lo, hi, _ = windows(0.0)
    sw, pw, tw, nw = (c[hi] - c[lo] for c in cum)
    _, r = best_fit(sw, pw, tw, nw, acfg)
    use = nw >= cfg.min_window_frames * 2
    cover = np.where(use, nw, 0.0).sum(axis=0)
    resid = np.where(use, r * nw, 0.0).sum(axis=0) / np.maximum(cover, 1e-9)
    resid[cover < 0.8 * cover.max()] = np.inf
    if not np.isfinite(resid).any():
        return None
    k = int(np.argmin(resid))
    lo, hi, seg = windows(float(lags[k]))
    sw, pw, nw = (cum[i][hi, k] - cum[i][lo, k] for i in (0, 1, 3))
    a, _ = best_fit(sw, pw, np.zeros(n_f), nw, acfg)
    a = np.where((nw >= cfg.min_window_frames * 2) & (np.abs(sw) > 0), a, np.nan)
    # before the first and after the last well-fitted stretch of a carry (and between
    # stretches) the nearest fit of that carry holds: a carry stays until the phone is moved
    out = np.full(n_f, np.nan, complex)
    for s0 in np.unique(seg):
        span = np.flatnonzero(seg == s0)
        good = span[~np.isnan(a[span])]
        if not len(good):
            continue
        pos = np.searchsorted(good, span)
        nearest = good[np.clip(pos, 0, len(good) - 1)]
        prev = good[np.clip(pos - 1, 0, len(good) - 1)]
        out[span] = a[np.where(np.abs(prev - span) < np.abs(nearest - span), prev, nearest)]
    if np.isnan(out).all():
        return None
    return k, out


def _known_costs(
    free: np.ndarray,
    known: tuple[int, np.ndarray],
    chains: list[_Chain],
    rows: list[np.ndarray],
    zls: list[np.ndarray],
    cfg: IdentifyConfig,
) -> np.ndarray:
    """Costs under the phone's known alignment: its clock offset and step scale as fitted, its
    yaw free only within ``yaw_slack_deg`` of the local fit (magnetic disturbance, drift), over
    a centred ``known_window_s``; the free fit's cost where the alignment is not known."""
    k, a = known
    cost = free.copy()
    slack = math.radians(cfg.yaw_slack_deg)
    for c, chain in enumerate(chains):
        f = rows[c]
        af = a[f]
        sw, pw, tw, nw = _window_sums(chain.times, chain.z, zls[c][:, k], cfg.known_window_s / 2)
        phi = np.angle(af)
        dev = np.clip(np.angle(sw * np.exp(-1j * phi)), -slack, slack)
        rot = np.exp(1j * (phi + dev))
        scale = np.abs(af)
        r = (tw - 2 * scale * (np.conj(rot) * sw).real + scale**2 * pw) / np.maximum(nw, 1e-9)
        moving = (tw + pw) / np.maximum(nw, 1e-9) >= cfg.min_speed_mps**2
        use = (nw >= cfg.min_window_frames / 2) & ~np.isnan(af)
        r = np.where(moving, np.maximum(r, 0.0), cfg.none_cost)
        cost[f[use], c] = r[use]
    return cost


def _viterbi(
    cost: np.ndarray, cfg: IdentifyConfig, near: list[np.ndarray] | None = None
) -> np.ndarray:
    """The phone's cheapest path over frames: chain index per frame, -1 for none.

    States are the chains and "none". Staying is free; moving between two chains costs
    ``switch_cost`` (``handover_cost`` between chains ``near`` each other at that frame),
    between a chain and none half of it; a chain that stops being published releases the
    phone to none for free (the person left, or the fragment ended)."""
    n_f, n_c = cost.shape
    none = n_c
    acc = np.full(n_c + 1, math.inf)
    acc[none] = 0.0
    back = np.zeros((n_f, n_c + 1), np.int32)
    half = cfg.switch_cost / 2
    states = np.arange(n_c + 1)
    for f in range(n_f):
        e = np.append(cost[f], cfg.none_cost)
        if n_c:
            bt = int(np.argmin(acc[:n_c]))
            best_trk = acc[bt]
        else:
            bt, best_trk = none, math.inf
        # best way into each state: stay, come from the best chain, or come from none
        into = acc.copy()
        src = states.copy()
        for cand, origin in ((best_trk + cfg.switch_cost, bt), (acc[none] + half, none)):
            better = cand < into
            better[none] = False
            into[better] = cand
            src[better] = origin
        if near is not None and len(near[f]):
            # a swap at an encounter: hand the phone over cheaply, both ways
            i = np.concatenate([near[f][:, 0], near[f][:, 1]])
            j = np.concatenate([near[f][:, 1], near[f][:, 0]])
            via = acc[i] + cfg.handover_cost
            # a chain near several: the cheapest comes last, and the last assignment stays
            order = np.argsort(-via, kind="stable")
            i, j, via = i[order], j[order], via[order]
            better = via < into[j]
            into[j[better]] = via[better]
            src[j[better]] = i[better]
        # into none: from the best chain (half the switch), or free from a chain that ended
        if n_c:
            if best_trk + half < into[none]:
                into[none], src[none] = best_trk + half, bt
            ended = np.isfinite(acc[:n_c]) & ~np.isfinite(cost[f])
            if ended.any():
                k = int(np.flatnonzero(ended)[np.argmin(acc[:n_c][ended])])
                if acc[k] < into[none]:
                    into[none], src[none] = acc[k], k
        acc = into + e
        back[f] = src
    state = int(np.argmin(acc))
    path = np.empty(n_f, int)
    for f in range(n_f - 1, -1, -1):
        path[f] = -1 if state == none else state
        state = int(back[f, state])
    return path


def _bridge(
    path: np.ndarray,
    present: np.ndarray,
    chains: list[_Chain],
    frame_t: np.ndarray,
    max_frames: int,
    max_m: float,
) -> None:
    """Bridge the gaps of at most ``max_frames`` frames in ``path`` (in place) between a chain
    ``a`` before and a chain ``b`` after, through published chains: staying on a chain is free,
    handing over to another costs 1 plus the distance between the two at the handover, which
    must be within ``max_m``. The cheapest such route fills the gap; none leaves it."""
    n = len(path)
    f = 0
    while f < n:
        if path[f] >= 0:
            f += 1
            continue
        g = f
        while g < n and path[g] < 0:
            g += 1
        if 0 < f and g < n and g - f <= max_frames:
            route = _route(int(path[f - 1]), int(path[g]), f, g, present, chains, frame_t, max_m)
            if route is not None:
                path[f:g] = route
        f = g


def _route(
    a: int,
    b: int,
    f: int,
    g: int,
    present: np.ndarray,
    chains: list[_Chain],
    frame_t: np.ndarray,
    max_m: float,
) -> list[int] | None:
    """The chain at each frame ``f..g-1`` of the cheapest continuous route from chain ``a`` at
    frame ``f - 1`` to chain ``b`` at frame ``g`` (dynamic programming over the frames)."""
    cost: dict[int, float] = {a: 0.0}
    back: list[dict[int, int]] = []
    for k in range(f, g + 1):
        live = [b] if k == g else [int(c) for c in np.flatnonzero(present[k])]
        t_prev, t_now = int(frame_t[k - 1]), int(frame_t[k])
        prev_xy = {i: chains[i].xy_at(t_prev) for i in cost}
        nxt: dict[int, float] = {}
        came: dict[int, int] = {}
        for j in live:
            xj = chains[j].xy_at(t_now)
            for i, ci in cost.items():
                if i == j:
                    c = ci
                else:
                    d = math.hypot(prev_xy[i][0] - xj[0], prev_xy[i][1] - xj[1])
                    if not d <= max_m:
                        continue
                    c = ci + 1.0 + d
                if j not in nxt or c < nxt[j]:
                    nxt[j], came[j] = c, i
        if not nxt:
            return None
        cost = nxt
        back.append(came)
    # back[k - f] maps a chain at frame k to the chain it came from at frame k - 1
    route: list[int] = []
    c = b
    for k in range(g, f, -1):
        c = back[k - f][c]
        route.append(c)
    return route[::-1]


def _drop_unanchored(
    path: np.ndarray, cost: np.ndarray, cfg: IdentifyConfig, out: Identities
) -> None:
    """A stretch on one chain with fewer than ``min_clear_frames`` (or ``min_clear_share`` of
    its) frames in which the chain fits and clearly better than any other (by ``ratio``) is a
    guess: the phone is left off it."""
    clear = _clear_path(path, cost, cfg) >= 0
    f = 0
    n = len(path)
    while f < n:
        c = path[f]
        g = f
        while g < n and path[g] == c:
            g += 1
        n_clear = int(clear[f:g].sum())
        if c >= 0 and (n_clear < cfg.min_clear_frames or n_clear < cfg.min_clear_share * (g - f)):
            path[f:g] = -1
            out.unanchored_frames += g - f
        f = g


def _alignments(
    out: Identities,
    chains: list[_Chain],
    walks: dict[str, np.ndarray],
    lags: np.ndarray,
    lag_ns: np.ndarray,
    acfg: AlignConfig,
    half_s: float,
) -> dict[str, Alignment]:
    """Each phone's alignment fitted over every frame it was assigned (for the report)."""
    by_key = {c.key: c for c in chains}
    samples: dict[str, list[tuple[int, complex]]] = {}
    for (key, t_ns), mid in out.mid_at.items():
        chain = by_key[key]
        z = chain.z[int(np.searchsorted(chain.times, t_ns))]
        if not np.isnan(z):
            samples.setdefault(mid, []).append((t_ns, complex(z)))
    fits = {}
    for mid, pairs in samples.items():
        t = np.array([p[0] for p in pairs], np.int64)
        z = np.array([p[1] for p in pairs])
        at = (t[:, None] + lag_ns[None, :]).ravel()
        zl = visual_velocity(walks[mid], at, half_s).reshape(len(t), len(lags))
        ev = PairEvidence(len(lags))
        for k in range(len(t)):
            ev.add(z[k], zl[k])
        al = ev.fit(acfg, lags)
        if al is not None:
            fits[mid] = al
    return fits
