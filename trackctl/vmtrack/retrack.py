"""Phone-guided re-tracking: each carrier followed through the raw detections by their phone.

Visual tracks swap people where people pass close (without appearance, position alone cannot
tell two walkers apart), and in a crowd they do so every few seconds; a phone bound to a chain
of such tracks inherits every swap. Offline, a phone is a far better motion model than a
constant-velocity filter: once its alignment is known (device-to-walk yaw, step scale, clock
offset; :mod:`~trackctl.vmtrack.align`), its dead reckoning says how its carrier moved between
two frames to a few centimetres. So each phone is tracked on its own, through the raw
detections of every frame, not through the visual tracks:

* **Model.** The carrier's position ``x_k`` moves by the phone's aligned displacement ``u_k``
  plus a random walk (``walk_sigma_mps`` per square-root second: step-length and heading error,
  a camera's calibration bias taking over from another's); a detection within reach costs
  ``d^2 / (2 det_sigma_m^2)``, no detection near costs ``miss_cost`` (the carrier is missed,
  hidden or out of view: the cap keeps a long unseen stretch from dragging the path onto
  whoever is nearest).
* **Global path** (Viterbi over a position grid of ``cell_m``): the whole log is searched at
  once, so the path needs no starting point and the carrier is wherever their phone's walk
  fits the detections best over the log. The displacement shifts the grid each frame (the
  fraction carried over), the random walk is a 3 x 3 neighbourhood, and the distance to the
  nearest detection is a Euclidean distance transform of the frame's detections (scipy).
  This is the Viterbi algorithm written out, not a library's: it runs over an image-shaped
  state whose transition is a shift (no library offers that).
* **Alignment search.** The chains' alignment (:mod:`~trackctl.vmtrack.identify`) is learnt
  from visual tracks and in a crowd from the wrong person; it starts nothing here. The yaw is
  searched instead: the same forward pass, without back-pointers, for every yaw on a
  ``yaw_step_deg`` grid at once (the grid coarser, ``search_cell_m``), over windows of
  ``window_s``; a Viterbi over the windows picks the yaw of each (a carry change that the
  phone did not notice is a jump at ``yaw_jump_cost``). Then ``refine_passes`` times the path
  is found and the alignment refitted from the detections on it (a ``align_window_s`` window
  per frame, the clock offset from all of them).
* **Publication.** A frame is published where the path has a detection within ``gate_m`` and
  across gaps up to ``fill_s`` between two such frames, on stretches whose detections turn,
  stop and start with the phone (``min_evidence``; a phone whose carrier is out of view fits
  anyone who walks straight); the position is the phone's walk plus
  the detections' offset from it, smoothed over ``smooth_s`` (so the noise of one detection
  does not show, and the phone's walk fills the gaps).

Memory grows with the site's area and the log's length: every frame's detection-distance grid
(4 bytes per cell, and a coarser one for the search) and one phone's back-pointers (1 byte per
cell), about 6 bytes per 0.2 m cell and frame in all: a 20 x 15 m lobby (with 2 m margins,
11 400 cells) takes 70 kB per frame, 740 MB for an hour at 3 frames per second.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from trackctl.progress import Progress
from trackctl.vmtrack import kernels
from trackctl.vmtrack.align import AlignConfig, best_fit, lag_grid
from trackctl.vmtrack.grid import SiteGrid, Visit, occupancy_steadiness
from trackctl.vmtrack.identify import dead_reckoned, visual_velocity
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.radio import PathLoss, RadioConfig, RadioEvidence

__all__ = ["PhoneTrack", "RetrackConfig", "Retracked", "VisitReading", "read_visits", "retrack"]


@dataclass(frozen=True, slots=True)
class RetrackConfig:
    """Phone-guided re-tracking parameters (metres, seconds, costs in ``d^2 / 2 sigma^2``)."""

    enabled: bool = True
    cell_m: float = 0.2
    """Grid cell of the final paths."""
    search_cell_m: float = 0.3
    """Grid cell of the yaw search."""
    det_sigma_m: float = 0.35
    """A detection's ground error, calibration bias included, m (measured on real footage:
    docs/vmtrack.md, Parameters)."""
    walk_sigma_mps: float = 0.2
    """Random walk of the carrier about the phone's aligned walk, m per sqrt(s): a 10 % step
    length or 5 deg heading error at 1.3 m/s, and a camera's bias taking over from another's."""
    miss_cost: float = 3.0
    """Cost of a frame with no detection near the path (missed, hidden, out of view): what a
    detection 2.5 sigma away costs, so a farther one is no better than none."""
    away_cost: float | None = 2.0
    """Cost of a frame with the carrier out of view; the path comes into view once (out of
    view, in view, out of view, each part possibly empty). None: the path is one walk over the
    whole log, in view throughout (docs/vmtrack.md, Parameters)."""
    door_cost: float = 2.0
    wall_cost: float = 25.0
    """Cost of coming into view or leaving it: ``door_cost`` at a door, ``wall_cost``
    anywhere else (a door inside the view, a long miss)."""
    return_cost: float | None = 0.0
    """A path may come back into view after leaving it, at this cost on top of the door's and
    of the misfit to where the phone's walk from the cell left puts the carrier
    (:class:`_Returns`). None: one visit (docs/vmtrack.md, Parameters)."""
    edge_m: float = 1.0
    door_ratio: float | None = None
    """None (the default): the whole edge of the covered area (within ``edge_m`` of it) is a
    door. A number: a door is only where detections begin or end (nobody within ``door_link_m``
    in the ``door_frames`` frames before, or after) this many times as often as inside the
    area, smoothed over ``door_smooth_m`` along the edge (docs/vmtrack.md, Parameters)."""
    door_link_m: float = 1.2
    door_frames: int = 3
    door_smooth_m: float = 1.5
    turnover_min: float | None = 20.0
    steadiness_min: float = 0.8
    steadiness_window_s: float = 30.0
    """The visit model read from the log (:class:`VisitReading`): a room is closed, its paths
    in view throughout, when its edge turnover is below ``turnover_min`` and its occupancy's
    steadiness over ``steadiness_window_s`` at least ``steadiness_min``; anything else is one
    visit (``away_cost``). None: one visit whatever the log (docs/vmtrack.md, Parameters)."""
    min_evidence: float | None = 5.0
    evidence_lag_s: float = 2.0
    evidence_sigma_mps: float = 0.3
    """A stretch is published only when its detections share ``min_evidence`` of motion
    changes with the phone (:func:`_evidence`: changes of velocity over ``evidence_lag_s``, in
    units of ``evidence_sigma_mps``), its RSSI's log-likelihood ratio counted in. None
    publishes every stretch (docs/vmtrack.md, Parameters)."""
    gate_m: float = 1.0
    """A frame counts as seen when a detection is this near the path."""
    fill_s: float = 2.0
    """Gaps up to this between seen frames are published on the phone's walk."""
    unseen_s: float = 20.0
    unseen_m: float = 1.0
    """Gaps up to ``unseen_s`` between two stretches are published on the phone's walk when
    it lands within ``unseen_m`` (+ 15 % of the distance walked) of the next stretch, the
    misfit spread over the gap (docs/vmtrack.md, Parameters)."""
    gap_walk_sigma_mps: float | None = 0.5
    """The random walk, m per sqrt(s), of the carrier about the phone's walk within a published
    gap (a fill or a bridge between two seen frames): the gap is tracked again over the
    detections, pinned to the carrier at both ends, and published on the detections that path
    is on (:func:`_through_gaps`). None: a gap is published on the phone's walk alone
    (docs/vmtrack.md, Parameters)."""
    twin_share: float | None = 0.6
    """A stretch another walker moves with at a steady offset over the gate in this share of
    its frames (most of them: real detections miss and merge), which the phone's walk ties to
    no other published stretch, is not published (:func:`_untwinned`; only without RSSI,
    which tells them apart by distance). None: no check (docs/vmtrack.md, Parameters)."""
    min_stretch_s: float = 5.0
    """A stretch (seen frames and the gaps filled between them) shorter than this is not
    published: a path that passes a stranger picks up a few detections on the way. Unless a
    waypoint: between two published stretches the phone's walk does not join directly, and
    joined by it to both (:func:`_with_waypoints`)."""
    smooth_s: float = 1.5
    """Gaussian time constant of the offset between the phone's walk and its detections."""
    jump_m: float | None = 1.5
    jump_window_s: float = 3.0
    """Where the lines fitted to the detections' offsets from the phone's walk over the
    ``jump_window_s`` before a frame and the one after disagree there by more than ``jump_m``
    (a steady drift, the walk's yaw or step-length error, fits one line; 1.5 m: 5 sd of the two
    lines' ends under 0.35 m detection noise at 7 Hz), the path went from one
    person to another: of the pieces such jumps cut a stretch into, only those the walk ties
    together with the best evidence are published (:func:`_one_carrier`). None: no check
    (docs/vmtrack.md, Parameters)."""
    yaw_step_deg: float = 15.0
    search_scales: tuple[float, ...] = (0.8, 0.9, 1.0, 1.1, 1.2)
    """Step-length scales searched (against the nominal 0.7 m step: 0.55-0.85 m steps)."""
    search_lag_step_s: float = 0.5
    """Clock offsets are searched on this grid over the range the alignment allows."""
    search_const_lag_step_s: float = 1.0
    """The one-yaw search tries every yaw at clock offsets this far apart."""
    search_max_hz: float | None = 3.5
    """The search sees every k-th frame, k the smallest that brings the log's frame rate to at
    most this, Hz (a 7 Hz video: every second frame); the path and the alignment are then found
    again on every frame. None: every frame (docs/vmtrack.md, Parameters)."""
    search_first_scales: tuple[float, ...] = (0.8, 1.0, 1.2)
    """Step scales at which the one-yaw search chooses the yaw of each stretch between carry
    changes, at every clock offset (docs/vmtrack.md, Parameters)."""
    search_candidates: int = 3
    """The one-yaw search refines this many of its best yaws (each more than a step from the
    others): the offset and scale under each, the cheapest kept."""
    search_starts_s: tuple[float, ...] = (-1.5, 0.0, 1.5)
    """Clock offsets, s, where the yaw search starts again when the offset it led to is at the
    edge of the range (the search failed there); the start whose path costs least is kept
    (docs/vmtrack.md, Parameters)."""
    search_walk_sigma_mps: float = 0.2
    """The random walk of the search (it absorbs the yaw and scale grids' steps)."""
    yaw_step_cost: float = 40.0
    """Cost of the walk's yaw moving by one ``yaw_step_deg`` step between two frames (drift,
    magnetic disturbance; docs/vmtrack.md, Parameters)."""
    yaw_jump_cost: float = 150.0
    """Cost of any other yaw change between two frames: a carry change the phone did not
    notice (docs/vmtrack.md, Parameters)."""
    ambiguity_candidates: int = 8
    ambiguity_margin: float | None = 10.0
    """A phone's path is weighed against up to ``ambiguity_candidates`` other refined
    alignments (those within this of the path's cost under ``walk_sigma_mps``, or under
    both walks summed when they see the carrier at the same time: :meth:`_Follower._weighed`):
    where one whose path costs at most this more (or less) under ``settle_walk_sigma_mps``
    puts the carrier more than ``gate_m`` away, the frame is not published
    (:meth:`_Follower.settle`), unless the middle of them all is within ``gate_m`` of each (a
    group: published there). None: no alternatives weighed (docs/vmtrack.md, Parameters)."""
    settle_walk_sigma_mps: float | None = 0.1
    """The random walk, m per sqrt(s), under which a phone's refined alignments are weighed
    against each other (:meth:`_Follower.settle`); the cheapest becomes the phone's path. None:
    weighed under ``walk_sigma_mps``, and the search's path is kept (docs/vmtrack.md,
    Parameters)."""
    exclusive: bool = True
    """One person carries one phone: two phones whose paths share detections for
    ``min_stretch_s`` or more are settled jointly, the one that loses least without them
    followed again without them (:func:`_exclusive`). Off for a site where people carry two
    phones (both would then be moved apart)."""
    trust_clear_share: float | None = 0.8
    """A phone whose offline identity is clear (:attr:`~trackctl.vmtrack.identify.Identities.
    clear`) in at least this share of the frames it is on a chain is followed from that
    identity's alignment, refitted, and not searched. None: every phone searched
    (``--refine full``; docs/vmtrack.md, Parameters)."""
    refine_passes: int = 2
    velocity_window_s: float = 7.0
    """Centred window of the least-squares velocity of the path's detections and of the phone's
    walk, for the refit (the offline identity's: both sides through one filter)."""
    align_window_s: float = 30.0
    """Centred window of the alignment refitted from the path's detections."""
    min_align_frames: int = 10
    """Detections a refit window needs."""
    radio: RadioConfig = field(default_factory=RadioConfig)
    """How the phones' RSSI at the site's APs weighs in (:mod:`~trackctl.vmtrack.radio`)."""
    max_bytes: int = 2_000_000_000
    """Memory the re-tracking may take (about 6 bytes per grid cell and frame: the frames'
    distance grids and one phone's back-pointers); above it the re-tracking is skipped with a
    warning, and the phones name the visual tracks they fit."""


@dataclass
class PhoneTrack:
    """One phone's re-tracked carrier."""

    xy: dict[int, tuple[float, float]]
    """Frame index -> published position."""
    seen: set[int]
    """Frame indices with a detection on the path (the rest of ``xy`` is filled)."""
    velocity: np.ndarray
    """(n_frames, 2) aligned phone velocity, m/s (NaN where unknown)."""
    lag_s: float
    a: np.ndarray
    """Alignment per frame (complex: scale and yaw), NaN where unknown."""
    withheld_s: float = 0.0
    """Seconds of the path on detections not published: stretches whose motion shares too
    few changes with the phone's to say it is the carrier (:func:`_evidence`)."""
    ambiguous_s: float = 0.0
    """Seconds not published because another alignment nearly as cheap puts the carrier
    elsewhere (:attr:`RetrackConfig.ambiguity_margin`)."""
    grouped_s: float = 0.0
    """Seconds published at the middle of the places where alignments nearly as cheap put the
    carrier, all within ``gate_m`` of it (a group walking together)."""
    riding: dict[int, np.ndarray] = field(default_factory=dict)
    """Frame index -> the detection the path is on where it publishes nothing (withheld)."""


@dataclass(frozen=True, slots=True)
class VisitReading:
    """What the log says of how people come and go (:attr:`RetrackConfig.turnover_min`)."""

    edge_turnover: float | None = None
    steadiness: float | None = None
    one_visit: bool = True
    """Each path comes into view once (False: in view throughout)."""


class Retracked(dict[str, PhoneTrack]):
    """Each phone's re-tracked carrier (MID -> track), with what the re-tracking fitted of the
    site: each AP's path loss (empty without RSSI or its fit), and the phones searched again
    under it."""

    def __init__(self) -> None:
        super().__init__()
        self.calibration: dict[str, PathLoss] = {}
        self.searched_again: list[str] = []
        self.searched: list[str] = []
        """The phones whose alignment was searched (the rest started from their identity's)."""
        self.visits: VisitReading | None = None
        """The visit model the log called for (:attr:`RetrackConfig.turnover_min`); None
        before it is read."""


def _reversed(away: float | np.ndarray) -> float | np.ndarray:
    return away[::-1] if isinstance(away, np.ndarray) else away


_STEADY = 1e6
"""A change of yaw that a steady search does not make (the carry did not change)."""

_OFFS = [(int(dy), int(dx)) for dy, dx in kernels.OFFSETS]
_BIG = kernels.BIG


def _slices(d: int, n: int) -> tuple[slice, slice]:
    """Source and destination slices of a shift by ``d`` cells along an axis of ``n``."""
    return (slice(0, n - d), slice(d, n)) if d >= 0 else (slice(-d, n), slice(0, n + d))


def _whole_cells(frac: np.ndarray, moves: np.ndarray, cell: float) -> np.ndarray:
    """The whole cells (layers, 2: x, y) of each layer's ``moves`` (complex, (layers,)) plus
    the fraction carried in ``frac`` ((layers, 2), updated in place: what is left over is
    carried to the next frame); a layer whose move is NaN restarts (its fraction set to 0,
    its cells 0)."""
    ok = ~np.isnan(moves)
    frac[~ok] = 0.0
    frac[ok, 0] += moves[ok].real / cell
    frac[ok, 1] += moves[ok].imag / cell
    whole = np.round(frac)  # half to even, as Python's round
    frac -= whole
    return whole.astype(int)


def _step_costs(
    cell: float, dt: float, cfg: RetrackConfig, sigma_mps: float | None = None
) -> np.ndarray:
    sigma = cfg.walk_sigma_mps if sigma_mps is None else sigma_mps
    var = max(sigma**2 * dt, 1e-6)
    return np.array([(dy * dy + dx * dx) * cell * cell / (2 * var) for dy, dx in _OFFS], np.float32)


def _displacements(
    frame_t: np.ndarray, track: np.ndarray, lag_s: float, a: np.ndarray
) -> np.ndarray:
    """The phone's aligned displacement (complex) into each frame; NaN where the phone has no
    walk (outside its samples, or the alignment unknown)."""
    u = np.full(len(frame_t), np.nan, complex)
    if len(track) < 2:
        return u
    tq = frame_t + int(round(lag_s * 1e9))
    inside = (tq >= track[0, 0]) & (tq <= track[-1, 0])
    d = np.interp(tq, track[:, 0], track[:, 1]) + 1j * np.interp(tq, track[:, 0], track[:, 2])
    step = np.r_[0, np.diff(d)] * a
    u[inside] = step[inside]
    u[0] = np.nan if not inside[0] else 0j
    # a frame whose predecessor is outside the walk starts afresh
    u[1:][~inside[:-1]] = np.nan
    return u


