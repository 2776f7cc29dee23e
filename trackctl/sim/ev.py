"""EV-Matching scenarios (dissertation §3.2.5 A): people under cell-level E-location and cameras.

People walk by the random-waypoint model (Camp et al.: uniform destination, uniform speed, uniform
pause) in a square area cut into square cells. Every ``sample_s`` each person is sampled:

* **E side** - a person who carries a phone (share ``1 - eid_miss``) is located at cell level;
  within ``drift_m`` of a cell border the E-location drifts into the neighbour cell with a
  probability that falls linearly from ``drift_p`` at the border to 0 at ``drift_m``. Per window
  and cell the EIDs' occurrence shares give the zones: ``>= inclusive_frac`` inclusive,
  ``>= vague_frac`` vague, below that exclusive (not listed).
  With ``drift_m`` > cell/2 every sample can drift, and a drifting sample lands up to
  ``drift_m - d`` past the border (uniform), so beyond the adjacent cell when ``drift_m`` > cell
  (cell-ID positioning on large or overlapping cells). A phone is heard only when it talks to the
  network: with ``hear_s`` set, each sample is heard with probability ``sample_s / hear_s``
  (random activity; the default hears every sample) and the zone shares count heard samples only.
  ``shared_eids`` pairs of people carry one EID (a cloned or colliding MAC, a shared phone): one
  EID then moves in two places at once.
* **V side** - each cell has a camera: its V-scenario of a window lists every person seen in the
  cell in at least one sampled frame, with the mean ground position and the number of frames; a
  person's VID is missing from a V-scenario with probability ``vid_miss`` (occlusion, missed
  detection). **Re-identification errors**: with probability ``reid_error`` per person and window
  the person's detections carry another person's VID for the whole window (errors are correlated
  within a window, as a tracker's identity switch is): the VID of someone in the same cell when
  there is one (an identity switch between neighbours), else of a random person (a wrong gallery
  match). The person's own VID is then absent from those V-scenarios.

Each cell's V-scenarios are on their own topic (``/ev/cell/<i>_<j>/v``), one message per window at
the window's start time, so a matcher reads one V-scenario through the MCAP index without touching
the others. E-observations and V-scenarios go to separate chunks (each window: one or more chunks of
E, then of V), so loading the E table never decompresses video data. The EID <-> VID ground truth
is one ``trackctl.GroundTruth`` on ``/ev/ground_truth``.

The walkers are vectorised over people (one state array, stepped at ``sample_s``) instead of
:func:`trackctl.sim.walkers.random_waypoint`, which samples one person at a time on a 50 ms grid:
that is far too slow and too large for 100k people over an hour.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from trackctl.errors import InputError
from trackctl.logs import topics
from trackctl.logs.jsonmap import NS_PER_S
from trackctl.logs.messages import (
    EObservations,
    GroundTruth,
    GroundTruthEntity,
    Vec3,
    VScenario,
)
from trackctl.logs.writer import MAX_CHANNELS, LogWriter

GROUND_TRUTH_BATCH = 10_000

__all__ = ["EvScenario", "simulate_ev", "cell_name", "eid_name", "vid_name"]


@dataclass(frozen=True)
class EvScenario:
    """Parameters of an EV scenario (defaults: the paper's 1000 people in 1000 x 1000 m)."""

    people: int = 1000
    area_m: float = 1000.0
    cell_m: float = 100.0
    duration_s: float = 1800.0
    window_s: float = 60.0
    sample_s: float = 5.0
    eid_miss: float = 0.1
    vid_miss: float = 0.02
    drift_m: float = 15.0
    drift_p: float = 0.5
    inclusive_frac: float = 0.75
    vague_frac: float = 0.25
    speed_mps: tuple[float, float] = (0.5, 1.5)
    pause_s: tuple[float, float] = (0.0, 60.0)
    hear_s: float | None = None
    reid_error: float = 0.0
    shared_eids: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.people < 1:
            raise InputError(f"--people {self.people}: need at least one person")
        if not (self.cell_m > 0 and self.area_m >= self.cell_m):
            raise InputError(f"--cell {self.cell_m} / --area {self.area_m}: need 0 < cell <= area")
        for name in ("eid_miss", "vid_miss", "drift_p", "reid_error"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise InputError(f"--{name.replace('_', '-')} {value}: expected a share in [0, 1]")
        if not 0 <= self.drift_m <= self.area_m:
            raise InputError(f"--drift-m {self.drift_m}: expected 0..area ({self.area_m})")
        if self.hear_s is not None and not self.hear_s > 0:
            raise InputError(f"--hear-interval {self.hear_s}: expected seconds > 0")
        if self.cells_per_side**2 + 2 > MAX_CHANNELS:
            raise InputError(
                f"--area {self.area_m} / --cell {self.cell_m}: {self.cells_per_side**2} cells, one "
                f"V topic each, exceed the {MAX_CHANNELS - 2} an MCAP log can hold (16-bit channel "
                "ids); use larger cells"
            )
        if not 0 <= 2 * self.shared_eids <= self.people:
            raise InputError(
                f"--shared-eids {self.shared_eids}: expected 0..people/2 ({self.people // 2})"
            )
        if not (0 < self.sample_s <= self.window_s <= self.duration_s):
            raise InputError(
                f"sample {self.sample_s} s, window {self.window_s} s, duration "
                f"{self.duration_s} s: need 0 < sample <= window <= duration"
            )
        if not 0 < self.vague_frac <= self.inclusive_frac <= 1:
            raise InputError("need 0 < vague_frac <= inclusive_frac <= 1")

    @property
    def cells_per_side(self) -> int:
        return int(math.ceil(self.area_m / self.cell_m - 1e-9))

    @property
    def windows(self) -> int:
        return int(self.duration_s // self.window_s)

    @property
    def samples_per_window(self) -> int:
        return max(1, int(round(self.window_s / self.sample_s)))


def cell_name(i: int, j: int) -> str:
    """Cell ``(i, j)`` (column along x, row along y) as ``<i>_<j>``."""
    return f"{i}_{j}"


def eid_name(code: int) -> str:
    """A locally administered MAC address (the EID of a phone) from an integer."""
    b = code.to_bytes(4, "big")
    return "02:00:" + ":".join(f"{x:02x}" for x in b)


def vid_name(code: int) -> str:
    """A visual ID label (what a re-identification stage would assign)."""
    return f"vid-{code:06d}"


class _Walkers:
    """Random-waypoint walkers, vectorised over people."""

    def __init__(self, cfg: EvScenario, rng: np.random.Generator) -> None:
        n = cfg.people
        self.cfg = cfg
        self.rng = rng
        self.pos = rng.uniform(0.0, cfg.area_m, (n, 2))
        self.target = rng.uniform(0.0, cfg.area_m, (n, 2))
        self.speed = rng.uniform(*cfg.speed_mps, n)
        self.pause = np.zeros(n)

    def step(self, dt: float) -> None:
        cfg, rng = self.cfg, self.rng
        pausing = self.pause > 0
        self.pause[pausing] -= dt
        resume = pausing & (self.pause <= 0)
        k = int(resume.sum())
        if k:
            self.target[resume] = rng.uniform(0.0, cfg.area_m, (k, 2))
            self.speed[resume] = rng.uniform(*cfg.speed_mps, k)
        moving = ~pausing
        delta = self.target[moving] - self.pos[moving]
        dist = np.hypot(delta[:, 0], delta[:, 1])
        reach = self.speed[moving] * dt
        arrive = dist <= reach
        frac = np.where(arrive, 1.0, reach / np.maximum(dist, 1e-12))
        self.pos[moving] += delta * frac[:, None]
        idx = np.flatnonzero(moving)[arrive]
        if idx.size:
            # an arrival pauses at least a moment so a zero pause still draws a new leg next step
            self.pause[idx] = np.maximum(rng.uniform(*cfg.pause_s, idx.size), 1e-9)


def _e_cells(cfg: EvScenario, pos: np.ndarray, rng: np.random.Generator, n_side: int) -> np.ndarray:
    """Cell index (i, j) of each E-location sample, with border drift."""
    c = cfg.cell_m
    ij = np.clip(np.floor(pos / c).astype(np.int64), 0, n_side - 1)
    lo = pos - ij * c
    hi = (ij + 1) * c - pos
    near_hi = hi < lo
    d = np.where(near_hi, hi, lo)
    toward = np.where(near_hi, 1, -1)
    if cfg.drift_m > 0:
        p = cfg.drift_p * np.clip(1.0 - d / cfg.drift_m, 0.0, 1.0)
    else:
        p = np.zeros_like(d)
    drift = rng.random(d.shape) < p
    step = toward
    if cfg.drift_m > c / 2:
        # past the border by up to drift_m - d: 1 cell, or more when drift_m > cell
        beyond = rng.uniform(0.0, 1.0, d.shape) * np.maximum(cfg.drift_m - d, 0.0)
        step = toward * (1 + np.floor(beyond / c).astype(np.int64))
    moved = ij + np.where(drift, step, 0)
    moved = np.clip(moved, 0, n_side - 1)
    return np.where(drift, moved, ij)


class _CountingWriter:
    """A log writer that counts the messages it writes per topic."""

    def __init__(self, writer: LogWriter) -> None:
        self.writer = writer
        self.counts: dict[str, int] = {}

    def put(self, topic: str, msg: object) -> None:
        self.writer.write(topic, msg)
        self.counts[topic] = self.counts.get(topic, 0) + 1


@dataclass(frozen=True, slots=True)
class _Ids:
    """Who carries a phone, and every person's EID and VID."""

    has_phone: np.ndarray
    eids: np.ndarray
    vids: np.ndarray


def _identities(cfg: EvScenario, rng: np.random.Generator) -> _Ids:
    """Draw phone carriers, EIDs and VIDs; ``shared_eids`` pairs of carriers share one EID."""
    n = cfg.people
    has_phone = rng.random(n) >= cfg.eid_miss
    eid_codes = rng.permutation(n) + 1
    vid_codes = rng.permutation(n) + 1
    eids = np.array([eid_name(int(c)) for c in eid_codes])
    vids = np.array([vid_name(int(c)) for c in vid_codes])
    if cfg.shared_eids:
        # pairs of phone carriers: the second of each pair carries the first's EID
        carriers = np.flatnonzero(has_phone)
        k = min(cfg.shared_eids, len(carriers) // 2)
        pick = rng.choice(carriers, 2 * k, replace=False)
        eids[pick[k:]] = eids[pick[:k]]
    return _Ids(has_phone, eids, vids)


def _write_truth(out: _CountingWriter, walkers: _Walkers, ids: _Ids, n: int) -> None:
    """The truth in messages of at most 10 000 people: a million-person city stays streamable."""
    for first in range(0, n, GROUND_TRUTH_BATCH):
        entities = tuple(
            GroundTruthEntity(
                entity_id=f"person{p:06d}",
                position_m=Vec3(float(walkers.pos[p, 0]), float(walkers.pos[p, 1]), 0.0),
                electronic_id=str(ids.eids[p]) if ids.has_phone[p] else None,
                visual_id=str(ids.vids[p]),
            )
            for p in range(first, min(n, first + GROUND_TRUTH_BATCH))
        )
        out.put(topics.EV_GROUND_TRUTH, GroundTruth(0, entities))


@dataclass(frozen=True, slots=True)
class _WindowSamples:
    """One window's samples: E keys (person * cells + cell) of heard samples, heard samples per
    person, V keys and the positions they were seen at."""

    e_keys: np.ndarray
    heard: np.ndarray
    v_keys: np.ndarray
    v_pos: np.ndarray


def _sample_window(
    cfg: EvScenario,
    walkers: _Walkers,
    phone_idx: np.ndarray,
    n_side: int,
    rng: np.random.Generator,
) -> _WindowSamples:
    """Sample everyone ``samples_per_window`` times (video cell, E cell if heard), walking on."""
    n = cfg.people
    n_cells = n_side * n_side
    e_keys = []
    v_keys = []
    v_pos = []
    heard = np.zeros(n, np.int64)
    for _ in range(cfg.samples_per_window):
        ij = np.clip(np.floor(walkers.pos / cfg.cell_m).astype(np.int64), 0, n_side - 1)
        v_keys.append(np.arange(n) * n_cells + ij[:, 1] * n_side + ij[:, 0])
        v_pos.append(walkers.pos.copy())
        eij = _e_cells(cfg, walkers.pos[phone_idx], rng, n_side)
        keys = phone_idx * n_cells + eij[:, 1] * n_side + eij[:, 0]
        if cfg.hear_s is not None:
            on = rng.random(len(phone_idx)) < min(1.0, cfg.sample_s / cfg.hear_s)
            keys = keys[on]
            heard[phone_idx[on]] += 1
        else:
            heard[phone_idx] += 1
        e_keys.append(keys)
        walkers.step(cfg.sample_s)
    return _WindowSamples(
        np.concatenate(e_keys), heard, np.concatenate(v_keys), np.concatenate(v_pos)
    )


@dataclass(frozen=True, slots=True)
class _EWindow:
    """A window's listed E entries (person, cell, vague?), sorted by cell then EID; entries of
    cell c are ``order[bounds[c]:bounds[c + 1]]``."""

    person: np.ndarray
    vague: np.ndarray
    order: np.ndarray
    bounds: np.ndarray


def _e_window(cfg: EvScenario, s: _WindowSamples, eids: np.ndarray, n_cells: int) -> _EWindow:
    """E-scenarios: occurrence share per (person, cell) -> inclusive / vague / exclusive."""
    ek, ecount = np.unique(s.e_keys, return_counts=True)
    share = ecount / np.maximum(s.heard[ek // n_cells], 1)
    listed = share >= cfg.vague_frac - 1e-12
    ek, share = ek[listed], share[listed]
    e_person, e_cell = ek // n_cells, ek % n_cells
    e_vague = share < cfg.inclusive_frac - 1e-12
    e_order = np.lexsort((eids[e_person], e_cell))
    e_bounds = np.searchsorted(e_cell[e_order], np.arange(n_cells + 1))
    return _EWindow(e_person, e_vague, e_order, e_bounds)


@dataclass(frozen=True, slots=True)
class _VWindow:
    """A window's V detections (labelled person, mean position, frames), sorted by cell then
    VID; detections of cell c are ``order[bounds[c]:bounds[c + 1]]``."""

    person: np.ndarray
    x: np.ndarray
    y: np.ndarray
    frames: np.ndarray
    order: np.ndarray
    bounds: np.ndarray


def _v_window(
    cfg: EvScenario,
    s: _WindowSamples,
    vids: np.ndarray,
    n_cells: int,
    rng: np.random.Generator,
) -> _VWindow:
    """V-scenarios: every person seen in >= 1 frame, minus missed detections, relabelled by
    re-identification errors."""
    vk, vinv, vcount = np.unique(s.v_keys, return_inverse=True, return_counts=True)
    vx = np.bincount(vinv, weights=s.v_pos[:, 0]) / vcount
    vy = np.bincount(vinv, weights=s.v_pos[:, 1]) / vcount
    keep = rng.random(vk.size) >= cfg.vid_miss
    vk, vx, vy, vcount = vk[keep], vx[keep], vy[keep], vcount[keep]
    v_person, v_cell = vk // n_cells, vk % n_cells
    if cfg.reid_error > 0:
        v_person = _reid_errors(cfg.reid_error, v_person, v_cell, cfg.people, rng)
    v_order = np.lexsort((vids[v_person], v_cell))
    v_bounds = np.searchsorted(v_cell[v_order], np.arange(n_cells + 1))
    return _VWindow(v_person, vx, vy, vcount, v_order, v_bounds)


@dataclass(frozen=True, slots=True)
class _Window:
    """What every message of one window shares."""

    t_ns: int
    window_ns: int
    samples: int
    names: list[str]
    """Cell names, by cell index."""


def _write_e(out: _CountingWriter, win: _Window, e: _EWindow, eids: np.ndarray) -> None:
    """One EObservations message per cell (all on the E topic)."""
    for c, name in enumerate(win.names):
        sel = e.order[e.bounds[c] : e.bounds[c + 1]]
        out.put(
            topics.EV_E,
            EObservations(
                t_ns=win.t_ns,
                window_ns=win.window_ns,
                cell=name,
                eids=tuple(eids[e.person[sel]].tolist()),
                vague=tuple(e.vague[sel].tolist()),
                samples=win.samples,
            ),
        )


def _write_v(
    out: _CountingWriter, win: _Window, v: _VWindow, vids: np.ndarray, v_topics: list[str]
) -> None:
    """One VScenario message per cell, each on its cell's topic."""
    for c, name in enumerate(win.names):
        sel = v.order[v.bounds[c] : v.bounds[c + 1]]
        out.put(
            v_topics[c],
            VScenario(
                t_ns=win.t_ns,
                window_ns=win.window_ns,
                cell=name,
                vids=tuple(vids[v.person[sel]].tolist()),
                # ground positions from video: decimetre resolution
                x_m=tuple(np.round(v.x[sel], 1).tolist()),
                y_m=tuple(np.round(v.y[sel], 1).tolist()),
                frames=tuple(v.frames[sel].tolist()),
            ),
        )


def simulate_ev(out: str, cfg: EvScenario | None = None) -> dict[str, int]:
    """Write an EV-Matching scenario log to ``out``; returns messages per topic.

    Raises:
        InputError: a parameter is out of range.
    """
    cfg = cfg or EvScenario()
    rng = np.random.default_rng(cfg.seed)
    n_side = cfg.cells_per_side
    n_cells = n_side * n_side
    ids = _identities(cfg, rng)
    walkers = _Walkers(cfg, rng)
    window_ns = int(round(cfg.window_s * NS_PER_S))
    names = [cell_name(i, j) for j in range(n_side) for i in range(n_side)]
    v_topics = [topics.ev_v(name) for name in names]
    with LogWriter(out) as writer:
        log = _CountingWriter(writer)
        writer.add_metadata("ev/scenario", {k: str(v) for k, v in asdict(cfg).items()})
        _write_truth(log, walkers, ids, cfg.people)
        writer.flush()
        phone_idx = np.flatnonzero(ids.has_phone)
        for w in range(cfg.windows):
            win = _Window(w * window_ns, window_ns, cfg.samples_per_window, names)
            samples = _sample_window(cfg, walkers, phone_idx, n_side, rng)
            e = _e_window(cfg, samples, ids.eids, n_cells)
            v = _v_window(cfg, samples, ids.vids, n_cells, rng)
            _write_e(log, win, e, ids.eids)
            writer.flush()  # E and V in separate chunks
            _write_v(log, win, v, ids.vids, v_topics)
            writer.flush()
    return log.counts


def _reid_errors(
    p: float, person: np.ndarray, cell: np.ndarray, n: int, rng: np.random.Generator
) -> np.ndarray:
    """Who each V detection is labelled as, after re-identification errors (module docstring).

    One draw per person and window: a person whose draw fails is labelled, in every cell they are
    seen in this window, as a neighbour in the same cell (identity switch) or, alone, as a random
    person (wrong gallery match)."""
    wrong = rng.random(n) < p
    hit = np.flatnonzero(wrong[person])
    if not hit.size:
        return person
    out = person.copy()
    # a random other detection of the same cell: sort detections by cell, pick an offset that
    # skips the detection itself
    order = np.argsort(cell, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    lo = np.searchsorted(cell[order], cell[hit], side="left")
    sizes = np.searchsorted(cell[order], cell[hit], side="right") - lo
    r = (rng.random(hit.size) * np.maximum(sizes - 1, 1)).astype(np.int64)
    cand = lo + r
    cand = np.where(cand >= rank[hit], cand + 1, cand).clip(0, order.size - 1)
    other = person[order[cand]]
    stranger = rng.integers(0, max(n - 1, 1), hit.size)
    stranger = np.where(stranger >= person[hit], stranger + 1, stranger) % n
    out[hit] = np.where(sizes > 1, other, stranger)
    # one wrong label per person per window: the same substitute in every cell they are seen in
    first: dict[int, int] = {}
    for i, (who, sub) in enumerate(zip(person[hit].tolist(), out[hit].tolist(), strict=True)):
        out[hit[i]] = first.setdefault(who, sub)
    return out