def _layer_costs(
    grid: SiteGrid,
    emissions: Sequence[np.ndarray | float],
    walks: np.ndarray,
    steps: np.ndarray,
    turn_cost: float | None = None,
    jump_cost: float | None = None,
    free: np.ndarray | None = None,
    visit: Visit | None = None,
    absolute: bool = False,
) -> np.ndarray:
    """One pass of the Viterbi recursion over (layer, position) without back-pointers: at each
    frame, the cheapest path's cost into each layer, relative to the cheapest of all (with
    ``absolute``, the whole cost: passes over the same frames compare). Layer
    ``l`` moves by ``walks[k, l]`` (complex) into frame ``k`` (NaN: it restarts anywhere).
    With ``turn_cost`` the layers are a ring of yaws: between frames a path may move to the
    next one at that cost, or to any at ``jump_cost`` (nothing into a ``free`` frame: the
    phone saw its carry change), keeping its position; without, they are independent and
    the last row ranks them. ``visit``: (door costs per cell, cost per frame out of view):
    each layer's path is out of view, then in view once, then out of view
    (:attr:`RetrackConfig.away_cost`)."""
    n_r = walks.shape[1]
    acc = np.zeros((n_r, *grid.shape), np.float32)
    nxt = np.empty_like(acc)
    out = np.zeros(walks.shape)
    frac = np.zeros((n_r, 2))
    total = 0.0
    mins = np.empty(n_r, np.float32)
    doors = np.zeros((1, 1), np.float32) if visit is None else visit[0]
    away_cost = _BIG if visit is None else visit[1]
    aways = np.broadcast_to(np.asarray(away_cost, np.float32), (len(walks),))
    before = np.zeros(n_r, np.float32)
    after = np.full(n_r, _BIG, np.float32)
    if visit is not None:
        acc += doors  # in view at the first frame: as if just come in
    for k in range(len(walks)):
        if visit is not None:
            after = np.minimum(after, (acc + doors).min(axis=(1, 2))) + aways[k]
        # each layer shifted by its whole cells and relaxed (compiled: kernels.advance)
        restart = np.isnan(walks[k])
        whole = _whole_cells(frac, walks[k], grid.cell)
        kernels.advance(acc, nxt, whole, restart, steps)
        jump = 0.0 if free is not None and free[k] else (jump_cost or 0.0)
        kernels.layer_frame(
            nxt,
            acc,
            np.float32(turn_cost or 0.0),
            np.float32(jump),
            turn_cost is not None,
            before,
            doors,
            visit is not None,
            _emission_grid(emissions[k]),
            mins,
        )
        m = mins.copy()
        if visit is not None:
            before = before + aways[k]
            m = np.minimum(m, np.minimum(before, after))
        low = np.float32(m.min())
        acc -= low
        out[k] = m - low
        if absolute:
            total += float(low)
            out[k] += total
        if visit is not None:
            before -= low
            after -= low
    return out


def _emission_grid(e: np.ndarray | float) -> np.ndarray:
    """A frame's emissions as the kernels take them: float32 (rows, columns), or (1, 1) for
    one cost everywhere."""
    if isinstance(e, np.ndarray) and e.ndim == 2:
        return e if e.dtype == np.float32 else e.astype(np.float32)
    return np.full((1, 1), e, np.float32)


def _viterbi_path(
    grid: SiteGrid,
    emissions: Sequence[np.ndarray | float],
    u: np.ndarray,
    steps: np.ndarray,
    visit: Visit | None = None,
    spread: tuple[float, float] | None = None,
) -> np.ndarray:
    """The cheapest path's cell (row, col) at every frame; (-1, -1) where it is out of view.
    ``visit``: (door costs per cell, cost per frame out of view): the path is out of view,
    then in view, then out of view (None: in view throughout). With ``spread`` and
    ``grid.return_cost`` it may come back into view after leaving (:class:`_Returns`: near
    where the phone's walk from the cell it left puts the carrier; ``spread``: the variance of
    the cell left, m^2, and of the carrier's random walk about the phone's walk per frame,
    m^2)."""
    n = len(u)
    acc = np.zeros(grid.shape, np.float32)
    back = np.zeros((n, *grid.shape), np.int8)
    shifts = np.zeros((n, 2), int)
    frac = np.zeros((1, 2))
    restart: dict[int, tuple[int, int]] = {}
    left = np.full(n, -1, np.int64)  # out of view after a visit from k: the cell left at k-1
    before, after = np.float32(0.0 if visit is not None else _BIG), _BIG
    doors, aways = (np.zeros(grid.shape, np.float32), _BIG) if visit is None else visit
    aways = np.broadcast_to(np.asarray(aways, np.float32), (n,))
    returns = _Returns.of(grid, u, spread) if visit is not None else None
    if visit is not None:
        acc += doors  # in view at the first frame: as if just come in
    for k, uk in enumerate(u):
        away = aways[k]
        back_in = None if returns is None else returns.cost(k, after, doors)
        if visit is not None:
            after = _leave(acc, doors, after, left, k, returns) + away
        if np.isnan(uk):
            restart[k] = _restart(acc, float(before + doors.min()))
            back[k] = -1
        else:
            sx, sy = (int(c) for c in _whole_cells(frac, np.array([uk]), grid.cell)[0])
            shifts[k] = (sy, sx)
            moved = np.empty_like(acc)
            kernels.predecessors(acc, sy, sx, steps, back[k], moved)
            acc = moved
            if visit is not None:
                acc = _come_in(acc, back[k], np.float32(before), doors, back_in)
        if visit is not None:
            before = np.float32(before + away)
        acc = acc + emissions[k]
        low = np.float32(min(float(acc.min()), float(before), float(after)))
        acc -= low
        before, after = np.float32(before - low), np.float32(after - low)
    y0, x0 = np.unravel_index(int(np.argmin(acc)), acc.shape)
    state = "in"
    if min(before, after) < acc[y0, x0]:
        state = "before" if before <= after else "after"
    return _backtrack(back, shifts, restart, left, (int(y0), int(x0)), state)


def _restart(acc: np.ndarray, come: float) -> tuple[int, int]:
    """A frame of :func:`_viterbi_path` where the phone's walk restarts: the path may be
    anywhere (``acc`` set, in place, to the cheapest of the frame before and of coming in,
    ``come``); the cell it came from, or (-1, -1): out of view, not yet come in."""
    j = int(np.argmin(acc))
    y0, x0 = np.unravel_index(j, acc.shape)
    cell = (int(y0), int(x0)) if acc.flat[j] <= come else (-1, -1)
    acc[:] = min(float(acc.flat[j]), come)
    return cell


def _leave(
    acc: np.ndarray,
    doors: np.ndarray,
    after: np.float32,
    left: np.ndarray,
    k: int,
    returns: _Returns | None,
) -> np.float32:
    """:func:`_viterbi_path`'s out-of-view state after a visit at frame ``k``, before the
    frame's cost: the cheaper of staying out and leaving now from ``acc`` (the frame before)
    through a door; a leave now is recorded in ``left`` (and ``returns``)."""
    out_at = acc + doors
    j = int(np.argmin(out_at))
    if out_at.flat[j] < after:
        after, left[k] = out_at.flat[j], j
        if returns is not None:
            returns.left(k, j)
    return np.float32(after)


def _come_in(
    acc: np.ndarray,
    back_k: np.ndarray,
    before: np.float32,
    doors: np.ndarray,
    back_in: np.ndarray | None,
) -> np.ndarray:
    """``acc`` (in place) where coming into view (``before``, the out-of-view cost, plus the
    ``doors``' costs, summed in float32; back-pointer -2) or back into it (``back_in``,
    :class:`_Returns`: -3) is cheaper than having been in view (compiled:
    :func:`kernels.come_in`)."""
    doors = np.broadcast_to(doors, acc.shape)
    returns = back_in is not None
    kernels.come_in(acc, back_k, before, doors, acc if back_in is None else back_in, returns)
    return acc


class _Returns:
    """Coming back into view in :func:`_viterbi_path`: the carrier left the view at a cell and
    walked on where no camera saw them, and the phone's walk says where: they come back at a
    door near there. The cost of coming back at a cell is the out-of-view path's, plus
    ``return_cost``, the door's cost and the misfit between the cell and where the phone's
    walk from the cell left puts the carrier: d^2 / 2 (v0 + v * frames away), ``spread`` =
    (v0, v): the cell left is as uncertain as a detection, and the carrier moves about the
    phone's walk by the random walk of the path in view. A stranger who walks like the phone
    while the carrier is away is not where the carrier's walk leads: this is what lets a
    carrier come back without letting a path ride strangers (the one-visit model's reason).
    A carrier who was away went where no camera sees: the walk from the cell left must have
    taken them out of the covered area at some frame before they come back (a path that left
    a companion walking beside the carrier and "came back" on the carrier never walked out of
    view). Only the cheapest leave so far is kept (the out-of-view state's); across a restart
    of the walk (no walk) there is no coming back."""

    def __init__(self, grid: SiteGrid, u: np.ndarray, spread: tuple[float, float]) -> None:
        self.extra = grid.return_cost or 0.0
        self.walk = np.cumsum(np.nan_to_num(u, nan=0.0))
        self.seg = np.cumsum(np.isnan(u))
        self.v0, self.v = spread
        # the cells' centres per column (x) and per row (y): a squared distance to the grid is
        # their two squared differences summed, one vector each, not a complex grid per frame
        self.col_x = grid.lo[0] + np.arange(grid.shape[1]) * grid.cell
        self.row_y = grid.lo[1] + np.arange(grid.shape[0]) * grid.cell
        self.grid = grid
        self.at: tuple[int, complex] | None = None
        """The frame of the cheapest leave and the position left (the cell of the frame
        before it)."""
        self.out = False
        """Whether the walk from the leave has been out of the covered area since."""

    @classmethod
    def of(
        cls, grid: SiteGrid, u: np.ndarray, spread: tuple[float, float] | None
    ) -> _Returns | None:
        """The returns of a path over ``grid`` (None: the path may not come back, one visit)."""
        return cls(grid, u, spread) if spread and grid.return_cost is not None else None

    def left(self, k: int, flat: int) -> None:
        """The path's cheapest leave is now at frame ``k``, from cell ``flat``."""
        row, col = divmod(flat, len(self.col_x))
        self.at = (k, complex(self.col_x[col], self.row_y[row]))
        self.out = False

    def cost(self, k: int, after: float | np.floating, doors: np.ndarray) -> np.ndarray | None:
        """Cost of coming back into view at frame ``k`` at each cell (None: cannot)."""
        if self.at is None or after >= _BIG:
            return None
        j, xy = self.at
        if self.seg[k] != self.seg[j - 1 if j else 0] or k <= j:
            return None
        where = xy + (self.walk[k] - self.walk[j - 1 if j else 0])
        self.out = self.out or not self._covered(where)
        if not self.out:
            return None
        var = max(self.v0 + self.v * (k - j), 1e-6)
        # compiled (kernels.return_costs): the float32 door costs plus the float64 misfit,
        # as numpy's (after + extra + doors + d2 / (2 var)).astype(float32) computed them
        base = np.float32(after + self.extra)
        out = np.empty(self.grid.shape, np.float32)
        doors = np.broadcast_to(doors, out.shape)
        kernels.return_costs(
            base, doors, self.row_y, self.col_x, where.real, where.imag, 2 * var, out
        )
        return out

    def _covered(self, xy: complex) -> bool:
        """Whether ``xy`` is in the area the cameras cover (off the grid is not)."""
        covered = self.grid.covered
        if covered is None:
            return False
        (rows, cols), ok = self.grid.cells_of(np.array([[xy.real, xy.imag]]))
        return bool(ok[0] and covered[rows[0], cols[0]])


def _backtrack(
    back: np.ndarray,
    shifts: np.ndarray,
    restart: dict[int, tuple[int, int]],
    left: np.ndarray,
    cell: tuple[int, int],
    state: str,
) -> np.ndarray:
    """The cells of :func:`_viterbi_path`'s path, from its last ``cell`` and ``state`` (in,
    before or after a visit) back through its back-pointers."""
    n, shape = len(back), back.shape[1:]
    cells = np.full((n, 2), -1, int)
    y, x = cell
    for k in range(n - 1, -1, -1):
        if state == "before":
            break
        if state == "after":
            if left[k] >= 0:
                y, x = (int(v) for v in np.unravel_index(int(left[k]), shape))
                state = "in"
            continue
        cells[k] = (y, x)
        b = int(back[k, y, x])
        if b == -1:
            y, x = restart[k]
            state = {-1: "before", -3: "after"}.get(y, state)
        elif b in (-2, -3):
            state = "before" if b == -2 else "after"
        else:
            dy, dx = _OFFS[b]
            y = min(max(y - dy - int(shifts[k, 0]), 0), shape[0] - 1)
            x = min(max(x - dx - int(shifts[k, 1]), 0), shape[1] - 1)
    return cells


def _search_field(
    points: Sequence[np.ndarray], cfg: RetrackConfig, every: int = 1
) -> tuple[SiteGrid, list[np.ndarray | float]]:
    """The search's coarser grid and the emissions on it of every ``every``-th frame (the same
    for all phones)."""
    grid = SiteGrid(points, cfg.search_cell_m).with_visits(points, cfg)
    return grid, [grid.emission(p, cfg.det_sigma_m, cfg.miss_cost) for p in points[::every]]


@dataclass
class _Searcher:
    """One phone's alignment search over the coarse grid (:func:`_search`)."""

    frame_t: np.ndarray
    grid: SiteGrid
    emissions: Sequence[np.ndarray | float]
    steps: np.ndarray
    track: np.ndarray
    cfg: RetrackConfig
    carry_changes: np.ndarray | None
    visit: Visit | None
    lags: np.ndarray
    """Clock offsets of the offset and scale pass."""
    candidates: list[tuple[float, np.ndarray]] = field(default_factory=list)
    """The one-yaw search's best (clock offset, rotation) of distinct yaws, cheapest first
    (``ambiguity_candidates`` of them)."""

    def costs(self, walks: np.ndarray) -> np.ndarray:
        """The whole cost of each layer's best path (``walks``: frames x layers)."""
        return _layer_costs(
            self.grid, self.emissions, walks, self.steps, visit=self.visit, absolute=True
        )[-1]

    def walks(self, aligned: Sequence[tuple[float, np.ndarray | complex]]) -> np.ndarray:
        """The displacements of each (clock offset, rotation) as a layer."""
        n = len(self.frame_t)
        return np.column_stack(
            [
                _displacements(self.frame_t, self.track, lag, np.broadcast_to(a, n))
                for lag, a in aligned
            ]
        )

    def offset_and_scale(self, a: np.ndarray) -> tuple[float, float, float]:
        """(cost, clock offset, scale) of the best offset and scale under rotation ``a``."""
        scales = self.cfg.search_scales
        costs = self.costs(self.walks([(float(lg), a * sc) for lg in self.lags for sc in scales]))
        i = int(np.argmin(costs))
        return float(costs[i]), float(self.lags[i // len(scales)]), float(scales[i % len(scales)])

    def yaw(self, lag_s: float, scale: float, steady: bool = False) -> np.ndarray | None:
        return _yaw_search(
            self.frame_t,
            self.grid,
            self.emissions,
            self.steps,
            self.track,
            lag_s,
            scale,
            self.cfg,
            self.carry_changes,
            self.visit,
            steady,
        )

    def changes(self, lag_s: float) -> bool:
        """Whether the phone saw its carry change within the log (at clock offset ``lag_s``)."""
        return bool(_carry_frames(self.frame_t, self.carry_changes, lag_s)[1:].any())

    def steady(self, coarse: np.ndarray) -> tuple[float, np.ndarray] | None:
        """The one-yaw search: (clock offset, rotation per frame) or None without a walk."""
        cfg = self.cfg
        rot = np.exp(1j * np.radians(np.arange(0.0, 360.0, cfg.yaw_step_deg)))
        if np.isnan(self.walks([(float(lg), 1.0 + 0j) for lg in coarse])).all():
            return None
        changed = any(self.changes(float(lg)) for lg in coarse)
        found = self._per_stretch(coarse) if changed else self._one_yaw(coarse, rot)
        if not found:
            return None
        refined = [(*self.offset_and_scale(a), a) for _, a in found]
        _, lag, scale, a = min(refined, key=lambda c: c[0])
        if changed:
            yaw = self.yaw(lag, scale, steady=True)
            if yaw is not None:
                return lag, yaw
        return lag, a * scale

    def _one_yaw(self, coarse: np.ndarray, rot: np.ndarray) -> list[tuple[float, np.ndarray]]:
        """The steady search without carry changes: every (offset, yaw) at once; the best
        distinct yaws, the first ``search_candidates`` to refine (the first
        ``ambiguity_candidates`` kept as :attr:`candidates`)."""
        cfg, n = self.cfg, len(self.frame_t)
        costs = self.costs(self.walks([(float(lg), r) for lg in coarse for r in rot]))
        k = max(cfg.search_candidates, cfg.ambiguity_candidates)
        found = [
            (float(coarse[i // len(rot)]), np.full(n, rot[i % len(rot)]))
            for i in _distinct_best(costs.reshape(len(coarse), len(rot)), k)
        ]
        self.candidates = found[: cfg.ambiguity_candidates]
        return found[: cfg.search_candidates]

    def _per_stretch(self, coarse: np.ndarray) -> list[tuple[float, np.ndarray]]:
        """The steady search with carry changes: a yaw per stretch between the changes the
        phone saw, at every offset and first scale; the cheapest to refine (empty: none)."""
        cfg = self.cfg
        found: list[tuple[float, np.ndarray]] = []
        for lg in coarse:
            for sc in cfg.search_first_scales:
                yaw = self.yaw(float(lg), sc, steady=True)
                if yaw is not None:
                    found.append((float(lg), yaw))
        if not found:
            return found
        order = np.argsort(self.costs(self.walks(found)))
        self.candidates = [found[i] for i in order[: cfg.ambiguity_candidates]]
        return [found[i] for i in order[: cfg.search_candidates]]

    def yaw_path(self, lag_s: float) -> tuple[float, np.ndarray] | None:
        """The yaw-per-frame search started at clock offset ``lag_s``, started again elsewhere
        when its offset ends at the edge of the range: (clock offset, rotation per frame)."""

        def from_start(start: float) -> tuple[float, float, float] | None:
            yaw = self.yaw(start, 1.0)
            return None if yaw is None else self.offset_and_scale(yaw)

        best = from_start(lag_s)
        if best is None:
            return None
        if abs(best[1]) >= self.lags[-1] - 1e-9:
            # an offset at the edge of the range: the yaw search from this start went wrong (a
            # wrong yaw fits no offset, and the pass runs to the edge); start it again elsewhere
            for start in self.cfg.search_starts_s:
                if abs(start - lag_s) > self.cfg.search_lag_step_s:
                    found = from_start(start)
                    if found is not None and found[0] < best[0]:
                        best = found
        _, lag, scale = best
        yaw = self.yaw(lag, scale)
        return None if yaw is None else (lag, yaw)


def _search(
    frame_t: np.ndarray,
    points: Sequence[np.ndarray],
    track: np.ndarray,
    lag_s: float,
    acfg: AlignConfig,
    cfg: RetrackConfig,
    carry_changes: np.ndarray | None = None,
    space: tuple[SiteGrid, Sequence[np.ndarray | float]] | None = None,
    visit: Visit | None = None,
    alternatives: list[tuple[float, np.ndarray]] | None = None,
) -> tuple[float, np.ndarray] | None:
    """The phone's alignment found from the detections alone (None without a walk), the
    cheaper of two searches:

    * **one yaw** (a yaw per stretch between the carry changes the phone saw): every yaw at
      every ``search_const_lag_step_s`` clock offset at the nominal step, then the clock
      offset and step scale under the ``search_candidates`` best yaws;
    * **a yaw per frame** (:func:`_yaw_search`, for carry changes the phone missed): at clock
      offset ``lag_s``, then the clock offset and step scale under that yaw, then the yaw
      again under those; started again elsewhere when the offset ends at the edge of its
      range.

    Each is judged by the cost of its best path, the yaw path's changes of yaw included.
    ``space``: the search grid and its emissions (:func:`_search_field`); ``visit``: the
    phone's costs of coming into view and of being out of it (default: the grid's).
    ``alternatives``, when given, receives the other alignments the searches found (the
    one-yaw search's best yaws, the yaw path): what :meth:`_Follower.settle` weighs the
    found one against."""
    n = len(frame_t)
    grid, emissions = space or _search_field(points, cfg)
    dt = float(np.median(np.diff(frame_t))) / 1e9 if n > 1 else 1.0
    every = lag_grid(acfg)
    lags = every[:: max(int(round(cfg.search_lag_step_s / acfg.lag_step_s)), 1)]
    coarse = every[:: max(int(round(cfg.search_const_lag_step_s / acfg.lag_step_s)), 1)]
    searcher = _Searcher(
        frame_t,
        grid,
        emissions,
        _step_costs(grid.cell, dt, cfg, cfg.search_walk_sigma_mps),
        track,
        cfg,
        carry_changes,
        grid.visit if visit is None else visit,
        lags,
    )
    one = searcher.steady(coarse)
    path = searcher.yaw_path(lag_s)
    if alternatives is not None:
        alternatives.extend(searcher.candidates)
        if path is not None:
            alternatives.append(path)
    if one is None or path is None:
        return one or path
    costs = searcher.costs(searcher.walks([path, one]))
    costs[0] += _yaw_changes_cost(path[1], cfg, _carry_frames(frame_t, carry_changes, path[0]))
    return (path, one)[int(np.argmin(costs))]


def _distinct_best(costs: np.ndarray, k: int) -> list[int]:
    """The flat indices of the ``k`` cheapest (offset, yaw) cells of ``costs`` (offsets x yaws)
    whose yaws are more than one step apart from each other's (a ring)."""
    n_yaw = costs.shape[1]
    best_per_yaw = costs.min(axis=0)
    chosen: list[int] = []
    for j in np.argsort(best_per_yaw, kind="stable"):
        gaps = [min(abs(int(j) - c), n_yaw - abs(int(j) - c)) for c in chosen]
        if all(g > 0 for g in gaps):
            chosen.append(int(j))
        if len(chosen) == k:
            break
    return [int(np.argmin(costs[:, j])) * n_yaw + j for j in chosen]


def _carry_frames(
    frame_t: np.ndarray, carry_changes: np.ndarray | None, lag_s: float
) -> np.ndarray:
    """Which frames follow a carry change the phone saw (phone-clock times, offset ``lag_s``)."""
    free = np.zeros(len(frame_t), bool)
    if carry_changes is not None and len(carry_changes):
        at = np.searchsorted(frame_t, np.asarray(carry_changes) - int(round(lag_s * 1e9)))
        free[at[at < len(frame_t)]] = True
    return free


def _yaw_changes_cost(a: np.ndarray, cfg: RetrackConfig, free: np.ndarray | None = None) -> float:
    """What :func:`_yaw_search` charges for the changes of a yaw path ``a`` (complex per frame):
    ``yaw_step_cost`` a step, ``yaw_jump_cost`` a larger change; nothing into a ``free`` frame
    (after a carry change the phone saw)."""
    step = np.radians(cfg.yaw_step_deg)
    turns = np.abs(np.angle(a[1:] * np.conj(a[:-1]))) / step
    keep = ~np.isnan(turns) if free is None else ~np.isnan(turns) & ~free[1:]
    turns = np.round(turns[keep])
    return float(cfg.yaw_step_cost * (turns == 1).sum() + cfg.yaw_jump_cost * (turns > 1).sum())


def _yaw_search(
    frame_t: np.ndarray,
    grid: SiteGrid,
    emissions: Sequence[np.ndarray | float],
    steps: np.ndarray,
    track: np.ndarray,
    lag_s: float,
    scale: float,
    cfg: RetrackConfig,
    carry_changes: np.ndarray | None = None,
    visit: Visit | None = None,
    steady: bool = False,
) -> np.ndarray | None:
    """The walk's rotation per frame (complex, with ``scale``): the yaw through which the
    cheapest path over (yaw, position) passes at that frame, from a forward and a backward
    pass (each layer's best cost summed: the two passes' best cells may differ, a close
    approximation of the max-marginal at O(frames x yaws) memory); None without a walk.
    ``carry_changes``: phone-clock times at which the phone saw its carry change (any yaw
    may follow, at no cost). ``steady``: the yaw changes only there."""
    n = len(frame_t)
    yaws = np.radians(np.arange(0.0, 360.0, cfg.yaw_step_deg))
    rot = np.exp(1j * yaws)
    u = _displacements(frame_t, track, lag_s, np.full(n, scale + 0j))
    if np.isnan(u).all():
        return None
    free = _carry_frames(frame_t, carry_changes, lag_s)
    costs = (_STEADY, _STEADY) if steady else (cfg.yaw_step_cost, cfg.yaw_jump_cost)
    visit = grid.visit if visit is None else visit
    forward = _layer_costs(grid, emissions, u[:, None] * rot[None, :], steps, *costs, free, visit)
    # backward: frame k+1 -> k moves by -u[k+1] (a frame after a gap starts afresh), through
    # the transition the forward pass takes into k+1
    u_back = np.r_[0j, -u[:0:-1]]
    free_back = np.r_[False, free[:0:-1]]
    visit_back = None if visit is None else (visit[0], _reversed(visit[1]))
    backward = _layer_costs(
        grid, emissions[::-1], u_back[:, None] * rot[None, :], steps, *costs, free_back, visit_back
    )[::-1]
    both = forward + backward
    if steady:
        # one yaw per stretch between carry changes: the layer whose paths cost least over it
        # (frame by frame, ties where the path is out of view would pick at random)
        seg = np.cumsum(free)
        sums = np.zeros((int(seg[-1]) + 1, len(rot)))
        np.add.at(sums, seg, both)
        choice = np.argmin(sums, axis=1)[seg]
    else:
        choice = _yaw_choice(both, costs, free)
    return scale * rot[choice]


def _yaw_choice(both: np.ndarray, costs: tuple[float, float], free: np.ndarray) -> np.ndarray:
    """The yaw layer of each frame from the forward+backward costs ``both`` (frames x yaws, a
    ring): a Viterbi over each frame's excess over its best layer, with the search's costs of
    a step and a jump (nothing into a ``free`` frame). Each frame's own best layer would
    flicker where two yaws tie (about a carry change: the excess of either is small), and each
    flicker would be charged as two jumps when the search is compared with the one-yaw search.
    Written out: 24 states, no library's HMM takes a cost matrix this simply."""
    n, m = both.shape
    excess = both - both.min(axis=1, keepdims=True)
    ring = np.abs(np.arange(m)[:, None] - np.arange(m)[None, :])
    ring = np.minimum(ring, m - ring)
    trans = np.where(ring == 0, 0.0, np.where(ring == 1, costs[0], costs[1]))
    anyway = np.zeros_like(trans)
    back = np.zeros((n, m), np.int64)
    acc = excess[0].copy()
    for k in range(1, n):
        cand = acc[:, None] + (anyway if free[k] else trans)
        back[k] = np.argmin(cand, axis=0)
        acc = cand[back[k], np.arange(m)] + excess[k]
    choice = np.empty(n, np.int64)
    choice[-1] = int(np.argmin(acc))
    for k in range(n - 1, 0, -1):
        choice[k - 1] = back[k, choice[k]]
    return choice


def _refit(
    frame_t: np.ndarray,
    hits: dict[int, np.ndarray],
    track: np.ndarray,
    acfg: AlignConfig,
    cfg: RetrackConfig,
    carry_changes: np.ndarray | None = None,
    prior: np.ndarray | None = None,
) -> tuple[float, np.ndarray] | None:
    """Clock offset and ``a`` per frame refitted from the detections on the path (each frame's
    centred ``align_window_s`` window; one offset, the one these fits explain best). A window
    does not reach across a carry change the phone saw (``carry_changes``, phone-clock
    times): the yaw changes there at once, and a window across it would fit neither yaw (on
    `students001` seed 2 a phone taken out of a back pocket turned 83 deg; the smeared yaw
    lost the carrier for another walker). ``prior``: the alignment the path was followed
    under, kept in a carry too few of the path's detections fall in (:func:`_whole_fit`)."""
    ks = np.array(sorted(hits))
    if len(ks) < cfg.min_align_frames:
        return None
    n = len(frame_t)
    dt = float(np.median(np.diff(frame_t))) / 1e9 if n > 1 else 1.0
    half = max(int(round(cfg.align_window_s / 2 / dt)), 1)
    det = np.array([[frame_t[k], *hits[k]] for k in ks], float)
    at = frame_t[ks].astype(float)
    half_v = cfg.velocity_window_s / 2
    zt = visual_velocity(det, at, half_v)
    idx = np.arange(n)
    best: tuple[float, float, np.ndarray] | None = None
    for lag in lag_grid(acfg):
        seg = np.cumsum(_carry_frames(frame_t, carry_changes, float(lag)))
        seg -= seg[0]
        first = np.flatnonzero(np.r_[True, np.diff(seg) != 0])
        lo = np.maximum(idx - half, first[seg])
        hi = np.minimum(idx + half + 1, np.r_[first[1:], n][seg])
        zl = visual_velocity(track, at + lag * 1e9, half_v)
        ok = ~(np.isnan(zl) | np.isnan(zt))
        sums = [np.zeros(n, complex), np.zeros(n), np.zeros(n), np.zeros(n)]
        sums[0][ks[ok]] = zt[ok] * np.conj(zl[ok])
        sums[1][ks[ok]] = np.abs(zl[ok]) ** 2
        sums[2][ks[ok]] = np.abs(zt[ok]) ** 2
        sums[3][ks[ok]] = 1.0
        cum = [np.r_[0, np.cumsum(s)] for s in sums]
        sw, pw, tw, nw = (c[hi] - c[lo] for c in cum)
        a, r = best_fit(sw, pw, tw, nw, acfg)
        use = nw >= cfg.min_align_frames
        if not use.any():
            continue
        resid = float((r * nw)[use].sum() / nw[use].sum())
        if best is None or resid < best[0]:
            whole = _whole_fit(cum, seg, first, acfg, cfg.min_align_frames, prior)
            best = (resid, float(lag), np.where(use, a, whole))
    return None if best is None else (best[1], best[2])


def _whole_fit(
    cum: list[np.ndarray],
    seg: np.ndarray,
    first: np.ndarray,
    acfg: AlignConfig,
    least: int,
    prior: np.ndarray | None = None,
) -> np.ndarray:
    """Per frame, the alignment fitted to all the detections of its carry (``seg``: the carry
    of each frame, ``first``: each carry's first frame; ``cum``: the refit's cumulative sums),
    or, where its carry holds fewer than ``least``, ``prior`` (the alignment the path was
    followed under, where it has one) when the phone saw its carry change, else the fit to all
    of the path's (:meth:`_Follower._refit` keeps whichever path costs less). It
    stands where no refit window holds enough detections (before a visit, after it, across a
    long absence): the nearest window's fit there rests on the visit's first or last few
    frames, and a carrier standing there says nothing of the step or the yaw (PETS footage,
    seed 6: P05 came back standing, her phone read 70 deg off over her first visit, which was
    never found). A carry the path hardly sees says nothing of its own alignment either, and
    another carry's is another yaw: the phone was turned as it went into a pocket or a bag
    (PETS footage with phones, `n` seed 3: P05's phone changed carry at 9.3 s, the path saw
    her in fewer than 10 frames before; the fit of the rest put the first carry at 23 deg,
    the search at 45 deg, whose path cost 18 less)."""
    n = len(seg)
    ends = np.r_[first[1:], n]
    sw, pw, tw, nw = (c[ends[seg]] - c[first[seg]] for c in cum)
    per_carry, _ = best_fit(sw, pw, tw, nw, acfg)
    whole, _ = best_fit(cum[0][-1:], cum[1][-1:], cum[2][-1:], cum[3][-1:], acfg)
    if prior is not None and len(first) > 1:
        # a prior with no alignment at a frame (an identity's chains not there) has none to keep
        whole = np.where(np.isfinite(prior), prior, whole[0])
    return np.where(nw >= least, per_carry, whole)


def _nearest(points: np.ndarray, xy: Sequence[float] | np.ndarray, within_m: float) -> int | None:
    """Index of the detection in ``points`` nearest ``xy``, if it is within ``within_m``."""
    if not len(points):
        return None
    d = np.hypot(points[:, 0] - xy[0], points[:, 1] - xy[1])
    j = int(np.argmin(d))
    return j if d[j] < within_m else None


class _Published(NamedTuple):
    """What :func:`_publish` makes of one path."""

    xy: dict[int, tuple[float, float]]
    """Positions to publish (frame index -> xy)."""
    seen: set[int]
    """The frames published on a detection."""
    hits: dict[int, np.ndarray]
    """The detections on the path (frame index -> xy)."""
    withheld: float
    """Seconds of stretches withheld for want of evidence."""
    twinned: list[int]
    """The frames of the stretches withheld because a twin walks beside them
    (:func:`_untwinned`): on the carrier or on somebody who moves like them."""


def _publish(
    frame_t: np.ndarray,
    points: Sequence[np.ndarray],
    grid: SiteGrid,
    cells: np.ndarray,
    u: np.ndarray,
    cfg: RetrackConfig,
    radio_gain: np.ndarray | None = None,
) -> _Published:
    """Positions to publish, the seen frames, the detections on the path, the seconds of
    stretches withheld for want of evidence and the frames of those withheld as twins.

    Seen frames less than ``fill_s`` apart form a stretch; a stretch shorter than
    ``min_stretch_s`` is dropped, and so is one whose detections share less than
    ``min_evidence`` of motion changes with the phone (:func:`_evidence`: a stranger who
    walks straight fits a phone of unknown yaw as well as its carrier) and of its RSSI
    (``radio_gain``, per frame: :meth:`~trackctl.vmtrack.radio.RadioEvidence.gain`, summed
    over the stretch: a straight walk past an AP that hears the phone then, and not a
    stranger's while the carrier is away); two stretches at most
    ``unseen_s`` apart are joined when
    the phone's walk across the gap lands within ``unseen_m`` (+ 15 % of the distance walked)
    of where the next one starts (the carrier walked where no camera saw them). A published position
    is the phone's walk plus the detections' offset from it: smoothed over ``smooth_s`` at
    seen frames, linear between them."""
    hits = _path_hits(points, grid.xy(cells), u, cfg.gate_m)
    if not hits:
        return _Published({}, set(), hits, 0.0, [])
    walk = np.cumsum(np.nan_to_num(u, nan=0.0))
    seg = np.cumsum(np.isnan(u))  # the walk restarts where the phone has none
    t = frame_t / 1e9
    kept, short = _stretches(np.array(sorted(hits)), t, seg, cfg)
    withheld = 0.0
    hops = _hops(points, hits, frame_t, cfg) if cfg.min_evidence is not None else None
    if cfg.jump_m is not None:
        track = _walk_track(frame_t, walk)
        kept, withheld = _one_carrier(
            kept,
            hits,
            walk,
            t,
            cfg,
            lambda r: _evidence(frame_t, r, hits, track, cfg, radio_gain, hops),
        )
    if cfg.min_evidence is not None:
        kept, unproven = _with_evidence(
            kept, frame_t, hits, walk, cfg, radio_gain, cfg.min_evidence, hops
        )
        withheld += unproven
    twins: list[np.ndarray] = []
    if cfg.twin_share is not None and radio_gain is None:
        kept, twins = _untwinned(kept, points, hits, walk, t, seg, cfg)
        withheld += sum(float(t[r[-1]] - t[r[0]]) for r in twins)
    twinned = [int(k) for r in twins for k in r]
    if not kept:
        return _Published({}, set(), hits, withheld, twinned)
    kept = _with_waypoints(kept, short, hits, walk, t, seg, cfg)
    seen = np.concatenate(kept)
    smooth = _smoothed_offsets(seen, hits, walk, t, seg, cfg.smooth_s)
    every = np.unique(np.concatenate(_published_frames(kept, smooth, walk, t, seg, cfg)))
    offsets = np.interp(every, seen, smooth.real) + 1j * np.interp(every, seen, smooth.imag)
    xy = _turned_gaps(every, walk[every] + offsets, np.sort(seen), walk, t)
    out = {int(k): (float(p.real), float(p.imag)) for k, p in zip(every, xy, strict=True)}
    return _Published(out, set(int(k) for k in seen), hits, withheld, twinned)


TURN_GAP_S = 2.0
"""A gap between two seen frames at least this long is filled by the turned walk
(:func:`_turned_gaps`); shorter ones keep the offsets' line."""
TURN_MAX_DEG, TURN_SCALE = 45.0, (0.8, 1.25)
"""The turn and scale a gap's walk may take: a heading off by up to 45 deg and a step 20-25 %
off (:func:`_turned_gaps`); beyond, the two ends are not one walk's and the offsets' line stays."""


def _turned_gaps(
    every: np.ndarray, xy: np.ndarray, seen: np.ndarray, walk: np.ndarray, t: np.ndarray
) -> np.ndarray:
    """The published positions ``xy`` (at frames ``every``) with each gap of at least
    :data:`TURN_GAP_S` between two seen frames filled by the phone's walk turned and scaled
    to run from the position before the gap to the one after it, where the walk there goes
    somewhere (its end at least half its length from its start, and 2 m long) and the turn
    is plausible (:data:`TURN_MAX_DEG`, :data:`TURN_SCALE`).

    Out of view, dead reckoning errs most by its heading and step length, which turn and
    stretch the walk about where it left; spreading the misfit along the gap as a line
    (the offsets' interpolation) leaves the middle of a long detour metres off (PETS footage
    with phones: P05's 15 s out of view, published over 1 m from her for 3-5 s of it). The
    turned walk meets both ends exactly, as the line does."""
    pos = {int(k): i for i, k in enumerate(every)}
    out = xy.copy()
    for a, b in zip(seen[:-1].tolist(), seen[1:].tolist(), strict=True):
        if t[b] - t[a] < TURN_GAP_S or not all(k in pos for k in (a, b, b - 1)):
            continue
        c = _gap_turn(walk, a, b, xy[pos[a]], xy[pos[b]])
        if c is None:
            continue
        gap = np.arange(a + 1, b)
        out[[pos[int(k)] for k in gap]] = xy[pos[a]] + (walk[gap] - walk[a]) * c
    return out


def _gap_turn(walk: np.ndarray, a: int, b: int, start: complex, end: complex) -> complex | None:
    """The turn and scale (complex) that take the phone's walk from frame ``a`` to ``b`` onto
    the run from ``start`` to ``end``, where the walk goes somewhere (its end at least half
    its length from its start, and 2 m long) and the turn is plausible (:data:`TURN_MAX_DEG`,
    :data:`TURN_SCALE`); None otherwise."""
    d = walk[b] - walk[a]
    length = _walked(walk, a, b)
    if length < 2.0 or abs(d) < 0.5 * length:
        return None
    c = complex((end - start) / d)
    if not TURN_SCALE[0] <= abs(c) <= TURN_SCALE[1] or abs(np.angle(c, deg=True)) > TURN_MAX_DEG:
        return None
    return c


def _path_hits(
    points: Sequence[np.ndarray], path: np.ndarray, u: np.ndarray, gate_m: float
) -> dict[int, np.ndarray]:
    """The detection nearest the path at each frame where the phone walks, within ``gate_m``
    (frame index -> xy)."""
    hits: dict[int, np.ndarray] = {}
    for k, p in enumerate(points):
        if np.isnan(u[k]):
            continue
        j = _nearest(p, path[k], gate_m)
        if j is not None:
            hits[k] = p[j]
    return hits


def _stretches(
    ks: np.ndarray, t: np.ndarray, seg: np.ndarray, cfg: RetrackConfig
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The seen frames ``ks`` cut into stretches (gaps over ``fill_s`` or a restart of the
    walk): those of ``min_stretch_s`` or more, and the shorter ones."""
    cut = np.flatnonzero((np.diff(t[ks]) > cfg.fill_s) | (np.diff(seg[ks]) != 0)) + 1
    parts = np.split(ks, cut)
    long = [t[r[-1]] - t[r[0]] >= cfg.min_stretch_s for r in parts]
    return [r for r, k in zip(parts, long, strict=True) if k], [
        r for r, k in zip(parts, long, strict=True) if not k
    ]


def _with_waypoints(
    kept: list[np.ndarray],
    short: list[np.ndarray],
    hits: dict[int, np.ndarray],
    walk: np.ndarray,
    t: np.ndarray,
    seg: np.ndarray,
    cfg: RetrackConfig,
) -> list[np.ndarray]:
    """``kept`` (in time order) with each ``short`` stretch between two of them that the
    phone's walk does not join directly, but joins to both (:func:`_joined`): a waypoint. A
    short stretch alone is what a path passing a stranger picks up (``min_stretch_s``); one
    that the carrier's dead reckoning reaches from the stretch before and leaves for the one
    after, each within the drift the gaps allow, is the carrier, seen briefly between two long
    absences, and it shortens the gaps (PETS footage with phones, `n` seeds 18 and 59: P05
    back in view for 4-5 s between her 16 s out of view and a 4 s miss, the two gaps 25 s
    together, over ``unseen_s``, so the 25 s were left unpublished)."""
    out = list(kept)
    for w in short:
        # the stretches part the seen frames in time (:func:`_stretches`): ``w`` lies wholly
        # between the ``j``-th kept stretch and the one before it
        j = int(np.searchsorted([int(r[0]) for r in out], int(w[0])))
        if j == 0 or j == len(out):
            continue
        a, b = out[j - 1], out[j]
        if _joined([a, b], hits, walk, t, seg, cfg) == [True]:
            continue
        if _joined([a, w, b], hits, walk, t, seg, cfg) == [True, True]:
            out.insert(j, w)
    return out


def _joined(
    kept: list[np.ndarray],
    hits: dict[int, np.ndarray],
    walk: np.ndarray,
    t: np.ndarray,
    seg: np.ndarray,
    cfg: RetrackConfig,
) -> list[bool]:
    """:func:`_joins` of ``kept``, their offsets smoothed over them alone."""
    smooth = _smoothed_offsets(np.concatenate(kept), hits, walk, t, seg, cfg.smooth_s)
    return _joins(kept, smooth, walk, t, seg, cfg)


def _offsets(r: np.ndarray, hits: dict[int, np.ndarray], walk: np.ndarray) -> np.ndarray:
    """The detections' offsets from the phone's walk at the frames ``r`` (complex)."""
    return np.array([complex(*hits[k]) for k in r]) - walk[r]


def _breaks(z: np.ndarray, t: np.ndarray, window_s: float) -> np.ndarray:
    """At each frame, how far apart the lines fitted (least squares) to the complex series
    ``z`` (at times ``t``) over the ``window_s`` before the frame and over the ``window_s``
    from it are there (0 where either side holds fewer than 4 frames)."""
    i = np.arange(len(z))
    lo = np.searchsorted(t, t - window_s, side="left")
    hi = np.searchsorted(t, t + window_s, side="right")
    tc = t - t[0]
    sums = [np.concatenate([[0], np.cumsum(v)]) for v in (np.ones(len(t)), tc, tc**2, z, tc * z)]

    def line_at(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        n, st, stt, sz, stz = (c[b] - c[a] for c in sums)
        den = n * stt - st**2
        flat = np.abs(den) <= 1e-12
        slope = np.where(flat, 0.0, (n * stz - st * sz) / np.where(flat, 1.0, den))
        return (sz - slope * st) / np.maximum(n, 1) + slope * tc

    d = np.zeros(len(z))
    ok = (i - lo >= 4) & (hi - i >= 4)
    d[ok] = np.abs(line_at(lo, i) - line_at(i, hi))[ok]
    return d


def _jumps(
    off: np.ndarray, det: np.ndarray, t: np.ndarray, window_s: float, jump_m: float
) -> list[int]:
    """Where (indices) the path went from one person to another: both the detections' offsets
    ``off`` from the phone's walk and the detections ``det`` themselves break by more than
    ``jump_m`` (:func:`_breaks`; a steady drift, the walk's yaw or step-length error, fits one
    line; the walk breaking alone is the phone's own error, the detections alone a person
    moving as the phone says); the middle of each run of such frames."""
    d = np.minimum(_breaks(off, t, window_s), _breaks(det, t, window_s))
    edges = np.flatnonzero(np.diff(np.r_[0, (d > jump_m).astype(np.int8), 0]))
    return [int(a + np.argmax(d[a:b])) for a, b in zip(edges[0::2], edges[1::2], strict=True)]


def _one_carrier(
    kept: list[np.ndarray],
    hits: dict[int, np.ndarray],
    walk: np.ndarray,
    t: np.ndarray,
    cfg: RetrackConfig,
    evidence: Callable[[np.ndarray], float],
) -> tuple[list[np.ndarray], float]:
    """The stretches without the pieces that are somebody else, and their seconds.

    A carrier moves about their phone's walk slowly (the random walk); a path that goes from
    one person to another while both are seen jumps by their distance (two people walking
    side by side move alike, and a phone's walk fits both). Each stretch is cut where its
    detections' offset from the walk jumps (:func:`_jumps`); pieces the walk ties together
    (one's end offset within ``jump_m`` of the next one's start: the path left somebody and
    came back to them) are one person, and of a stretch's people only the one with the most
    evidence (``evidence`` of each piece, summed) is kept; pieces shorter than
    ``min_stretch_s`` go too."""
    out: list[np.ndarray] = []
    dropped = 0.0
    assert cfg.jump_m is not None
    for r in kept:
        off = _offsets(r, hits, walk)
        cuts = _jumps(off, off + walk[r], t[r], cfg.jump_window_s, cfg.jump_m)
        if not cuts:
            out.append(r)
            continue
        pieces = np.split(np.arange(len(r)), cuts)
        people: list[list[np.ndarray]] = []
        for p in pieces:
            start = off[p][t[r[p]] <= t[r[p[0]]] + cfg.jump_window_s].mean()
            ends = [
                off[g[-1]][t[r[g[-1]]] >= t[r[g[-1][-1]]] - cfg.jump_window_s].mean()
                for g in people
            ]
            near = [abs(e - start) for e in ends]
            if near and min(near) <= cfg.jump_m:
                people[int(np.argmin(near))].append(p)
            else:
                people.append([p])
        best = max(people, key=lambda g: sum(evidence(r[p]) for p in g))
        for g in people:
            for p in g:
                long = t[r[p[-1]]] - t[r[p[0]]] >= cfg.min_stretch_s
                if g is best and long:
                    out.append(r[p])
                else:
                    dropped += float(t[r[p[-1]]] - t[r[p[0]]])
    return out, dropped


def _twin(
    r: np.ndarray,
    points: Sequence[np.ndarray],
    hits: dict[int, np.ndarray],
    t: np.ndarray,
    cfg: RetrackConfig,
) -> int:
    """The most frames of the stretch ``r`` at which one other walker is seen at a steady
    offset from its detections, over the gate: followed from each detection of the stretch's
    middle frame, both ways, the offset an average over ~1 s (a walker 1 m/s off the
    stretch's motion falls behind by 1 m and is lost), each frame's detection within two
    detection sigmas of it."""
    mid = len(r) // 2
    best = 0
    for p in points[r[mid]]:
        c0 = p - hits[r[mid]]
        if np.hypot(*c0) <= cfg.gate_m:
            continue
        matched = 0
        for order in (r[mid:], r[mid - 1 :: -1] if mid else r[:0]):
            c, last = c0, t[r[mid]]
            for k in order:
                j = _nearest(points[k], hits[k] + c, 2 * cfg.det_sigma_m)
                if j is None or np.hypot(*(points[k][j] - hits[k])) <= cfg.gate_m:
                    continue
                w = 1.0 - math.exp(-abs(t[k] - last))
                c, last, matched = c + w * (points[k][j] - hits[k] - c), t[k], matched + 1
        best = max(best, matched)
    return best


def _untwinned(
    kept: list[np.ndarray],
    points: Sequence[np.ndarray],
    hits: dict[int, np.ndarray],
    walk: np.ndarray,
    t: np.ndarray,
    seg: np.ndarray,
    cfg: RetrackConfig,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The stretches without those another walker moves with (:func:`_twin` in at least
    ``twin_share`` of their frames) and that the phone's walk ties to no other stretch kept,
    and those dropped.

    Two people walking the same way a few metres apart (farther than the gate: not a group)
    move alike, and motion cannot say which of them carries the phone: the path may sit on
    either. Where the walk ties such a stretch to another (the gap between them walked on the
    phone lands within ``unseen_m`` + 15 % of the distance walked of it, as publication
    bridges them), the carrier is the one the rest of the path leads to; alone, it is a guess."""
    assert cfg.twin_share is not None
    tied = [False] * len(kept)
    for j in range(len(kept) - 1):
        a, b = kept[j], kept[j + 1]
        end = _offsets(a[t[a] >= t[a[-1]] - cfg.smooth_s], hits, walk).mean()
        start = _offsets(b[t[b] <= t[b[0]] + cfg.smooth_s], hits, walk).mean()
        if _bridged(int(a[-1]), int(b[0]), float(abs(start - end)), walk, t, seg, cfg):
            tied[j] = tied[j + 1] = True
    # a tied stretch is kept whatever walks beside it: the twin search (a loop over frames)
    # runs only on the others
    alone = [
        not ti and _twin(r, points, hits, t, cfg) >= cfg.twin_share * len(r)
        for r, ti in zip(kept, tied, strict=True)
    ]
    out = [r for r, drop in zip(kept, alone, strict=True) if not drop]
    return out, [r for r, drop in zip(kept, alone, strict=True) if drop]


def _walk_track(frame_t: np.ndarray, walk: np.ndarray) -> np.ndarray:
    """The phone's aligned walk as (t_ns, x, y) rows, one per frame."""
    return np.column_stack([frame_t.astype(float), walk.real, walk.imag])


def _with_evidence(
    kept: list[np.ndarray],
    frame_t: np.ndarray,
    hits: dict[int, np.ndarray],
    walk: np.ndarray,
    cfg: RetrackConfig,
    radio_gain: np.ndarray | None,
    least: float,
    hops: np.ndarray | None = None,
) -> tuple[list[np.ndarray], float]:
    """The stretches with at least ``least`` evidence (:func:`_evidence`, the path's ``hops``
    counting nothing), and the seconds of those without."""
    t = frame_t / 1e9
    track = _walk_track(frame_t, walk)
    judged = [(r, _evidence(frame_t, r, hits, track, cfg, radio_gain, hops) >= least) for r in kept]
    withheld = float(sum(t[r[-1]] - t[r[0]] for r, ok in judged if not ok))
    return [r for r, ok in judged if ok], withheld


def _smoothed_offsets(
    seen: np.ndarray,
    hits: dict[int, np.ndarray],
    walk: np.ndarray,
    t: np.ndarray,
    seg: np.ndarray,
    smooth_s: float,
) -> np.ndarray:
    """The detections' offset from the phone's walk at each seen frame, Gaussian-smoothed over
    ``smooth_s`` within one stretch of walk (complex)."""
    off = np.array([complex(*hits[k]) for k in seen]) - walk[seen]
    smooth = np.empty(len(seen), complex)
    for i, k in enumerate(seen):
        near = (np.abs(t[seen] - t[k]) <= 3 * smooth_s) & (seg[seen] == seg[k])
        w = np.exp(-0.5 * ((t[seen][near] - t[k]) / smooth_s) ** 2)
        smooth[i] = (w * off[near]).sum() / w.sum()
    return smooth


def _published_frames(
    kept: list[np.ndarray],
    smooth: np.ndarray,
    walk: np.ndarray,
    t: np.ndarray,
    seg: np.ndarray,
    cfg: RetrackConfig,
) -> list[np.ndarray]:
    """The frames of each stretch, and of each gap between two the phone's walk bridges: at most
    ``unseen_s`` long, in one stretch of walk, landing within ``unseen_m`` (+ 15 % of the
    distance walked) of where the next stretch starts."""
    frames = [np.arange(r[0], r[-1] + 1) for r in kept]
    joins = _joins(kept, smooth, walk, t, seg, cfg)
    pairs = zip(kept, kept[1:], joins, strict=False)
    gaps = [np.arange(a[-1] + 1, b[0]) for a, b, ok in pairs if ok]
    return frames + gaps


def _joins(
    kept: list[np.ndarray],
    smooth: np.ndarray,
    walk: np.ndarray,
    t: np.ndarray,
    seg: np.ndarray,
    cfg: RetrackConfig,
) -> list[bool]:
    """Whether the phone's walk bridges each gap between consecutive stretches of ``kept``
    (``smooth``: the offsets at their frames): :func:`_bridged` or :func:`_turned`."""
    pos = np.cumsum([0] + [len(r) for r in kept])
    out = []
    for j in range(len(kept) - 1):
        a_, b_ = int(kept[j][-1]), int(kept[j + 1][0])
        before, after = smooth[pos[j + 1] - 1], smooth[pos[j + 1]]
        out.append(
            _bridged(a_, b_, float(abs(after - before)), walk, t, seg, cfg)
            or _turned(a_, b_, walk[a_] + before, walk[b_] + after, walk, t, seg, cfg)
        )
    return out


def _turned(
    a: int,
    b: int,
    start: complex,
    end: complex,
    walk: np.ndarray,
    t: np.ndarray,
    seg: np.ndarray,
    cfg: RetrackConfig,
) -> bool:
    """Whether the gap from frame ``a`` (at ``start``) to ``b`` (at ``end``) is published as
    the phone's walk turned and scaled onto both ends (:func:`_gap_turn`, placed so by
    :func:`_turned_gaps`): at most ``unseen_s`` long, in one stretch of walk, at least
    :data:`TURN_GAP_S`. Unseen, dead reckoning errs most by its heading (the yaw of a carry
    fitted where the carrier was seen, held across the gap): a heading 20 deg off over a 16 m
    walk lands 5.6 m aside, which no drift allowance of a few % of the distance admits, and
    which the turned walk meets at both ends (PETS footage with phones, `n` seed 21: P05
    undetected for 15 s at the view's far edge, her phone's yaw there the fit of a carry she
    took up 5 s before, some 25 deg off; the gap was left unpublished). Between two stretches
    already published as the carrier, a plausible turn is the walk that joins them. Stretches
    are not tied by it (:func:`_untwinned`): a twin walking 2.6 m aside is a 15 deg turn away
    over 10 m."""
    return bool(
        TURN_GAP_S <= t[b] - t[a] <= cfg.unseen_s
        and seg[a] == seg[b]
        and _gap_turn(walk, a, b, start, end) is not None
    )


def _bridged(
    a: int,
    b: int,
    drift: float,
    walk: np.ndarray,
    t: np.ndarray,
    seg: np.ndarray,
    cfg: RetrackConfig,
) -> bool:
    """Whether the phone's walk bridges the gap from frame ``a`` (a stretch's last) to ``b``
    (the next one's first), the offsets from the walk at the two ends ``drift`` apart: at most
    ``unseen_s`` long, in one stretch of walk, landing within ``unseen_m`` (+ 15 % of the
    distance walked) of where the next stretch starts.

    Dead reckoning drifts with the distance walked (each step's length and heading err), not
    with how far the walk ends from where it began: a detour out of view that comes back near
    where it left (PETS footage with phones: P06's 7 s away, 9.2 m walked, 6.6 m from its
    start) drifts as its 9.2 m do."""
    return bool(
        t[b] - t[a] <= cfg.unseen_s
        and seg[a] == seg[b]
        and drift <= cfg.unseen_m + 0.15 * _walked(walk, a, b)
    )


def _walked(walk: np.ndarray, a: int, b: int) -> float:
    """The distance the walk (complex positions per frame) covers from frame ``a`` to ``b``."""
    return float(np.abs(np.diff(walk[a : b + 1])).sum())


HOP_STILL_S, HOP_STAY_M, HOP_LEAVE_M, HOP_STAY_SHARE = 1.0, 0.5, 1.0, 0.8
"""A path hops off somebody standing (:func:`_hops`) where its detections have stood within
``HOP_STAY_M`` for ``HOP_STILL_S``, are ``HOP_LEAVE_M`` or more from there ``evidence_lag_s``
later, and another detection stands within ``HOP_STAY_M`` of the spot (the mean of the path's
detections over the still second) in ``HOP_STAY_SHARE`` of the frames the path is seen away
from it, over ``evidence_lag_s`` from the first such frame (:func:`_seen_away`)."""


def _hops(
    points: Sequence[np.ndarray],
    hits: dict[int, np.ndarray],
    frame_t: np.ndarray,
    cfg: RetrackConfig,
) -> np.ndarray:
    """The times (ns) at which the path on ``hits`` leaves somebody who stays where they stood,
    or comes to somebody who stood there before it came: it went from one person to another.
    A carrier who starts walking leaves the spot they stood on empty, and one who stops
    comes to a spot nobody stands on (two people do not stand within ``HOP_STAY_M``); a
    path that goes from a stander to a walker passing them makes a start of its own, which
    neither of them made (PETS footage with phones, `n` seed 54: P08's phone searched onto
    P02, standing at the sign, then onto P04 walking past him as the phone starts to walk:
    17 of the stretch's 19 of evidence from that start, P02 standing on; P08's phone published
    on P04 for 9 s, 1.5 s more on P02)."""
    ks = np.array(sorted(hits), int)
    if len(ks) < 2:
        return np.empty(0)
    x = np.array([hits[k] for k in ks], float)
    t = frame_t[ks] / 1e9
    found = _hops_one_way(points, hits, ks, x, t, cfg) + _hops_one_way(
        points, hits, ks[::-1], x[::-1], -t[::-1], cfg
    )
    return np.unique(frame_t[np.array(found, int)]) if found else np.empty(0)


def _hops_one_way(
    points: Sequence[np.ndarray],
    hits: dict[int, np.ndarray],
    ks: np.ndarray,
    x: np.ndarray,
    t: np.ndarray,
    cfg: RetrackConfig,
) -> list[int]:
    """The frames at which the path on ``hits`` (at frames ``ks``, positions ``x``, times ``t``
    increasing: a path read backwards has its times negated) first leaves a spot somebody
    stays on (:func:`_hops`)."""
    before = np.searchsorted(t, t - HOP_STILL_S)
    later = np.searchsorted(t, t + cfg.evidence_lag_s)
    still = np.hypot(*(x - x[before]).T) < HOP_STAY_M
    ok = later < len(t)
    left = np.zeros(len(t), bool)
    left[ok] = np.hypot(*(x[later[ok]] - x[ok]).T) >= HOP_LEAVE_M
    found = []
    step = 1 if len(ks) < 2 or ks[1] > ks[0] else -1
    for i in np.flatnonzero(still & left & (before < np.arange(len(t)))):
        spot = x[before[i] : i + 1].mean(axis=0)
        away = _seen_away(hits, spot, int(ks[i]), int(ks[later[i]]), step, len(points))
        if away and _stays(points, spot, away):
            found.append(away[0])
    return found


def _seen_away(
    hits: dict[int, np.ndarray], spot: np.ndarray, at: int, later: int, step: int, n: int
) -> list[int]:
    """The frames the path is seen more than ``HOP_STAY_M`` from ``spot``, over as many frames
    as from ``at`` to ``later`` (``step``: 1 forwards, -1 backwards in time), from the first
    such frame after ``at`` (none when it does not leave by ``later``); ``n`` frames in all."""

    def far(f: int) -> bool:
        return f in hits and bool(np.hypot(*(hits[f] - spot)) > HOP_STAY_M)

    first = next((f for f in range(at + step, later + step, step) if far(f)), None)
    if first is None:
        return []
    span = abs(later - at)
    return [f for f in range(first, first + step * span, step) if 0 <= f < n and far(f)]


def _stays(points: Sequence[np.ndarray], spot: np.ndarray, away: list[int]) -> bool:
    """Whether a detection stays within ``HOP_STAY_M`` of ``spot`` in ``HOP_STAY_SHARE`` of
    the frames ``away``."""
    stays = sum(
        bool(len(points[f])) and np.hypot(*(points[f] - spot).T).min() <= HOP_STAY_M for f in away
    )
    return stays >= HOP_STAY_SHARE * len(away)


def _evidence(
    frame_t: np.ndarray,
    stretch: np.ndarray,
    hits: dict[int, np.ndarray],
    track: np.ndarray,
    cfg: RetrackConfig,
    radio_gain: np.ndarray | None = None,
    hops: np.ndarray | None = None,
) -> float:
    """The evidence that a stretch's detections are the phone's carrier: the motion changes
    they share with the phone, plus (with ``radio_gain``, per frame) its sum over the
    stretch's frames. The motion: the integral over its time of Re(dv conj(dp)) / 2 sigma_v^2
    (per second: the same at any frame rate), dv the change of the detections' velocity over
    ``evidence_lag_s`` (centred least squares over a third of ``velocity_window_s``), dp the
    same of the phone's aligned walk. A person who walks straight or stands changes nothing,
    whatever the phone does, and the detections' noise averages out: motion evidence comes
    only from turns, stops and starts made together; a straight walk through the view (a
    hotel's entrance) is told by the RSSI alone. ``track``: the phone's aligned walk
    (t_ns, x, y) at every frame. ``hops``: times (ns) the path went from one person to
    another (:func:`_hops`); a change measured across one is theirs together, nobody's own,
    and counts nothing."""
    ks = stretch
    det = np.array([[frame_t[k], *hits[k]] for k in ks], float)
    at = frame_t[ks].astype(float)
    before = at - cfg.evidence_lag_s * 1e9
    half = cfg.velocity_window_s / 6
    dv = visual_velocity(det, at, half) - visual_velocity(det, before, half)
    dp = visual_velocity(track, at, half) - visual_velocity(track, before, half)
    ok = ~(np.isnan(dv) | np.isnan(dp))
    if hops is not None and len(hops):
        # the two velocities are each fitted over +-half: the change reaches that far
        lo = np.searchsorted(hops, before - half * 1e9, "left")
        ok &= lo == np.searchsorted(hops, at + half * 1e9, "right")
    radio = float(radio_gain[ks[0] : ks[-1] + 1].sum()) if radio_gain is not None else 0.0
    if not ok.any():
        return radio
    dt = float(np.median(np.diff(frame_t[ks[0] : ks[-1] + 1]))) / 1e9
    gain = (dv[ok] * np.conj(dp[ok])).real.sum() * dt
    return float(gain / (2 * cfg.evidence_sigma_mps**2)) + radio


def _with_radio(
    radio: RadioEvidence | None,
    mid: str,
    grid: SiteGrid,
    emissions: Sequence[np.ndarray | float],
    every: int = 1,
) -> tuple[Sequence[np.ndarray | float], Visit | None]:
    """The frames' emissions and the visit's costs of one phone: with its RSSI when there is
    (``emissions`` of every ``every``-th frame: the scans of those frames)."""
    if not radio or not radio.cfg.enabled:
        return emissions, grid.visit
    visit = grid.visit
    if visit is not None:
        visit = (visit[0], radio.away(mid, float(np.mean(visit[1])))[::every])
    return radio.emissions(mid, grid, emissions, every), visit


def retrack(
    frame_t: np.ndarray,
    points: Sequence[np.ndarray],
    phones: dict[str, PhoneMotion],
    start: dict[str, tuple[float, np.ndarray]],
    acfg: AlignConfig,
    cfg: RetrackConfig,
    aligned: bool = False,
    radio: RadioEvidence | None = None,
    progress: Progress | None = None,
    trusted: Mapping[str, int] | None = None,
) -> Retracked:
    """Each phone's carrier re-tracked through the raw detections ``points`` (one (n, 2) array
    per frame at ``frame_t``). ``start``: a first clock offset and ``a`` per frame per phone (the
    chains' alignment; only the offset is used to start). Phones without a walk
    are left out. ``aligned``: the phones' alignment is declared (heading = walk, one clock):
    ``start`` is used as it is, neither searched nor refitted. ``radio``: the phones' RSSI at
    the site's APs (:mod:`~trackctl.vmtrack.radio`), weighed with the detections; with its
    ``fit``, each AP's path loss is fitted where the paths put the carriers and the paths are
    found again under it (:func:`_calibrated_pass`). ``trusted``: phones whose ``start`` is
    their carrier's (:attr:`RetrackConfig.trust_clear_share`), with the frames their identity
    is clear in: followed from it, refitted, not searched, unless the path followed belies it
    (:func:`_belied`: then searched too, :func:`_searched_instead`) or loses its carrier at a
    carry change (:func:`_lost_at_change`: then that carry's yaw is searched,
    :func:`_carries_searched`)."""
    out = Retracked()
    n = len(frame_t)
    if n < 2:
        return out
    grid = SiteGrid(points, cfg.cell_m)
    cfg, out.visits = read_visits(grid, frame_t, points, cfg)
    grid.with_visits(points, cfg)
    # the frames' distance grids (float32), the search's coarser ones, one path's back-pointers
    coarse = (cfg.cell_m / cfg.search_cell_m) ** 2
    need = int(n * grid.shape[0] * grid.shape[1] * (4 + 4 * coarse + 1))
    if need > cfg.max_bytes:
        warnings.warn(
            f"phone re-tracking skipped: {n} frames over a {grid.shape[1] * cfg.cell_m:.0f} x "
            f"{grid.shape[0] * cfg.cell_m:.0f} m site need {need / 1e9:.1f} GB "
            f"(limit {cfg.max_bytes / 1e9:.1f} GB); cut the log, or use --no-retrack",
            UserWarning,
            stacklevel=3,
        )
        return out
    follow = _Follower(frame_t, points, phones, grid, acfg, cfg, aligned)
    trust = dict(trusted or {})
    _first_paths(follow, out, start, trust, radio, progress)
    final = radio
    if radio is not None and _calibrates(radio) and out:
        final = _calibrated_pass(follow, out, radio, frame_t, cfg, progress, trust)
    for mid, found in out.items():
        out[mid] = follow.settle(mid, found, final)
    if cfg.exclusive:
        _exclusive(follow, out, final)
        _off_others(follow, out, final)
    _all_through_gaps(follow, out)
    _all_through_ends(follow, out)
    _all_through_visits(follow, out)
    return out


def _first_paths(
    follow: _Follower,
    out: Retracked,
    start: dict[str, tuple[float, np.ndarray]],
    trust: dict[str, int],
    radio: RadioEvidence | None,
    progress: Progress | None,
) -> None:
    """Each phone's first-pass path (:func:`_first_path`) into ``out``: searched, or followed
    from its identity's alignment when ``trust`` holds it. A trusted phone whose path belies
    its identity (:func:`_belied`) is searched too (:func:`_searched_instead`); one whose path
    loses its carrier at a carry change the phone saw (:func:`_lost_at_change`) is followed
    again with that carry's yaw searched (:func:`_carries_searched`)."""
    n = len(follow.frame_t)
    for k, (mid, track) in enumerate(follow.walks.items()):
        if progress is not None:
            progress(k, len(follow.walks), "re-tracking phones")
        if len(track) < 2:
            continue
        # a searched phone starts from the nominal step (scale 1) at the chains' clock offset:
        # in a crowd the chains' scale is another walker's as often as not, and the refit
        # finds the phone's own; a trusted one from the chains' whole alignment
        lag, a0 = start.get(mid, (0.0, np.full(n, 1.0 + 0j)))
        search = not follow.aligned and mid not in trust
        if search:
            out.searched.append(mid)
        got = _first_path(follow, mid, (lag, a0), search, mid in start, radio)
        if not search and not follow.aligned and got is not None:
            if _belied(got, trust[mid]):
                got = _searched_instead(follow, out, mid, got, (lag, a0), trust, radio)
            elif _lost_at_change(follow, mid, got):
                got = _carries_searched(follow, mid, got, radio)
        if got is not None:
            out[mid] = got


def _searched_instead(
    follow: _Follower,
    out: Retracked,
    mid: str,
    got: PhoneTrack,
    begin: tuple[float, np.ndarray],
    trust: dict[str, int],
    radio: RadioEvidence | None,
) -> PhoneTrack:
    """A trusted phone whose path ``got`` belies its identity (:func:`_belied`), searched: the
    searched path where it costs less and does not belie the identity too (then the phone is
    searched, and leaves ``trust``), else ``got`` and the search forgotten. A search that
    finds the carrier in fewer frames than the identity claimed has found somebody else as
    often as not: the identity is then wrong about the alignment and the frames both (PETS
    footage with phones: P08, 10 s in view, clear in 85-283 frames of the identity on 9 of 20
    logs, their paths on him nowhere; searched and kept where cheaper, on 2 of the 4 such logs
    run so it was published on another carrier (6 s) or on strangers, and on him nowhere).

    A search kept is combined with ``got`` carry by carry (:meth:`_Follower._combined`): the
    identity's alignment may hold for one carry and the search's for another, and each path
    then sees the carrier in its own carry only (`n` seed 25: P05's hand phone moved to a bag
    at 56 s; followed from her identity, on her only after it, 106 frames; searched, only
    before it, 243 frames, unnamed for her last 42 s; combined, 372 frames)."""
    searched = follow(mid, *begin, True, radio)
    if (
        searched is None
        or _belied(searched, trust[mid])
        or _cheaper(follow, mid, radio, got, searched) is got
    ):
        follow.alternatives.pop(mid, None)
        return got
    out.searched.append(mid)
    del trust[mid]
    return follow._combined(mid, searched, [got], radio)


def _held_by_others(out: Retracked, mid: str) -> dict[int, list[tuple[float, float]]]:
    """Per frame, where the other phones' carriers are seen (their detections)."""
    held: dict[int, list[tuple[float, float]]] = {}
    for other, found in out.items():
        if other != mid:
            for k in found.seen:
                held.setdefault(k, []).append(found.xy[k])
    return held


def _gaps(found: PhoneTrack) -> list[tuple[int, int]]:
    """The (last seen frame, next seen frame) around each run of at least two published
    frames that are not seen (fills and bridges)."""
    ks = np.array(sorted(k for k in found.xy if k not in found.seen), dtype=np.int64)
    if not len(ks):
        return []
    runs = np.split(ks, np.flatnonzero(np.diff(ks) > 1) + 1)
    return [
        (int(r[0]) - 1, int(r[-1]) + 1)
        for r in runs
        if len(r) >= 2 and int(r[0]) - 1 in found.seen and int(r[-1]) + 1 in found.seen
    ]


def _all_through_gaps(follow: _Follower, out: Retracked) -> None:
    """Each phone's published gaps tracked again (:func:`_through_gaps`), in place; nothing
    when :attr:`RetrackConfig.gap_walk_sigma_mps` is None."""
    if follow.cfg.gap_walk_sigma_mps is None:
        return
    for mid, found in out.items():
        out[mid] = _through_gaps(follow, mid, found, _held_by_others(out, mid))


def _through_gaps(
    follow: _Follower, mid: str, found: PhoneTrack, held: dict[int, list[tuple[float, float]]]
) -> PhoneTrack:
    """``found`` with each published gap between two seen frames tracked again over the
    detections (those no other phone's carrier is seen on, ``held``): a Viterbi path from the
    carrier's position before the gap to theirs after it, moving with the phone's walk and a
    random walk of ``gap_walk_sigma_mps``; where that path is on a detection (``gate_m``) that
    joins an end of the gap (:func:`_linked`), the gap is published there (the offsets from
    the walk smoothed as on seen frames, linear between).

    The whole log's path walks ``walk_sigma_mps`` about the phone's walk: tight, so that it
    does not ride strangers. But a phone's walk errs by a drift over a few seconds (a heading
    lagging a turn, a yaw settling after a carry change), not by a diffusion, and where the
    carrier's detections stray from it by more than the tight walk reaches, the path leaves
    them and the gap is published on the walk, 1-2 m off (PETS footage with phones, `h` seed 2:
    P06 after a carry change, detected 0.2-0.7 m from her truth for 6 s, published 1.3-1.9 m
    off). Within a gap, both ends are the carrier's; a looser walk pinned to them reaches the
    carrier's detections, and cannot wander farther than the gap's length allows."""
    gaps = _gaps(found)
    if not gaps or follow.cfg.gap_walk_sigma_mps is None:
        return found
    u = _displacements(follow.frame_t, follow.walks[mid], found.lag_s, found.a)
    walk = np.cumsum(np.nan_to_num(u, nan=0.0))
    t = follow.frame_t / 1e9
    xy = dict(found.xy)
    for a, b in gaps:
        ks = np.arange(a, b + 1)
        if np.isnan(u[ks[1:]]).any():
            continue
        on = _gap_on(follow, ks, u, xy, held)
        if not on:
            continue
        on[a], on[b] = xy[a], xy[b]
        at = np.array(sorted(on), dtype=np.int64)
        hits = {k: np.asarray(on[k], float) for k in at}
        smooth = _smoothed_offsets(at, hits, walk, t, np.zeros(len(walk), int), follow.cfg.smooth_s)
        smooth[0], smooth[-1] = complex(*on[a]) - walk[a], complex(*on[b]) - walk[b]
        off = np.interp(ks, at, smooth.real) + 1j * np.interp(ks, at, smooth.imag)
        # what the path did not reach is walked as publication walks a gap (turned, over 2 s)
        placed = _turned_gaps(ks, walk[ks] + off, at, walk, t)
        for k, p in zip(ks[1:-1], placed[1:-1], strict=True):
            xy[int(k)] = (float(p.real), float(p.imag))
    return replace(found, xy=xy)


def _gap_on(
    follow: _Follower,
    ks: np.ndarray,
    u: np.ndarray,
    xy: dict[int, tuple[float, float]],
    held: dict[int, list[tuple[float, float]]],
) -> dict[int, tuple[float, float]]:
    """The detections the second path of the gap ``ks`` (its ends seen frames, ``xy`` the
    carrier's positions there) is on, where they join an end (:func:`_through_gaps`)."""
    cfg, grid = follow.cfg, follow.grid
    assert cfg.gap_walk_sigma_mps is not None
    steps = _step_costs(grid.cell, follow.dt, cfg, cfg.gap_walk_sigma_mps)
    a, b = int(ks[0]), int(ks[-1])
    points = [_free(follow.points[int(k)], held.get(int(k), []), cfg.gate_m) for k in ks]
    emissions = [grid.emission(p, cfg.det_sigma_m, cfg.miss_cost) for p in points]
    # pinned to the carrier at both ends
    emissions[0] = grid.emission(np.array([xy[a]]), cfg.det_sigma_m, float(_BIG))
    emissions[-1] = grid.emission(np.array([xy[b]]), cfg.det_sigma_m, float(_BIG))
    us = u[ks].copy()
    us[0] = 0j
    path = grid.xy(_viterbi_path(grid, emissions, us, steps))
    on: dict[int, tuple[float, float]] = {}
    for i in range(1, len(ks) - 1):
        j = _nearest(points[i], path[i], cfg.gate_m)
        if j is not None:
            on[int(ks[i])] = (float(points[i][j][0]), float(points[i][j][1]))
    ends = ((xy[a], follow.points[a]), (xy[b], follow.points[b]))
    frames = dict(zip((int(k) for k in ks), points, strict=True))
    return {k: on[k] for k in _linked(on, ks, follow.frame_t / 1e9, ends, frames)}


GAP_LINK_S = 1.0
"""A gap's path is published on the detections it is on (:func:`_through_gaps`) only where
they join one of the gap's ends without a miss longer than this: where the carrier leaves the
view in the gap, a stranger the path finds later is not theirs."""


def _linked(
    on: dict[int, tuple[float, float]],
    ks: np.ndarray,
    t: np.ndarray,
    ends: tuple[tuple[tuple[float, float], np.ndarray], ...],
    frames: dict[int, np.ndarray],
) -> list[int]:
    """The frames of ``on`` (detections within the gap ``ks``) reached from either end through
    frames of ``on`` at most :data:`GAP_LINK_S` apart, each continuing the one before it, and
    the first the carrier's detection at the end (:func:`_continues`; ``ends``: the carrier's
    position and the frame's detections at the first and at the last frame; ``frames``: the
    detections of each frame of the gap): a walker beside the carrier, detected with them,
    whom the path moves onto where the carrier is missed, is not the carrier."""
    out: set[int] = set()
    for order, (anchor, there) in zip((ks, ks[::-1]), ends, strict=True):
        last = float(t[order[0]])
        for k in order[1:-1]:
            if abs(t[k] - last) > GAP_LINK_S:
                break
            if int(k) not in on:
                continue
            if not _continues(anchor, there, on[int(k)], frames[int(k)]):
                break
            out.add(int(k))
            last, anchor, there = float(t[k]), on[int(k)], frames[int(k)]
    return sorted(out)


def _continues(
    anchor: tuple[float, float], there: np.ndarray, nxt: tuple[float, float], here: np.ndarray
) -> bool:
    """Whether detection ``nxt`` (one of ``here``) continues the carrier's at ``anchor``: the
    detection of the anchor's frame (``there``) nearest the anchor and ``nxt`` are each the
    other's nearest in its frame (mutual nearest neighbours, the association's test)."""
    mine, back = _nearest(there, anchor, math.inf), _nearest(there, nxt, math.inf)
    if mine is None or back is None or not len(here):
        return True
    ahead = _nearest(here, there[mine], math.inf)
    return back == mine and ahead is not None and bool(np.allclose(here[ahead], nxt))


def _all_through_ends(follow: _Follower, out: Retracked) -> None:
    """Each phone's carrier followed over the detections beyond the phone's samples
    (:func:`_through_ends`), in place."""
    for mid, found in out.items():
        out[mid] = _through_ends(follow, mid, found, _held_by_others(out, mid))


def _through_ends(
    follow: _Follower, mid: str, found: PhoneTrack, held: dict[int, list[tuple[float, float]]]
) -> PhoneTrack:
    """``found`` carried along the detections that continue the carrier's (:func:`_chain`:
    mutual nearest neighbours, no miss over :data:`GAP_LINK_S`) before the phone's first
    sample and after its last, where the carrier is seen up to that edge.

    A phone's samples need not span the camera's log: its clock is off by seconds (PETS
    footage with phones: a phone whose clock runs 1.6 s ahead has no walk for the log's last
    1.6 s, and its carrier, seen to the last frame, went unnamed there). Where the phone says
    nothing, the detections alone carry the identity, as the visual tracker carries it
    through a phone's silence: the person the phone was bound to at its edge is the one who
    walks on from there."""
    u = _displacements(follow.frame_t, follow.walks[mid], found.lag_s, found.a)
    walks = np.flatnonzero(~np.isnan(u))
    if not len(walks) or not found.seen:
        return found
    n, t = len(u), follow.frame_t / 1e9
    # the phone's first frame is a restart (no step into it) but has its walk
    first, last = int(walks[0]) - 1, int(walks[-1])
    xy, seen = dict(found.xy), set(found.seen)
    for edge, bound, order in (
        (min(found.seen), first, np.arange(min(found.seen) - 1, -1, -1)),
        (max(found.seen), last, np.arange(max(found.seen) + 1, n)),
    ):
        # a phone silent there, and its carrier seen up to where it falls silent
        if not 0 < bound < n - 1 or abs(t[edge] - t[bound]) > GAP_LINK_S:
            continue
        v = _edge_velocity(found.xy, edge, int(order[0]) - edge, t)
        for k, p in _chain(follow, edge, (np.asarray(xy[edge]), v), order, held).items():
            if k < first or k > last:
                xy[k] = p
                seen.add(k)
    return replace(found, xy=xy, seen=seen)


def _all_through_visits(follow: _Follower, out: Retracked) -> None:
    """Each phone's carrier followed over the detections before its first seen frame and after
    its last while the phone walks there (:func:`_through_visit`), in place."""
    for mid, found in out.items():
        out[mid] = _through_visit(follow, mid, found, _held_by_others(out, mid))


def _through_visit(
    follow: _Follower, mid: str, found: PhoneTrack, held: dict[int, list[tuple[float, float]]]
) -> PhoneTrack:
    """``found`` carried along the detections that continue the carrier's (:func:`_chain`)
    before its first seen frame and after its last, over frames it publishes nothing in, as
    far as the phone's walk goes where they go (:func:`_walked_alike`).

    The path holds a carrier where the phone's aligned walk stays within the random walk of
    their detections, and the alignment is refitted from the detections the path is on. Where
    a visit's first or last seconds need another yaw (the indoor field turns a compass by
    10-20 deg from place to place, a heading drifts), the path leaves the carrier there for
    out of view and nothing is left to refit the yaw from (PETS footage with phones, `n`
    seed 17: P06's hand phone turned by some 30 deg in her hand at 16.9 s, which the phone
    did not see; before it her aligned walk ran 25-35 deg off hers, and the path took her
    only after it, 12 s into her visit). The detections that continue hers are hers, as the visual
    tracker would carry them, while they go where the phone says she goes: turned by a
    plausible heading error and step, as a gap out of view is walked (:func:`_gap_turn`)."""
    if not found.seen:
        return found
    u = _displacements(follow.frame_t, follow.walks[mid], found.lag_s, found.a)
    walk = np.cumsum(np.nan_to_num(u, nan=0.0))
    seg = np.cumsum(np.isnan(u))
    t = follow.frame_t / 1e9
    xy, seen = dict(found.xy), set(found.seen)
    first, last = min(found.seen), max(found.seen)
    for edge, way in ((first, -1), (last, 1)):
        order = np.arange(edge + way, -1 if way < 0 else len(u), way)
        free = np.array([int(k) not in xy and seg[k] == seg[edge] for k in order], bool)
        order = order[: int(np.argmin(free)) if not free.all() else len(order)]
        if not len(order):
            continue
        start = (np.asarray(found.xy[edge], float), _edge_velocity(found.xy, edge, way, t))
        chain = _chain(follow, edge, start, order, held)
        for k in _walked_alike(chain, edge, walk, t) if len(chain) >= 2 else ():
            xy[k] = chain[k]
            seen.add(k)
    return replace(found, xy=xy, seen=seen)


ALIKE_HALF_S, ALIKE_SLACK_S, ALIKE_STILL_MPS = 1.0, 1.5, 0.3
"""The detections and the phone's walk are compared by their velocities over +-``ALIKE_HALF_S``,
the walk's taken up to ``ALIKE_SLACK_S`` earlier or later; below ``ALIKE_STILL_MPS`` a walker
stands (:func:`_walked_alike`)."""


def _walked_alike(
    chain: dict[int, tuple[float, float]], edge: int, walk: np.ndarray, t: np.ndarray
) -> list[int]:
    """The frames of ``chain`` (detections going away from frame ``edge``) where the phone's
    walk moves as they do, up to the first run of :data:`GAP_LINK_S` or more where it does
    not. Alike: both stand (:data:`ALIKE_STILL_MPS`), or both move, at most
    :data:`TURN_MAX_DEG` apart and at speeds within a factor of 2, the walk's velocity taken
    within :data:`ALIKE_SLACK_S` of the detections' (a turn a step late, a clock off by a
    second: the alignment there is what is in doubt). A detection off for a frame or two is
    a blob's scatter."""
    kt = np.array(sorted(chain), int)
    pos = np.array([complex(*chain[int(k)]) for k in kt])
    tc = t[kt]

    def velocity(times: np.ndarray, at: np.ndarray, z: np.ndarray) -> np.ndarray:
        lo, hi = at - ALIKE_HALF_S, at + ALIKE_HALF_S
        zr = lambda q: np.interp(q, times, z.real) + 1j * np.interp(q, times, z.imag)  # noqa: E731
        return (zr(hi) - zr(lo)) / (2 * ALIKE_HALF_S)

    vc = velocity(tc, tc, pos)
    shifts = np.arange(-ALIKE_SLACK_S, ALIKE_SLACK_S + 1e-9, 0.25)
    vw = np.array([velocity(t, tc + s, walk) for s in shifts])  # (shifts, chain frames)
    still_c, still_w = np.abs(vc) < ALIKE_STILL_MPS, np.abs(vw) < ALIKE_STILL_MPS
    ratio = vc / np.where(still_w, 1.0, vw)
    moving = (
        ~still_c
        & ~still_w
        & (np.abs(np.angle(ratio, deg=True)) <= TURN_MAX_DEG)
        & (np.abs(ratio) >= 0.5)
        & (np.abs(ratio) <= 2.0)
    )
    ok = dict(zip(kt.tolist(), ((still_c & still_w) | moving).any(axis=0).tolist(), strict=True))
    out: list[int] = []
    off_since: float | None = None
    for k in sorted(chain, key=lambda k: abs(k - edge)):
        if ok[k]:
            out.append(k)
            off_since = None
        elif off_since is None:
            off_since = float(t[k])
        elif abs(t[k] - off_since) >= GAP_LINK_S:
            break
    if off_since is not None:  # the chain ended off the walk: its last frames are not kept
        out = [k for k in out if abs(t[k] - t[edge]) < abs(off_since - t[edge])]
    return out


def _edge_velocity(
    xy: dict[int, tuple[float, float]], edge: int, way: int, t: np.ndarray
) -> np.ndarray:
    """The published track's velocity (m/s) into frame ``edge`` over the :data:`GAP_LINK_S`
    before it, in the direction of time ``way`` (+1: forwards, -1: backwards); zero when
    nothing is published there."""
    inner = [k for k in xy if 0 < (edge - k) * way and abs(t[k] - t[edge]) <= GAP_LINK_S]
    k0 = max(inner, key=lambda k: abs(k - edge), default=edge)
    return np.subtract(xy[edge], xy[k0]) / max(abs(t[edge] - t[k0]), 1e-9)


CHAIN_GAIN = 0.3
"""How much each detection taken moves a chain's velocity (:func:`_chain`): an average over
the last few, steadier than one frame's step through the detections' scatter."""


def _chain(
    follow: _Follower,
    edge: int,
    start: tuple[np.ndarray, np.ndarray],
    order: np.ndarray,
    held: dict[int, list[tuple[float, float]]],
) -> dict[int, tuple[float, float]]:
    """The detections (free of other carriers', ``held``) that continue the carrier's at frame
    ``edge`` over the frames ``order``; ``start``: their position there and velocity (m/s, in
    the order's direction of time). Each is the nearest, within ``gate_m``, to where the one
    before it moves at that velocity, and its mutual nearest neighbour there
    (:func:`_continues`, the frame before moved alike); no miss longer than
    :data:`GAP_LINK_S`."""
    t = follow.frame_t / 1e9
    gate = follow.cfg.gate_m
    (anchor, v), there, last = start, follow.points[edge], float(t[edge])
    out: dict[int, tuple[float, float]] = {}
    for k in order.tolist():
        dt = abs(t[k] - last)
        if dt > GAP_LINK_S:
            break
        here = _free(follow.points[k], held.get(k, []), gate)
        ahead = anchor + v * dt
        j = _nearest(here, ahead, gate)
        if j is None:
            continue
        nxt = (float(here[j][0]), float(here[j][1]))
        if not _continues((float(ahead[0]), float(ahead[1])), there + v * dt, nxt, here):
            break
        out[k] = nxt
        v = (1 - CHAIN_GAIN) * v + CHAIN_GAIN * (here[j] - anchor) / dt
        anchor, there, last = here[j], here, float(t[k])
    return out


def _free(points: np.ndarray, held: list[tuple[float, float]], gate_m: float) -> np.ndarray:
    """``points`` without those within ``gate_m`` of a position in ``held``."""
    if not held or not len(points):
        return points
    d = np.hypot(*(points[:, None, :] - np.asarray(held)[None, :, :]).transpose(2, 0, 1))
    return points[(d > gate_m).all(axis=1)]


def _first_path(
    follow: _Follower,
    mid: str,
    begin: tuple[float, np.ndarray],
    search: bool,
    identified: bool,
    radio: RadioEvidence | None,
) -> PhoneTrack | None:
    """A phone's first-pass path from ``begin`` (clock offset, ``a`` per frame): searched when
    ``search``, else followed and refitted, its clock offset checked (:func:`_lag_checked`)
    unless the alignment is declared. A searched phone with an identity (``identified``:
    ``begin`` is its chains' alignment) is also followed from it, and the cheaper of the two
    paths is kept, unless the calibrated pass (:func:`_calibrated_pass`) follows: it keeps the
    cheaper of the refitted and the re-searched path itself. The search's grids can miss the
    optimum the identity sits on, and a log without fitted RSSI never reaches that pass (PETS
    footage without APs: a 5 Hz phone searched onto somebody 3 m away, at a cost of 1019
    against the identity's 883). Comparing in the first pass of a log that does reach it as
    well moved `crowds_zara01` seed 3 from 0.992 to 0.923: the calibrated pass refits from the
    first pass's path, and the identity's clock offset there was 0.37 s off."""
    lag, a0 = begin
    got = follow(mid, lag, a0, search, radio)
    if not search and not follow.aligned and got is not None:
        return _lag_checked(follow, mid, got, radio)
    if not (search and identified) or _calibrates(radio):
        return got
    followed = follow(mid, lag, a0, False, radio)
    kept = _cheaper(follow, mid, radio, got, followed)
    # the other is another account of the phone, as the search's alternatives are: the
    # settling weighs it, and may take a carry's alignment from it (PETS footage with phones,
    # `n` seed 47: P05's hand phone, the search's path 733.8, the identity's 734.0, which
    # alone follows her through the last 6 s, after a carry change)
    other = followed if kept is got else got
    if other is not None and kept is not None:
        follow.alternatives.setdefault(mid, []).append((other.lag_s, other.a))
    return kept


def _cheaper(
    follow: _Follower,
    mid: str,
    radio: RadioEvidence | None,
    first: PhoneTrack | None,
    other: PhoneTrack | None,
) -> PhoneTrack | None:
    """``other`` where it costs less than ``first`` (:meth:`_Follower.cost`) or ``first`` is
    None, else ``first``."""
    if other is not None and (
        first is None or follow.cost(mid, other, radio) < follow.cost(mid, first, radio)
    ):
        return other
    return first


TRUST_SEEN_SHARE = 0.5
"""A trusted phone's followed path that sees its carrier in fewer than this share of the
frames its identity is clear in belies the identity's alignment (:func:`_belied`)."""


def _belied(got: PhoneTrack, clear_frames: int) -> bool:
    """Whether a trusted phone's path ``got`` (followed from its identity's alignment) belies
    it: it sees the carrier in fewer than :data:`TRUST_SEEN_SHARE` of the ``clear_frames``
    the identity put the phone on one chain. The identity says whose phone it is, but its
    alignment can be far off, and a path followed from a yaw 180 deg off walks away from the
    carrier it named (PETS footage with phones, seed 14: P05's hand phone at 5 Hz, clear in
    57 of the 64 frames its identity put it on a chain, followed from yaw 178 deg and step
    scale 0.70, on her in no frame; found only later, by `_off_others`, for 25 s; searched
    at once, on her in 97 % of her frames)."""
    return len(got.seen) < TRUST_SEEN_SHARE * clear_frames


def _lost_at_change(follow: _Follower, mid: str, got: PhoneTrack) -> bool:
    """Whether a trusted phone's path ``got`` (followed from its identity's alignment) loses
    its carrier at a carry change the phone saw: it sees them within ``min_stretch_s`` of the
    change on one side and in no frame of the carry on the other, a carry of
    ``min_stretch_s`` or more. The identity's alignment of a carry is learnt from the chains
    the phone was on in it, and a carry taken up late in a visit (or put down early in it)
    has few; the refit cannot mend it from a path that left the carrier there, for that path
    has no detections in the carry to refit from (PETS footage with phones, `n` seed 43: P02's
    phone moved from a front pocket to a bag at 29 s, 12 s before he left the view; followed,
    the path went out of view at the change and he was unnamed for those 12 s; searched, it
    follows him to the end; seed 52: P06's phone changed carry at 15.3 s, 11 s into her visit,
    and the path took her only after it)."""
    min_s = follow.cfg.min_stretch_s
    carry, seen = _carries(follow, mid, got)
    if not got.seen or not carry[-1]:
        return False
    t = follow.frame_t / 1e9
    at = np.flatnonzero(seen)
    for c in range(int(carry[-1]) + 1):
        ks = np.flatnonzero(carry == c)
        if not len(ks) or t[ks[-1]] - t[ks[0]] < min_s or seen[ks].any():
            continue
        before, after = at[at < ks[0]], at[at > ks[-1]]
        if (c > 0 and len(before) and t[ks[0]] - t[before[-1]] <= min_s) or (
            c < carry[-1] and len(after) and t[after[0]] - t[ks[-1]] <= min_s
        ):
            return True
    return False


def _carries(follow: _Follower, mid: str, got: PhoneTrack) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, the carry of phone ``mid`` (0, then 1 after the first change it saw, ...,
    at ``got``'s clock offset) and whether ``got`` sees its carrier there."""
    carry = np.cumsum(_carry_frames(follow.frame_t, follow.phones[mid].carry_changes, got.lag_s))
    seen = np.zeros(len(carry), bool)
    seen[sorted(got.seen)] = True
    return carry, seen


def _carries_searched(
    follow: _Follower, mid: str, got: PhoneTrack, radio: RadioEvidence | None
) -> PhoneTrack:
    """A trusted phone's path ``got`` that lost its carrier at a carry change
    (:func:`_lost_at_change`) followed again with the yaw of each carry it sees nobody in
    searched (one yaw per carry, at its clock offset and step: :meth:`_Follower.carry_yaws`),
    and kept where cheaper (:meth:`_Follower.cost`). The identity's alignment holds where
    the path saw the carrier; only the carry it lost is in doubt, and a whole search can land
    elsewhere (PETS footage with phones, `n` seed 52: searched, P06's phone went on strangers
    at a cost of 1005 against the followed path's 723)."""
    scale = float(np.nanmedian(np.abs(got.a))) if np.isfinite(got.a).any() else 1.0
    yaw = follow.carry_yaws(mid, got.lag_s, scale, radio)
    if yaw is None:
        return got
    carry, seen = _carries(follow, mid, got)
    a = got.a.copy()
    for c in range(int(carry[-1]) + 1):
        ks = carry == c
        if not seen[ks].any():
            a[ks] = yaw[ks]
    again = follow(mid, got.lag_s, a, False, radio)
    return _cheaper(follow, mid, radio, got, again) or got


def _lag_checked(
    follow: _Follower, mid: str, got: PhoneTrack, radio: RadioEvidence | None
) -> PhoneTrack:
    """A phone followed from its identity (trusted, not searched), with its clock offset
    checked: its path's cost (:meth:`_Follower.cost`) under its alignment at the offsets of
    the lag grid (``lag_step_s`` apart, within ``max_clock_offset_s``), walked downhill from
    the refitted one; where one is cheaper, the phone is followed (and refitted) from it too,
    and the cheaper path is kept. The identity says whose phone it is, its chains'
    clock offset can be a second off, and a refit only finds the nearest optimum (PETS
    footage with phones, `n` seed 0: a bag phone clear in 0.988 of its frames, offset -1.0
    s, refitted to -1.25, true -1.98; there its path cut the carrier's turn along a stranger
    for 5 s; at -2.0 the path costs 801 against 957). One cost is a single pass over the
    frames: ~0.17 s per phone on 80 s of footage against ~7 s for a search."""
    acfg = follow.acfg
    step, limit = acfg.lag_step_s, acfg.max_clock_offset_s + 1e-9
    best_cost = here = follow.cost(mid, got, radio)
    best_lag = got.lag_s
    for sign in (-1.0, 1.0):
        lag = got.lag_s + sign * step
        while abs(lag) <= limit:
            c = follow.cost(mid, replace(got, lag_s=lag), radio)
            if c >= best_cost:
                break
            best_cost, best_lag = c, lag
            lag += sign * step
        if best_lag != got.lag_s:
            break
    if best_lag == got.lag_s:
        return got
    moved = follow(mid, best_lag, got.a, False, radio)
    if moved is not None and follow.cost(mid, moved, radio) < here:
        return moved
    return got


def _calibrates(radio: RadioEvidence | None) -> bool:
    """True when the APs' path loss is fitted and the paths found again under it (the
    calibrated pass runs)."""
    return bool(radio and radio.cfg.enabled and radio.cfg.fit)


def read_visits(
    grid: SiteGrid, frame_t: np.ndarray, points: Sequence[np.ndarray], cfg: RetrackConfig
) -> tuple[RetrackConfig, VisitReading]:
    """``cfg`` with the visit model the log calls for (in view throughout: ``away_cost`` None),
    and what it was read from (nothing when one visit is asked for whatever the log)."""
    if cfg.away_cost is None or cfg.turnover_min is None:
        return cfg, VisitReading(one_visit=cfg.away_cost is not None)
    turnover = grid.edge_turnover(points, cfg)
    steady = occupancy_steadiness(frame_t, points, cfg.steadiness_window_s)
    closed = (
        turnover is not None
        and steady is not None
        and turnover < cfg.turnover_min
        and steady >= cfg.steadiness_min
    )
    reading = VisitReading(turnover, steady, one_visit=not closed)
    return (replace(cfg, away_cost=None) if closed else cfg), reading


def _shared(
    points: Sequence[np.ndarray], out: Retracked, min_frames: int, gate_m: float
) -> tuple[str, str, list[int]] | None:
    """The two phones whose paths are on the same detections in the most frames (at least
    ``min_frames``), and those frames; None when no two are."""
    near: dict[str, dict[int, int]] = {}
    for mid, tr in out.items():
        near[mid] = {}
        for k in tr.seen:
            j = _nearest(points[k], tr.xy[k], gate_m) if k in tr.xy else None
            if j is not None:
                near[mid][k] = j
    best: tuple[str, str, list[int]] | None = None
    mids = sorted(out)
    for i, a in enumerate(mids):
        for b in mids[i + 1 :]:
            ks = sorted(k for k, j in near[a].items() if near[b].get(k) == j)
            if len(ks) >= min_frames and (best is None or len(ks) > len(best[2])):
                best = (a, b, ks)
    return best


def _exclusive(follow: _Follower, out: Retracked, radio: RadioEvidence | None) -> None:
    """One person, one phone (in place): where two phones' paths are on the same detections
    for ``min_stretch_s`` or more, the phone whose path costs least more without them
    (:meth:`_Follower.cost`, each under its own alignment refitted) gives them up and is
    followed again without them; the other keeps its path. Two walkers side by side fit
    each other's phones nearly as well, and each phone followed alone can end on the one
    that fits it best (`biwi_hotel` seed 1: two phones on one of a pair); the pair's
    cheapest joint answer puts the phones on both. Repeated while any two share (a phone
    moved may land on a third's carrier), at most twice per phone."""
    cfg = follow.cfg
    min_frames = max(int(round(cfg.min_stretch_s / follow.dt)), 1)
    for _ in range(2 * len(out)):
        shared = _shared(follow.points, out, min_frames, cfg.gate_m)
        if shared is None:
            return
        a, b, ks = shared
        options = []
        for keep, move in ((a, b), (b, a)):
            before = follow.cost(move, out[move], radio)
            held = follow.taken.get(move, {})
            follow.taken[move] = follow.holding(move, out[keep], ks)
            moved = follow(move, out[move].lag_s, out[move].a, False, radio)
            rise = np.inf if moved is None else follow.cost(move, moved, radio) - before
            options.append((rise, move, follow.taken[move], moved))
            follow.taken[move] = held
        rise, move, taken, moved = min(options, key=lambda o: o[0])
        follow.taken[move] = taken
        if moved is None:
            del out[move]
        else:
            out[move] = follow.settle(move, moved, radio)


def _on_others(points: Sequence[np.ndarray], out: Retracked, mid: str, gate_m: float) -> list[int]:
    """The frames where phone ``mid``'s path, publishing nothing, is on the detection another
    phone's carrier is published on (seen)."""
    riding = out[mid].riding
    ks = []
    for other, tr in out.items():
        if other == mid:
            continue
        for k in tr.seen & riding.keys():
            j = _nearest(points[k], tr.xy[k], gate_m) if k in tr.xy else None
            if j is not None and np.allclose(points[k][j], riding[k]):
                ks.append(k)
    return sorted(set(ks))


def _off_others(follow: _Follower, out: Retracked, radio: RadioEvidence | None) -> None:
    """One person, one phone, where one of them withholds (in place): a path on another
    carrier's detections for ``min_stretch_s`` or more where it publishes nothing (it rode the
    walker beside its carrier, and publication cut that stretch as somebody else,
    :func:`_one_carrier`) is followed again without them, and kept when it then sees its
    carrier more, publishes no fewer frames, and still publishes what it did (PETS footage,
    seed 1: P06's phone on P05 beside her for 9 s, P06 unnamed there). A path moved elsewhere
    is not kept: the frames were the other carrier's, not a clue to where this one is; nor is
    one that sees its carrier in a few frames more but no longer bridges a gap out of view.

    A path that withholds ``min_stretch_s`` or more where fewer frames than that are on
    another carrier's published detections is followed again without all the detections it
    withholds, on the same terms: publication judged them somebody else's, or could not tell
    (PETS footage, `h` seed 5: P06's phone on P04 and P05, who walk together, for 96 frames,
    24 of them on P05 where her phone's path is published). Not so a path that publishes
    nothing: those terms are then empty (it sees nothing and publishes nothing to keep), and
    a path with the detections it withholds taken away lands on whoever is left beside them
    (PETS footage, `n` seed 29: P08's phone, withheld on P04 and P05, who walk 0.5-1.0 m
    apart, followed again onto P04 and published there for 3.4 s; P08 is elsewhere)."""
    cfg = follow.cfg
    min_frames = max(int(round(cfg.min_stretch_s / follow.dt)), 1)
    for mid in sorted(out):
        ks = _on_others(follow.points, out, mid, cfg.gate_m)
        if len(ks) < min_frames and out[mid].seen:
            ks = sorted(out[mid].riding)
        if len(ks) < min_frames:
            continue
        tr, held = out[mid], follow.taken.get(mid, {})
        taken = dict(held)
        for k in ks:
            left = taken.get(k, follow.points[k])
            taken[k] = left[~np.all(np.isclose(left, tr.riding[k]), axis=1)]
        follow.taken[mid] = taken
        moved = follow(mid, tr.lag_s, tr.a, False, radio)
        if moved is not None:
            moved = follow.settle(mid, moved, radio)
        if (
            moved is None
            or len(moved.seen) <= len(tr.seen)
            or len(moved.xy) < len(tr.xy)
            or _lost(tr, moved, cfg.gate_m) > PART_LOST
        ):
            follow.taken[mid] = held
            continue
        out[mid] = moved


def _lost(a: PhoneTrack, b: PhoneTrack, within_m: float) -> float:
    """The share of ``a``'s seen frames that ``b`` does not publish within ``within_m``."""
    lost = sum(k not in b.xy or np.hypot(*np.subtract(a.xy[k], b.xy[k])) > within_m for k in a.seen)
    return lost / max(len(a.seen), 1)


def _calibrated_pass(
    follow: _Follower,
    out: Retracked,
    radio: RadioEvidence,
    frame_t: np.ndarray,
    cfg: RetrackConfig,
    progress: Progress | None = None,
    trusted: Collection[str] = frozenset(),
) -> RadioEvidence:
    """The APs' calibration from where the first pass put the carriers (on detections), then
    each path again under it, twice: from the first pass's alignment (refitted, not searched)
    and searched afresh; the cheaper path is kept. The first pass searched under the default
    model, whose errors (7 dB at 10 m) can make a wrong alignment the cheapest, and a refit
    from it only finds the nearest optimum (`students001` seed 3: a phone 2 s off its clock
    offset on the walker ahead of its carrier, right in 43 of 114 frames, 114 searched
    again). A ``trusted`` phone is refitted only (:attr:`RetrackConfig.trust_clear_share`)."""
    on = {mid: sorted(tr.seen) for mid, tr in out.items()}
    calibrated = radio.calibrated(
        {mid: (frame_t[ks], np.array([out[mid].xy[k] for k in ks])) for mid, ks in on.items()}
    )
    out.calibration = calibrated.model
    for k, (mid, first) in enumerate(list(out.items())):
        if progress is not None:
            progress(k, len(out), "re-tracking phones under the fitted radio model")
        again = follow(mid, first.lag_s, first.a, False, calibrated)
        if not follow.aligned and mid not in trusted:
            searched = follow(mid, first.lag_s, first.a, True, calibrated)
            if searched is not None and (
                again is None
                or follow.cost(mid, searched, calibrated) < follow.cost(mid, again, calibrated)
            ):
                if again is None or _moved(again, searched, cfg.gate_m) > 0:
                    out.searched_again.append(mid)
                again = searched
        if again is not None:
            out[mid] = again
    return calibrated


def _moved(a: PhoneTrack, b: PhoneTrack, within_m: float) -> float:
    """The share of the frames either path publishes where the other is absent or further
    than ``within_m``."""
    frames = a.xy.keys() | b.xy.keys()
    if not frames:
        return 0.0
    same = sum(
        k in a.xy and k in b.xy and np.hypot(*np.subtract(a.xy[k], b.xy[k])) <= within_m
        for k in frames
    )
    return 1.0 - same / len(frames)


def _search_every(dt: float, max_hz: float | None) -> int:
    """The smallest k for which every k-th frame, ``dt`` s apart, is at most ``max_hz``."""
    if max_hz is None or dt <= 0:
        return 1
    return max(int(math.ceil(1.0 / (dt * max_hz) - 1e-9)), 1)


def _held(a: np.ndarray, every: int, n: int) -> np.ndarray:
    """Per-frame values found on every ``every``-th of ``n`` frames, held over the frames
    between."""
    return a if every == 1 else a[np.arange(n) // every]


class _Follower:
    """Follows one phone's carrier through the detections: the search (or a given alignment),
    then the path and the alignment refitted from it, ``refine_passes`` times."""

    def __init__(
        self,
        frame_t: np.ndarray,
        points: Sequence[np.ndarray],
        phones: dict[str, PhoneMotion],
        grid: SiteGrid,
        acfg: AlignConfig,
        cfg: RetrackConfig,
        aligned: bool,
    ) -> None:
        self.frame_t, self.points, self.phones, self.grid = frame_t, points, phones, grid
        self.acfg, self.cfg, self.aligned = acfg, cfg, aligned
        self.dt = float(np.median(np.diff(frame_t))) / 1e9
        self.every = _search_every(self.dt, cfg.search_max_hz)
        """The search sees every this many frames (:attr:`RetrackConfig.search_max_hz`)."""
        self.steps = _step_costs(grid.cell, self.dt, cfg)
        self.spread = (cfg.det_sigma_m**2, cfg.walk_sigma_mps**2 * self.dt)
        """Variances of where a path left the view and of its walk per frame (:class:`_Returns`)."""
        self.settle_steps = (
            self.steps
            if cfg.settle_walk_sigma_mps is None
            else _step_costs(grid.cell, self.dt, cfg, cfg.settle_walk_sigma_mps)
        )
        self.emissions = [grid.emission(p, cfg.det_sigma_m, cfg.miss_cost) for p in points]
        self.space: tuple[SiteGrid, list[np.ndarray | float]] | None = None
        self.walks = {mid: dead_reckoned(phones[mid]) for mid in sorted(phones)}
        self.alternatives: dict[str, list[tuple[float, np.ndarray]]] = {}
        """Each phone's other alignments from its last search."""
        self.taken: dict[str, dict[int, np.ndarray]] = {}
        """Per phone, the frames where another phone's carrier holds a detection, and what is
        left of the frame's detections without it (:func:`_exclusive`)."""

    def _frames(self, mid: str) -> tuple[Sequence[np.ndarray], Sequence[np.ndarray | float]]:
        """The detections phone ``mid`` may be on, and their emissions: every frame's but those
        another phone's carrier holds."""
        taken = self.taken.get(mid)
        if not taken:
            return self.points, self.emissions
        points, emissions = list(self.points), list(self.emissions)
        for k, left in taken.items():
            points[k] = left
            emissions[k] = self.grid.emission(left, self.cfg.det_sigma_m, self.cfg.miss_cost)
        return points, emissions

    def holding(self, mid: str, keeper: PhoneTrack, frames: Sequence[int]) -> dict[int, np.ndarray]:
        """Phone ``mid``'s taken detections (:attr:`taken`) with, at each of ``frames``, the one
        ``keeper``'s carrier is on (the nearest to its position, within ``gate_m``) added."""
        taken = dict(self.taken.get(mid, {}))
        for k in frames:
            left = taken.get(k, self.points[k])
            j = _nearest(left, keeper.xy[k], self.cfg.gate_m)
            if j is not None:
                taken[k] = np.delete(left, j, axis=0)
        return taken

    def __call__(
        self, mid: str, lag: float, a: np.ndarray, search: bool, radio: RadioEvidence | None
    ) -> PhoneTrack | None:
        frame_t, grid, cfg = self.frame_t, self.grid, self.cfg
        track = self.walks[mid]
        points, emissions = self._frames(mid)
        phone_em, visit = _with_radio(radio, mid, grid, emissions)
        if search:
            found = self._search(mid, lag, points, radio)
            if found is None:
                return None
            lag, a = found
        passes = 0 if self.aligned else cfg.refine_passes
        for p in range(passes + 1):
            u = _displacements(frame_t, track, lag, a)
            # every pass may come back into view (:class:`_Returns`): a start that fits one
            # visit of two (an identity's alignment off over the other) would otherwise be
            # refitted to the visit it fits, and the other lost
            cells = _viterbi_path(grid, phone_em, u, self.steps, visit, self.spread)
            gain = None
            if radio and radio.cfg.enabled and cfg.min_evidence is not None:
                gain = radio.gain(mid, grid.xy(cells))  # read by the publication rule only
            xy, seen, hits, withheld, twinned = _publish(frame_t, points, grid, cells, u, cfg, gain)
            if p == passes:
                break
            # refitted from what is published as the carrier (a stretch withheld is somebody
            # else, or says nothing), and from the stretches withheld as twins: whichever of
            # the two walkers carries the phone, they move alike, and the yaw and step that
            # fit one fit the carrier (without them the refit of a stretch nothing else is
            # published in is the rest's: PETS footage, `w` seed 2: P06's first 16 s beside P05,
            # ridden on her and withheld, were then out of view, the phone's yaw 95 deg off
            # there after a carry change): all the path's detections only while nothing is
            on = (
                {k: hits[k] for k in (*seen, *twinned)}
                if len(seen) >= cfg.min_align_frames
                else hits
            )
            fit = self._refit(mid, on, a, phone_em, visit)
            if fit is None:
                break
            lag, a = fit
        velocity = np.column_stack([u.real, u.imag]) / self.dt
        riding = {k: h for k, h in hits.items() if k not in seen}
        return PhoneTrack(xy, seen, velocity, lag, a, withheld, riding=riding)

    def _refit(
        self,
        mid: str,
        on: dict[int, np.ndarray],
        a: np.ndarray,
        phone_em: Sequence[np.ndarray | float],
        visit: Visit | None,
    ) -> tuple[float, np.ndarray] | None:
        """The alignment refitted from the detections ``on`` (:func:`_refit`). A carry too
        few of them fall in takes the whole fit or the alignment ``a`` the path was followed
        under, whichever path costs less (:func:`_whole_fit`): the detections say nothing of
        such a carry, and the path over the whole log tells the two apart."""
        changes = self.phones[mid].carry_changes
        track = self.walks[mid]
        fit = _refit(self.frame_t, on, track, self.acfg, self.cfg, changes)
        if fit is None or changes is None or not len(changes):
            return fit  # one carry: the prior is never kept (:func:`_whole_fit`)
        kept = _refit(self.frame_t, on, track, self.acfg, self.cfg, changes, a)
        if fit is None or kept is None or np.array_equal(fit[1], kept[1]):
            return fit
        costs = [self._cost(track, f[0], f[1], phone_em, visit) for f in (fit, kept)]
        return kept if costs[1] < costs[0] else fit

    def _cost(
        self,
        track: np.ndarray,
        lag: float,
        a: np.ndarray,
        phone_em: Sequence[np.ndarray | float],
        visit: Visit | None,
        steps: np.ndarray | None = None,
    ) -> float:
        """The cost of the cheapest path of the walk ``track`` under (``lag``, ``a``)."""
        u = _displacements(self.frame_t, track, lag, a)
        steps = self.steps if steps is None else steps
        costs = _layer_costs(self.grid, phone_em, u[:, None], steps, visit=visit, absolute=True)
        return float(costs[-1, 0])

    def _search(
        self, mid: str, lag: float, points: Sequence[np.ndarray], radio: RadioEvidence | None
    ) -> tuple[float, np.ndarray] | None:
        """Phone ``mid``'s alignment searched (:func:`_search`) on every k-th frame
        (:attr:`RetrackConfig.search_max_hz`), held over the frames between; its other
        alignments kept in :attr:`alternatives` the same way."""
        grid, coarse_em, coarse_visit = self._coarse(mid, radio)
        alternatives: list[tuple[float, np.ndarray]] = []
        found = _search(
            self.frame_t[:: self.every],
            points[:: self.every],
            self.walks[mid],
            lag,
            self.acfg,
            self.cfg,
            self.phones[mid].carry_changes,
            (grid, coarse_em),
            coarse_visit,
            alternatives,
        )
        n = len(self.frame_t)
        self.alternatives[mid] = [(lg, _held(a, self.every, n)) for lg, a in alternatives]
        return None if found is None else (found[0], _held(found[1], self.every, n))

    def _coarse(
        self, mid: str, radio: RadioEvidence | None
    ) -> tuple[SiteGrid, Sequence[np.ndarray | float], Visit | None]:
        """The search's coarse grid (built once), with phone ``mid``'s emissions and visit
        on it (its RSSI weighed in: :func:`_with_radio`), every ``every``-th frame."""
        if self.space is None:
            self.space = _search_field(self.points, self.cfg, self.every)
        coarse_em, coarse_visit = _with_radio(radio, mid, *self.space, every=self.every)
        return self.space[0], coarse_em, coarse_visit

    def carry_yaws(
        self, mid: str, lag: float, scale: float, radio: RadioEvidence | None
    ) -> np.ndarray | None:
        """Phone ``mid``'s yaw per carry (between the carry changes it saw) at clock offset
        ``lag`` and step ``scale``: the yaw whose paths cost least over each carry
        (:func:`_yaw_search` with ``steady``, on the search's grid and frames), per frame
        (complex, with the scale); None without a walk."""
        grid, coarse_em, coarse_visit = self._coarse(mid, radio)
        frame_t = self.frame_t[:: self.every]
        dt = float(np.median(np.diff(frame_t))) / 1e9 if len(frame_t) > 1 else 1.0
        steps = _step_costs(grid.cell, dt, self.cfg, self.cfg.search_walk_sigma_mps)
        changes = self.phones[mid].carry_changes
        yaw = _yaw_search(
            frame_t,
            grid,
            coarse_em,
            steps,
            self.walks[mid],
            lag,
            scale,
            self.cfg,
            changes,
            coarse_visit,
            steady=True,
        )
        return None if yaw is None else _held(yaw, self.every, len(self.frame_t))

    def cost(
        self,
        mid: str,
        found: PhoneTrack,
        radio: RadioEvidence | None,
        steps: np.ndarray | None = None,
    ) -> float:
        """The cost of the cheapest path under ``found``'s alignment (paths of two alignments
        of one phone compare), with the random walk's ``steps`` (None: the paths')."""
        phone_em, visit = _with_radio(radio, mid, self.grid, self._frames(mid)[1])
        return self._cost(self.walks[mid], found.lag_s, found.a, phone_em, visit, steps)

    def _weighed(
        self, mid: str, found: PhoneTrack, radio: RadioEvidence | None, margin: float
    ) -> list[tuple[float, PhoneTrack]]:
        """``found`` and the other alignments of its last search, each refined, with their
        paths' costs under ``settle_walk_sigma_mps`` (``found`` first). An alternative that
        costs more than ``margin`` more than ``found`` there can neither become the path nor
        dispute a frame; one that could is left out when it costs more than ``margin`` more
        under the walk paths are found under, and under both walks summed too or on a visit
        apart from ``found``'s (:func:`_apart`)."""
        tight = self.cost(mid, found, radio, self.settle_steps)
        weighed = [(tight, found)]
        loose: float | None = None
        for lag, a in self.alternatives.get(mid, []):
            other = self(mid, lag, a, False, radio)
            # an alignment whose path sees the carrier nowhere says where they are not, not
            # where they are: out of view all log is cheap under the tight walk wherever the
            # dead reckoning strays more than it (a phone in a bag on real footage: a path on
            # its carrier in 375 frames, 1020 against 970 for none), and the path that found
            # them has already beaten it under the walk paths are found under
            if other is None or not (other.seen or not found.seen):
                continue
            cost = self.cost(mid, other, radio, self.settle_steps)
            if cost - tight <= margin:
                # a contender is as cheap, or nearly, under the walk paths are found under,
                # or cheaper under both walks together: the tight walk alone prefers a short
                # visit to a long one of a phone that strays (PETS footage, seed 9: P10's bag,
                # on him 49 s at 771, 19 s on somebody else at 946 under the paths' walk;
                # under the tight walk 960 against 955), where an alignment on a carrier whose
                # search path rides strangers costs a little more under the paths' walk and
                # much less under the tight one (`students001` seed 2: 6-10 more, 24-30 less)
                loose = self.cost(mid, found, radio) if loose is None else loose
                worse = self.cost(mid, other, radio) - loose
                if worse > margin and (_apart(found, other) or cost - tight + worse > margin):
                    continue
            weighed.append((cost, other))
        return weighed

    def _combined(
        self, mid: str, found: PhoneTrack, candidates: list[PhoneTrack], radio: RadioEvidence | None
    ) -> PhoneTrack:
        """``found`` followed again with each carry's alignment taken from the candidate that
        sees the carrier most in that carry (:func:`_per_carry`), where that path sees more of
        the carrier, still publishes what ``found`` did (all but :data:`PART_LOST` of its seen
        frames, within ``gate_m``) and costs no more under the walk paths are found under.

        A carry change the phone saw turns its yaw, and the settling weighs whole alignments:
        one may fit the carry before a change and another the carry after it, and none both
        (PETS footage with phones, `n` seed 32: P05's phone in her hand at 5 Hz, the search's
        path at -123 deg, then +9 deg after the change near 60 s; the alignment adopted keeps
        -123 deg after it and loses her last 20 s; combined, 385 frames against 275, and 747
        against 763 under the paths' walk). A path that sees nobody is not combined: it has no
        account of the carrier to build on, and each candidate was weighed against it already
        (seed 29: P08's phone, on nobody, a candidate on P05's companion for 81 frames;
        combined, 92 frames at 1004.9 against 1005.5, and 3.7 s of wrong binding)."""
        if not found.seen:
            return found
        changes = self.phones[mid].carry_changes
        segments = np.cumsum(_carry_frames(self.frame_t, changes, found.lag_s))
        a = _per_carry(found, candidates, segments)
        if a is None:
            return found
        combined = self(mid, found.lag_s, a, False, radio)
        if combined is None or len(combined.seen) <= len(found.seen):
            return found
        if _lost(found, combined, self.cfg.gate_m) > PART_LOST:
            return found
        if self.cost(mid, combined, radio) > self.cost(mid, found, radio):
            return found
        return combined

    def settle(self, mid: str, found: PhoneTrack, radio: RadioEvidence | None) -> PhoneTrack:
        """The cheapest of ``found`` and the other alignments of its last search but a part
        of it (:func:`_part_of`), each refined, weighed under ``settle_walk_sigma_mps``
        (``found`` when that is None; which alternatives are weighed: :meth:`_weighed`), without
        the frames where another costs at most ``ambiguity_margin`` more and puts the carrier
        more than ``gate_m`` away (``ambiguous_s`` counts them), unless the middle of all those
        places is within ``gate_m`` of each: the frame is then published there
        (``grouped_s``). Frames the other does not publish are not in dispute: it did not see
        the carrier there."""
        cfg = self.cfg
        alternatives = self.alternatives.get(mid)
        if cfg.ambiguity_margin is None or not alternatives:
            return found
        adopt = cfg.settle_walk_sigma_mps is not None
        weighed = self._weighed(mid, found, radio, cfg.ambiguity_margin)
        # the first of equals: the search's own path; a part of it cannot replace it
        best, found = min(_contenders(weighed, cfg), key=lambda w: w[0]) if adopt else weighed[0]
        if adopt:
            found = self._combined(mid, found, [o for _, o in weighed], radio)
        near = [o for c, o in weighed if o is not found and c - best <= cfg.ambiguity_margin]
        alike = [o for o in near if _alike(o, found, ALIKE, self.acfg.lag_step_s)]
        found = _filled(found, alike, self.dt, cfg.min_stretch_s)
        xy, grouped, disputed = _settle_disputes(found.xy, [o.xy for o in near], cfg.gate_m)
        if not disputed and not grouped:
            return found
        # the middle of a group is on no one's detections: not seen (one person, one phone
        # does not take two phones of a group, each at its middle, for two on one person)
        return replace(
            found,
            xy=xy,
            seen=found.seen - disputed - grouped,
            ambiguous_s=found.ambiguous_s + len(disputed) * self.dt,
            grouped_s=found.grouped_s + len(grouped) * self.dt,
        )


ALIKE = 0.15
"""Two alignments of a phone are one (:func:`_alike`) where they differ by at most this share
of the alignment (scale 15 %, or yaw 8.6 deg), with clock offsets at most one step of the
refit's grid apart."""


PART_LOST = 0.05
"""A path that publishes all but at most this share of another's seen frames within
``gate_m`` still publishes what the other did (:func:`_part_of`, :func:`_off_others`)."""


def _part_of(other: PhoneTrack, found: PhoneTrack, cfg: RetrackConfig) -> bool:
    """Whether ``other`` sees the carrier only where ``found`` publishes them (all but
    :data:`PART_LOST` of its seen frames, within ``gate_m``), and in fewer frames: the same
    answer with frames left out of view. It cannot replace ``found`` in
    :meth:`_Follower.settle`, whose tight walk (``settle_walk_sigma_mps``) prices frames out of
    view at nothing wherever a dead reckoning strays more than it, so that it prefers a path
    that sees less of the carrier to one that sees more (PETS footage with phones, `n` seed
    30: P05's bag phone at 5 Hz, on both her visits, 354 frames, under the tight walk 859,
    under the paths' own walk 741; the alignment that leaves her second visit out of view, 246
    frames, all on her, 830 and 768: cheaper under the two walks summed by 2, adopted, and her
    last 42 s lost). It can still dispute a frame (:func:`_settle_disputes`), where it puts
    the carrier elsewhere."""
    return len(other.seen) < len(found.seen) and _lost(other, found, cfg.gate_m) <= PART_LOST


def _apart(found: PhoneTrack, other: PhoneTrack) -> bool:
    """Whether ``other`` sees the carrier mostly while ``found`` does not: less than half of
    the shorter of the two visits (first to last seen frame) falls within the other. Two such
    paths do not explain the same frames: out of view the tight walk
    (``settle_walk_sigma_mps``) costs no more than the paths' walk, in view every frame pays
    for how far the detections stray from the phone's walk, so under it the shorter visit is
    cheaper whoever it is on, and only the walk paths are found under tells the two apart
    (:meth:`_Follower._weighed`; PETS footage with phones, `n` seed 49: P10's phone, in his
    hand at 5 Hz, on him 21.9-69.3 s, 310 frames, at 835 under the paths' walk and 1032 under
    the tight one, where the dead reckoning strays after his carry change at 42 s; a stranger
    3.6-19.6 s, 109 frames, at 910 under both: P10 never named)."""
    if not found.seen or not other.seen:
        return False
    a, b = (min(found.seen), max(found.seen)), (min(other.seen), max(other.seen))
    shared = min(a[1], b[1]) - max(a[0], b[0])
    return shared < 0.5 * min(a[1] - a[0], b[1] - b[0])


def _per_carry(
    found: PhoneTrack, candidates: Sequence[PhoneTrack], segments: np.ndarray
) -> np.ndarray | None:
    """``found``'s alignment with each carry's frames (``segments``: a carry's number per
    frame) taken from the candidate whose path sees the carrier in most of them, where one
    sees more than ``found`` does (None: none does anywhere). A candidate's clock offset is
    not taken: one phone has one clock."""
    if not len(segments) or segments[-1] == 0:
        return None
    a = found.a.copy()
    changed = False
    for s in range(int(segments[-1]) + 1):
        frames = np.flatnonzero(segments == s)

        def seen(t: PhoneTrack, frames: np.ndarray = frames) -> int:
            return int(np.isin(frames, list(t.seen)).sum())

        best = max(candidates, key=seen)
        if seen(best) > seen(found):
            a[frames] = best.a[frames]
            changed = True
    return a if changed else None


def _contenders(
    weighed: list[tuple[float, PhoneTrack]], cfg: RetrackConfig
) -> list[tuple[float, PhoneTrack]]:
    """``weighed`` (the phone's path first, then its alternatives, each with its cost) without
    the alternatives that are a part of the path (:func:`_part_of`): those that may replace it
    in :meth:`_Follower.settle`."""
    path = weighed[0][1]
    return [w for w in weighed if w[1] is path or not _part_of(w[1], path, cfg)]


def _alike(a: PhoneTrack, b: PhoneTrack, share: float, lag_step_s: float) -> bool:
    """``a`` and ``b`` are one alignment refined twice: clock offsets at most ``lag_step_s``
    apart (neighbours on the refit's grid, :attr:`AlignConfig.lag_step_s`: the true offset lies
    between them, and the refit cannot tell them apart by more than a few units of cost), and
    ``a`` within ``share`` of ``b`` (:data:`ALIKE`) over the median frame where both are
    known."""
    if abs(a.lag_s - b.lag_s) > lag_step_s + 1e-6:
        return False
    rel = np.abs(a.a - b.a) / np.maximum(np.abs(b.a), 1e-9)
    rel = rel[np.isfinite(rel)]
    return bool(len(rel)) and float(np.median(rel)) <= share


def _filled(found: PhoneTrack, alike: Sequence[PhoneTrack], dt: float, min_s: float) -> PhoneTrack:
    """``found`` with the runs of frames it does not publish that paths of its own alignment
    (:func:`_alike`, nearly as cheap) publish, each run at least ``min_s`` long (publication's
    ``min_stretch_s``): two Viterbi paths of one alignment whose costs differ by a few units
    part where the carrier walks beside somebody, or out of view, and the one that rides
    somebody else there withholds the stretch (:func:`_one_carrier`), or does not bridge the
    gap, where the other publishes it (PETS footage: P06's first 12 s beside P05; P05's 15 s
    out of view). Where those paths disagree with each other the frame is disputed as any
    other (:func:`_settle_disputes`)."""
    extra = {k: p for o in alike for k, p in o.xy.items() if k not in found.xy}
    ks = np.array(sorted(extra), dtype=np.int64)
    runs = np.split(ks, np.flatnonzero(np.diff(ks) > 1) + 1) if len(ks) else []
    keep = [r for r in runs if (len(r) - 1) * dt >= min_s]
    if not keep:
        return found
    add = {int(k): extra[int(k)] for r in keep for k in r}
    seen = {k for o in alike for k in o.seen if k in add}
    return replace(
        found,
        xy={**found.xy, **add},
        seen=found.seen | seen,
        withheld_s=max(0.0, found.withheld_s - len(add) * dt),
    )


def _settle_disputes(
    xy: dict[int, tuple[float, float]], others: list[dict[int, tuple[float, float]]], gate_m: float
) -> tuple[dict[int, tuple[float, float]], set[int], set[int]]:
    """Where the paths ``others`` (as cheap, or nearly) put the carrier more than ``gate_m``
    from ``xy``: the frame's position becomes the middle of all of them when that is within
    ``gate_m`` of each (a group walking together: whoever of them carries the phone, it is
    there), and the frame is disputed otherwise. Returns the positions, the frames moved to
    their middle and the disputed frames (not in the positions). A path that does not publish a
    frame has no say in it."""
    out: dict[int, tuple[float, float]] = {}
    grouped: set[int] = set()
    disputed: set[int] = set()
    for k, p in xy.items():
        hyps = [p] + [o[k] for o in others if k in o]
        pts = np.asarray(hyps, float)
        if np.all(np.hypot(*(pts[1:] - pts[0]).T) <= gate_m):
            out[k] = p
            continue
        mid = pts.mean(axis=0)
        if np.all(np.hypot(*(pts - mid).T) <= gate_m):
            out[k] = (float(mid[0]), float(mid[1]))
            grouped.add(k)
        else:
            disputed.add(k)
    return out, grouped, disputed
