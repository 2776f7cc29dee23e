"""EV-Matching algorithms (dissertation §3.2.3-3.2.4): EID set splitting with vague zones, VID
filtering and matching refining (SS), and the single-EID baseline EDP.

SS, step by step:

1. **EID set splitting** (Algorithms 1 and 3). The partition starts as {Ueid}. Each iteration
   takes a random window (a random time stamp, as the paper's Preprocess does), keeps its
   E-scenarios that list an EID still to be distinguished, and splits every set by them in one
   shuffle: an EID's new set is (old set, cell it is listed in). This is the multi-way form of the
   paper's binary split; an EID in the vague zone is listed in every cell it was heard in for a
   fair share of the window and goes to each of them (the paper's "vague EIDs go to both
   children"). A set's path records a scenario only when the split changed the set (Algorithm 1:
   "if P_eid changes then record C"). A requested EID alone in a set is distinguished; its
   evidence is the recorded scenarios of that set where it was *inclusive* (vague ones are never
   used to identify an EID, §3.2.3 B). Sets with no EID left to distinguish are dropped.
2. **VID filtering**. Every evidence scenario's V-scenario is read once (shared by all EIDs that
   use it) and each EID's VIDs are counted across its evidence; the VID seen most is the match.
3. **Matching refining** (Algorithm 2). A result is acceptable when the EID has >= ``min_evidence``
   scenarios, the best VID leads the runner-up by >= ``margin`` and shows in >= ``support`` of
   them. Otherwise (missing VIDs, people without a phone sharing the scenarios) the EID gets the
   next window's inclusive scenario and is filtered again, until acceptable or out of scenarios
   (``max_evidence``); then it is unresolved, with the reason. VIDs matched with confidence are
   ruled out for the others (a VID belongs to one person).

EDP (the baseline of [78], adapted to MapReduce with one EID per task as the paper does): for one
EID, greedily pick the scenarios listing it that shrink its candidate EID set the most, with no
vague zones, then take the VID seen most in those V-scenarios (one pass, no refining). Each task
reads its own V-scenarios, so one read serves one EID.
"""

from __future__ import annotations

import itertools
import time
from array import array
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple, overload

import numpy as np
import pandas as pd

from trackctl.evmatch.data import EData, VSource, VStore
from trackctl.evmatch.eindex import ECatalog, EIndex, local_index
from trackctl.evmatch.engines import Engine
from trackctl.logs.messages import EvMatch

__all__ = [
    "MatchParams",
    "MatchOutcome",
    "match_ss",
    "match_edp",
    "window_order",
    "AMBIGUOUS",
]

AMBIGUOUS = "ambiguous"
REASON_UNKNOWN = "EID never appears in the E-observations"
REASON_NO_INCLUSIVE = "never in an inclusive zone: only vague E-observations, no usable evidence"


@dataclass(frozen=True)
class MatchParams:
    """Acceptance rule of VID filtering and limits of refining."""

    margin: int = 1
    min_evidence: int = 2
    support: float = 0.5
    max_evidence: int = 12


Evidence = dict[int, "array[int]"]
"""Evidence scenarios per EID code, as compact arrays (a city has a million EIDs)."""


def _evidence_type(cat: ECatalog) -> str:
    """The ``array`` type code of evidence: 4-byte ids when every scenario id fits."""
    return "i" if len(cat.windows_ns) * max(cat.n_cells, 1) < 2**31 else "q"


class _Result(NamedTuple):
    """One EID's outcome without its evidence names (built into an EvMatch on demand)."""

    vid: str | None
    confidence: float
    reason: str
    status: str
    candidates: tuple[str, ...]


class _Results:
    """Outcomes by EID code as arrays (a city resolves a million EIDs; a tuple each would take
    ~200 bytes): status, best VID, runner-up and confidence, plus the reason and candidates of
    the few EIDs left unmatched."""

    _STATUS = ("", "matched", AMBIGUOUS, "unresolved")

    def __init__(self, n_eids: int) -> None:
        self.status = np.zeros(n_eids, np.int8)
        self.vid = np.full(n_eids, None, object)
        self.runner_up = np.full(n_eids, None, object)
        self.confidence = np.zeros(n_eids, np.float64)
        self._other: dict[int, tuple[str, tuple[str, ...]]] = {}
        self._count = 0

    def __len__(self) -> int:
        return self._count

    def __contains__(self, e: object) -> bool:
        return isinstance(e, (int, np.integer)) and bool(self.status[int(e)])

    def __setitem__(self, e: int, r: _Result) -> None:
        if not self.status[e]:
            self._count += 1
        self.status[e] = self._STATUS.index(r.status)
        self.confidence[e] = r.confidence
        if r.status == "matched":
            self.vid[e] = r.vid
            self.runner_up[e] = r.candidates[1] if len(r.candidates) > 1 else None
            self._other.pop(e, None)
        else:
            self.vid[e] = r.vid
            self._other[e] = (r.reason, r.candidates)

    def update(self, results: dict[int, _Result]) -> None:
        for e, r in results.items():
            self[e] = r

    def __getitem__(self, e: int) -> _Result:
        status = int(self.status[e])
        if not status:
            raise KeyError(e)
        vid = self.vid[e]
        if status == 1:
            v2 = self.runner_up[e]
            cands: tuple[str, ...] = (vid,) if v2 is None else (vid, v2)
            return _Result(vid, float(self.confidence[e]), "", "matched", cands)
        reason, other = self._other[e]
        return _Result(vid, float(self.confidence[e]), reason, self._STATUS[status], other)


class Matches(Sequence[EvMatch]):
    """The matches in request order, each built on demand from a compact result and the EID's
    evidence ids: a million EvMatch objects with their evidence names would need gigabytes."""

    def __init__(
        self,
        cat: ECatalog,
        requested: Sequence[str],
        result: _Results,
        evidence: Evidence,
        missing: Collection[int],
    ) -> None:
        self._cat = cat
        self._requested = requested
        self._codes = (
            pd.Index(cat.eids).get_indexer(list(requested))
            if len(requested)
            else np.zeros(0, np.int64)
        )
        self._result = result
        self._evidence = evidence
        self._missing = missing

    def __len__(self) -> int:
        return len(self._requested)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and list(self) == list(other)

    __hash__ = None  # type: ignore[assignment]

    def _build(self, i: int) -> EvMatch:
        e = int(self._codes[i])
        if e < 0:
            return EvMatch(self._requested[i], None, 0.0, (), REASON_UNKNOWN, "unresolved")
        r = self._result[e]
        names = tuple(
            self._cat.scenario_name(s) for s in self._evidence.get(e, ()) if s not in self._missing
        )
        return EvMatch(
            str(self._cat.eids[e]), r.vid, r.confidence, names, r.reason, r.status, r.candidates
        )

    @overload
    def __getitem__(self, i: int) -> EvMatch: ...

    @overload
    def __getitem__(self, i: slice) -> list[EvMatch]: ...

    def __getitem__(self, i: int | slice) -> EvMatch | list[EvMatch]:
        if isinstance(i, slice):
            return [self._build(j) for j in range(*i.indices(len(self)))]
        if not -len(self) <= i < len(self):
            raise IndexError(i)
        return self._build(i % len(self))


def _pairs(eids: Sequence[int], evidence: Evidence) -> tuple[np.ndarray, np.ndarray]:
    """(EID, scenario) arrays of the EIDs' evidence, without a Python list per pair; int32 when
    the ids fit (a city's first refining round has ten million pairs)."""
    lens = np.fromiter((len(evidence[e]) for e in eids), np.int64, count=len(eids))
    total = int(lens.sum())
    # evidence arrays hold 4-byte ids ('i') exactly when every scenario id fits (_evidence_type)
    s_type = np.int32 if eids and evidence[eids[0]].itemsize == 4 else np.int64
    e_type = np.int32 if max(eids, default=0) < 2**31 else np.int64
    ev_e = np.repeat(np.asarray(eids, e_type), lens)
    ev_s = np.fromiter(itertools.chain.from_iterable(evidence[e] for e in eids), s_type, total)
    return ev_e, ev_s


@dataclass
class MatchOutcome:
    """Matches (one per requested EID, in request order) plus the work it took."""

    matches: Sequence[EvMatch]
    v_scenarios_read: int = 0
    v_scenarios_unique: int = 0
    v_bytes_read: int = 0
    split_iterations: int = 0
    refine_rounds: int = 0
    distinguished: int = 0
    stage_seconds: dict[str, float] = field(default_factory=dict)


def window_order(n_windows: int, seed: int) -> np.ndarray:
    """The random order in which windows (time stamps) are taken."""
    return np.random.default_rng(seed).permutation(n_windows)


def _rank(order: np.ndarray) -> np.ndarray:
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    return rank


def _ranges(starts: np.ndarray, lens: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(starts[i], starts[i] + lens[i])`` for every i, without a loop."""
    total = int(lens.sum())
    if not total:
        return np.zeros(0, np.int64)
    before = np.cumsum(lens) - lens
    return np.repeat(np.asarray(starts, np.int64) - before, lens) + np.arange(total)


@dataclass(frozen=True)
class _Paths:
    """Each set's path of splitting scenarios, as one flat array with offsets (CSR): a city has
    a million sets with a dozen scenarios each, too many for a tuple per set."""

    start: np.ndarray  # int64, one more than there are sets
    flat: np.ndarray  # scenario ids, int32 when they fit

    @classmethod
    def root(cls, n_scenarios: int) -> _Paths:
        dtype = np.int32 if n_scenarios < 2**31 else np.int64
        return cls(np.zeros(2, np.int64), np.zeros(0, dtype))

    def lens(self, sets: np.ndarray) -> np.ndarray:
        return self.start[sets + 1] - self.start[sets]

    def child(self, parent: np.ndarray, append: np.ndarray | None = None) -> _Paths:
        """New sets, set i being ``parent[i]``'s path plus ``append[i]`` when that is >= 0."""
        parent = np.asarray(parent, np.int64)
        plen = self.lens(parent)
        extra = np.zeros(len(parent), np.int64) if append is None else (append >= 0)
        start = np.zeros(len(parent) + 1, np.int64)
        np.cumsum(plen + extra, out=start[1:])
        flat = np.empty(int(start[-1]), self.flat.dtype)
        flat[_ranges(start[:-1], plen)] = self.flat[_ranges(self.start[parent], plen)]
        if append is not None:
            grow = np.flatnonzero(extra)
            flat[start[grow] + plen[grow]] = append[grow]
        return _Paths(start, flat)

    def members(self, sets: np.ndarray) -> np.ndarray:
        """The scenarios of the given sets' paths, concatenated."""
        return self.flat[_ranges(self.start[sets], self.lens(sets))].astype(np.int64)


def _path_evidence(
    eindex: EIndex, sets: np.ndarray, eids: np.ndarray, paths: _Paths
) -> tuple[np.ndarray, np.ndarray]:
    """For each (set, EID) pair: the scenarios of the set's path where the EID is inclusive (one
    batched question to the E index), as per-pair counts and the scenarios concatenated."""
    lens = paths.lens(sets)
    flat_s = paths.members(sets)
    pair = np.repeat(np.arange(len(sets)), lens)
    mask = eindex.inclusive_mask(np.asarray(eids, np.int64)[pair], flat_s)
    return np.bincount(pair[mask], minlength=len(sets)), flat_s[mask]


def _longest_per_eid(
    eids: np.ndarray, counts: np.ndarray, flat: np.ndarray, typecode: str
) -> dict[int, array[int]]:
    """Each EID's longest evidence among its copies (the first copy on ties)."""
    if not len(eids):
        return {}
    starts = np.cumsum(counts) - counts
    order = np.lexsort((np.arange(len(eids)), -counts, eids))
    first = order[np.r_[True, eids[order][1:] != eids[order][:-1]]]
    out: dict[int, array[int]] = {}
    as_type = np.int32 if array(typecode).itemsize == 4 else np.int64
    for e, a, n in zip(
        eids[first].tolist(), starts[first].tolist(), counts[first].tolist(), strict=True
    ):
        ev = array(typecode)
        ev.frombytes(flat[a : a + n].astype(as_type).tobytes())
        out[e] = ev
    return out


def _set_split(
    eindex: EIndex,
    targets: np.ndarray,
    order: np.ndarray,
    engine: Engine,
    progress: Callable[[int, int | None], None] | None,
) -> tuple[Evidence, int, int]:
    """EID set splitting; returns evidence per target, how many targets were distinguished (alone
    in a set), iterations."""
    cat = eindex.catalog
    n_e = len(cat.eids)
    pending = np.zeros(n_e, bool)
    pending[targets] = True
    node = np.zeros(n_e, np.int64)
    eid = np.arange(n_e, dtype=np.int64)
    paths = _Paths.root(len(cat.windows_ns) * cat.n_cells)
    evidence: Evidence = {}
    iterations = 0
    for w in order:
        if not pending.any():
            break
        iterations += 1
        lw_eid, lw_cell = eindex.listing(int(w))
        # Preprocess: only the scenarios that list an EID still to be distinguished
        useful = np.unique(lw_cell[pending[lw_eid]])
        keep = np.isin(lw_cell, useful)
        listing = pd.DataFrame({"eid": lw_eid[keep], "cell": lw_cell[keep]})
        del lw_eid, lw_cell, keep
        split = _split_sets(engine.split(node, eid, listing), node, paths, int(w), cat.n_cells)
        if split is None:
            break
        node, eid, paths = _settle(*split, pending, eindex, evidence)
        if progress is not None:
            progress(int((~pending[targets]).sum()), len(targets))
    distinguished = int((~pending[targets]).sum())
    # targets never alone: their best copy's evidence (refining may still resolve them)
    left = pending[eid]
    counts, flat = _path_evidence(eindex, node[left], eid[left], paths)
    evidence.update(_longest_per_eid(eid[left], counts, flat, _evidence_type(cat)))
    return evidence, distinguished, iterations


def _split_sets(
    out: pd.DataFrame, node: np.ndarray, paths: _Paths, w: int, n_cells: int
) -> tuple[np.ndarray, np.ndarray, _Paths] | None:
    """The engine's split as dense set ids, EIDs and each set's path of splitting scenarios
    (a set that did not change keeps its parent's path); None when nothing is left."""
    o_node = out["node"].to_numpy(np.int64)
    o_cell = out["cell"].to_numpy(np.int64)
    o_eid = out["eid"].to_numpy(np.int64)
    if not len(o_eid):
        return None
    start = np.r_[True, (o_node[1:] != o_node[:-1]) | (o_cell[1:] != o_cell[:-1])]
    gid = np.cumsum(start) - 1
    gsize = np.bincount(gid)
    parent_size = np.bincount(node)
    g_first = np.flatnonzero(start)
    g_parent = o_node[g_first]
    g_cell = o_cell[g_first]
    changed = (gsize != parent_size[g_parent]) & (g_cell >= 0)
    append = np.where(changed, w * n_cells + g_cell, -1)
    return gid, o_eid, paths.child(g_parent, append)


def _settle(
    node: np.ndarray,
    eid: np.ndarray,
    paths: _Paths,
    pending: np.ndarray,
    eindex: EIndex,
    evidence: Evidence,
) -> tuple[np.ndarray, np.ndarray, _Paths]:
    """Take out the targets alone in a set (distinguished, with their path's inclusive
    scenarios as evidence; an EID alone in several sets keeps its longest); dropping them may
    leave others alone, so repeat."""
    while True:
        alone = (np.bincount(node)[node] == 1) & pending[eid] if len(node) else node > 0
        if alone.any():
            counts, flat = _path_evidence(eindex, node[alone], eid[alone], paths)
            done = _longest_per_eid(eid[alone], counts, flat, _evidence_type(eindex.catalog))
            evidence.update(done)
            done_ids = np.fromiter(done, np.int64, len(done))
            pending[done_ids] = False
            keep_rows = ~_rows_in(eid, done_ids, len(pending))
            node, eid = node[keep_rows], eid[keep_rows]
        if len(node):
            # drop sets with no EID left to distinguish; renumber densely (order kept)
            has_pending = np.bincount(node, weights=pending[eid].astype(float)) > 0
            keep_rows = has_pending[node]
            node, eid = node[keep_rows], eid[keep_rows]
            uniq, node = np.unique(node, return_inverse=True)
            paths = paths.child(uniq)
        if not alone.any() or not len(node):
            break
    return node, eid, paths


def _rows_in(eid: np.ndarray, done: np.ndarray, n_eids: int) -> np.ndarray:
    """Rows whose EID is in ``done`` (a dense lookup: ``np.isin`` sorts both sides)."""
    flag = np.zeros(n_eids, bool)
    flag[done] = True
    return flag[eid]


class _Judgement:
    """VID filtering's judgement of the pending EIDs, as arrays aligned with ``eids`` (a city
    judges a million EIDs a round): best free VID and votes, runner-up and votes, evidence with
    video, and a code for why the result is not acceptable (0 when it is); the reason's text is
    made only for the EIDs that end unresolved."""

    OK, NO_FREE, FEW, TIE, WEAK = range(5)

    def __init__(
        self, counts: pd.DataFrame, eids: np.ndarray, usable: np.ndarray, params: MatchParams
    ) -> None:
        ce = counts["eid"].to_numpy(np.int64)
        cv = counts["vid"].to_numpy(object)
        cc = counts["count"].to_numpy(np.int64)
        n = len(eids)
        self.eids, self.n, self.params = eids, usable, params
        self.v1 = np.full(n, None, object)
        self.v2 = np.full(n, None, object)
        self.c1 = np.zeros(n, np.int64)
        self.c2 = np.zeros(n, np.int64)
        found = np.zeros(n, bool)
        if len(ce):
            first = np.flatnonzero(np.r_[True, ce[1:] != ce[:-1]])
            pos = np.minimum(np.searchsorted(ce[first], eids), len(first) - 1)
            found = ce[first][pos] == eids
            i1 = first[pos]
            i2 = np.minimum(i1 + 1, len(ce) - 1)
            second = found & (i1 + 1 < len(ce)) & (ce[i2] == eids)
            self.v1[found], self.c1[found] = cv[i1[found]], cc[i1[found]]
            self.v2[second], self.c2[second] = cv[i2[second]], cc[i2[second]]
        code = np.full(n, self.OK, np.int64)
        code[self.c1 < params.support * usable] = self.WEAK
        code[self.c1 - self.c2 < params.margin] = self.TIE
        code[usable < params.min_evidence] = self.FEW
        code[~found] = self.NO_FREE
        self.code = code

    def why(self, i: int) -> str:
        n, v1, c1 = int(self.n[i]), self.v1[i], int(self.c1[i])
        v2, c2, code = self.v2[i], int(self.c2[i]), self.code[i]
        if code == self.NO_FREE:
            return f"no free VID in its {n} V-scenarios"
        if code == self.FEW:
            return f"only {n} evidence scenario(s) with video (need {self.params.min_evidence})"
        if code == self.TIE:
            return f"{AMBIGUOUS} after {n} scenarios: {v1} in {c1}, {v2 or '-'} in {c2}"
        if code == self.WEAK:
            return f"weak: best VID {v1} in only {c1} of {n} scenarios"
        return ""

    def candidates(self, i: int) -> tuple[str, ...]:
        return tuple(str(x) for x in (self.v1[i], self.v2[i]) if x is not None)


def _ranked(counts: pd.DataFrame) -> dict[int, list[tuple[str, int]]]:
    """Top two (VID, count) per EID."""
    top = counts.groupby("eid", sort=False).head(2)
    out: dict[int, list[tuple[str, int]]] = {}
    for e, v, c in zip(
        top["eid"].tolist(), top["vid"].tolist(), top["count"].tolist(), strict=True
    ):
        out.setdefault(int(e), []).append((str(v), int(c)))
    return out


def _confidence(c1: int, c2: int, n: int) -> float:
    return round(max(0.0, min(1.0, (c1 - c2) / n)), 4) if n else 0.0


def _targets_and_order(
    data: ECatalog, requested: Sequence[str], seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """The requested EIDs' codes (unique, sorted; EIDs the log never saw are answered apart)
    and the seeded order in which both algorithms visit the time windows."""
    codes, _ = data.eid_codes(requested)
    return np.unique(codes), window_order(len(data.windows_ns), seed)


def match_ss(
    data: EData | EIndex,
    vstore: VSource,
    requested: Sequence[str],
    engine: Engine,
    params: MatchParams,
    seed: int,
    progress: Callable[[int, int | None], None] | None = None,
) -> MatchOutcome:
    """EID set splitting + VID filtering + matching refining (see the module docstring).

    ``data`` is the E table (queried in this process) or an :class:`EIndex` built with the
    same seed's window order (the Spark engine's, whose shards live on the executors).
    """
    t0 = time.perf_counter()
    cat = data.catalog if isinstance(data, EIndex) else data
    targets, order = _targets_and_order(cat, requested, seed)
    eindex = data if isinstance(data, EIndex) else local_index(data, data.rows, _rank(order))
    evidence, distinguished, iterations = _set_split(eindex, targets, order, engine, progress)
    t1 = time.perf_counter()
    result = _Results(len(cat.eids))
    typecode = _evidence_type(cat)
    shared = eindex.multi_located()
    have_inclusive = eindex.with_inclusive(targets)
    pending: list[int] = []
    for e in targets.tolist():
        evidence[e] = evidence.get(e, array(typecode))
        if not evidence[e] and not have_inclusive[e]:
            result[e] = _unresolved(REASON_NO_INCLUSIVE)
        elif e not in shared:
            pending.append(e)
    mine = [e for e in targets.tolist() if e in shared and e not in result]
    for e, first in eindex.first_inclusive(mine, params.max_evidence).items():
        evidence[e] = array(typecode, first)
    result.update(_judge_shared(vstore, engine, evidence, shared, mine))
    rounds = 0
    taken: set[str] = set()
    while pending:
        rounds += 1
        pending = _refine_round(eindex, vstore, engine, params, evidence, pending, taken, result)
        if progress is not None:
            progress(len(result), len(targets))
    t2 = time.perf_counter()
    return MatchOutcome(
        matches=Matches(cat, requested, result, evidence, vstore.missing),
        v_scenarios_read=vstore.reads,
        v_scenarios_unique=vstore.reads,
        v_bytes_read=vstore.bytes_read,
        split_iterations=iterations,
        refine_rounds=rounds,
        distinguished=distinguished,
        stage_seconds={"wall_s_split": t1 - t0, "wall_s_filter": t2 - t1},
    )


def _unresolved(why: str, candidates: tuple[str, ...] = ()) -> _Result:
    status = AMBIGUOUS if why.startswith(AMBIGUOUS) else "unresolved"
    return _Result(None, 0.0, why, status, candidates)


def _judge_shared(
    vstore: VSource,
    engine: Engine,
    evidence: Evidence,
    shared: dict[int, str],
    mine: list[int],
) -> dict[int, _Result]:
    """EIDs carried by several devices: ``ambiguous``, with the VIDs their evidence shows most."""
    if not mine:
        return {}
    ev_e, ev_s = _pairs(mine, evidence)
    ranked = _ranked(vstore.vote(engine, ev_e, ev_s))
    out = {}
    for e in mine:
        top = ranked.get(e, [])
        shown = ", ".join(f"{v} in {c}" for v, c in top)
        why = f"{AMBIGUOUS}: {shared[e]}" + (f"; candidates {shown}" if shown else "")
        out[e] = _unresolved(why, tuple(v for v, _ in top))
    return out


def _extend_all(
    eindex: EIndex,
    eids: Sequence[int],
    evidence: Evidence,
    params: MatchParams,
    vstore: VSource,
) -> set[int]:
    """Give each EID more evidence (one batched question to the E index): every V-scenario
    already read where it is inclusive (no extra video to process), else the inclusive scenario
    farthest in time from its evidence (people who share a cell now likely share it a minute
    later, so a near window rarely tells them apart); ties go to the earlier window in the random
    order. Scenarios without video do not count toward ``max_evidence``. Returns the EIDs that
    got more."""
    missing = vstore.missing
    room = {e: params.max_evidence - _usable(evidence[e], missing) for e in eids}
    requests = {e: evidence[e] for e in eids if room[e] > 0}
    added = eindex.extend(requests, vstore.known, missing, room)
    for e, more in added.items():
        evidence[e].extend(more)
    return set(added)


def _refine_round(
    eindex: EIndex,
    vstore: VSource,
    engine: Engine,
    params: MatchParams,
    evidence: Evidence,
    pending: list[int],
    taken: set[str],
    result: _Results,
) -> list[int]:
    """One round of VID filtering and matching refining; returns the EIDs still pending."""
    missing = vstore.missing
    # add one scenario to EIDs short of evidence before filtering (free of a V read if shared)
    short = [e for e in pending if _usable(evidence[e], missing) < params.min_evidence]
    _extend_all(eindex, short, evidence, params, vstore)
    ev_e, ev_s = _pairs(pending, evidence)
    counts = vstore.vote(engine, ev_e, ev_s, taken)
    del ev_e, ev_s
    eids = np.asarray(pending, np.int64)
    usable = np.fromiter((_usable(evidence[e], missing) for e in pending), np.int64, len(pending))
    j = _Judgement(counts, eids, usable, params)
    del counts
    ok = np.flatnonzero(j.code == _Judgement.OK)
    ok = ok[np.lexsort((eids[ok], -j.c1[ok], -(j.c1[ok] - j.c2[ok])))]
    still: list[int] = []
    claimed: set[str] = set()
    for i in ok.tolist():
        e, vid, v2 = int(eids[i]), j.v1[i], j.v2[i]
        if vid in claimed:
            still.append(e)  # the VID went to a stronger claim this round; re-judge next round
            continue
        claimed.add(vid)
        conf = _confidence(int(j.c1[i]), int(j.c2[i]), int(usable[i]))
        result[e] = _Result(vid, conf, "", "matched", (vid,) if v2 is None else (vid, v2))
    taken |= claimed
    waiting = set(still)
    rest = [i for i, e in enumerate(pending) if e not in result and e not in waiting]
    grown = _extend_all(eindex, [pending[i] for i in rest], evidence, params, vstore)
    for i in rest:
        e = pending[i]
        if e in grown:
            still.append(e)
        else:
            result[e] = _unresolved(j.why(i), j.candidates(i))
    return sorted(still)


def _usable(scenarios: Sequence[int], missing: Collection[int]) -> int:
    return sum(1 for s in scenarios if s not in missing)


def match_edp(
    data: EData,
    vstore: VStore,
    requested: Sequence[str],
    engine: Engine,
    params: MatchParams,
    seed: int,
    progress: Callable[[int, int | None], None] | None = None,
) -> MatchOutcome:
    """The EDP baseline: per-EID greedy E-filtering then one V-identification vote."""
    t0 = time.perf_counter()
    targets, order = _targets_and_order(data, requested, seed)
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    rows = data.rows
    w = rows["w"].to_numpy(np.int64)
    s_all = w * data.n_cells + rows["cell"].to_numpy(np.int64)
    e_all = rows["eid"].to_numpy(np.int64)
    want = np.isin(e_all, targets)
    useful = np.unique(s_all[want])
    in_useful = np.isin(s_all, useful)
    members: dict[int, frozenset[int]] = {
        int(s): frozenset(g.tolist())
        for s, g in pd.Series(e_all[in_useful]).groupby(s_all[in_useful])
    }
    by_eid: dict[int, list[int]] = {}
    sel = np.flatnonzero(want)
    sel = sel[np.lexsort((s_all[sel], rank[w[sel]], e_all[sel]))]
    for e, s in zip(e_all[sel].tolist(), s_all[sel].tolist(), strict=True):
        by_eid.setdefault(e, []).append(s)
    max_ev = params.max_evidence

    def select(e: int) -> list[int]:
        cands = by_eid.get(e, [])
        chosen: list[int] = []
        current: frozenset[int] | None = None
        while len(chosen) < max_ev:
            best, best_set = None, None
            for s in cands:
                if s in chosen:
                    continue
                inter = members[s] if current is None else current & members[s]
                if best_set is None or len(inter) < len(best_set):
                    best, best_set = s, inter
            if best is None or best_set is None:
                break
            if current is not None and len(best_set) >= len(current):
                break
            chosen.append(best)
            current = best_set
            if len(current) <= 1:
                break
        return chosen

    chosen_all = engine.edp_select(targets.tolist(), select)
    t1 = time.perf_counter()
    evidence: Evidence = {
        e: array(_evidence_type(data), ch)
        for e, ch in zip(targets.tolist(), chosen_all, strict=True)
    }
    ev_e, ev_s = _pairs(targets.tolist(), evidence)
    ranked = _ranked(vstore.vote(engine, ev_e, ev_s))
    result = _Results(len(data.eids))
    reads = 0
    nbytes = 0
    for e, ch in zip(targets.tolist(), chosen_all, strict=True):
        # each EID task reads its own V-scenarios (no sharing across EIDs)
        reads += len(ch)
        nbytes += sum(vstore.sizes.get(s, 0) for s in ch)
        n = _usable(ch, vstore.missing)
        r = ranked.get(e, [])
        if not ch:
            result[e] = _unresolved("no E-scenario lists it")
        elif not r:
            result[e] = _unresolved(f"no VID in its {n} V-scenarios")
        else:
            c2 = r[1][1] if len(r) > 1 else 0
            result[e] = _Result(
                r[0][0], _confidence(r[0][1], c2, n), "", "matched", tuple(v for v, _ in r)
            )
    if progress is not None:
        progress(len(targets), len(targets))
    t2 = time.perf_counter()
    return MatchOutcome(
        matches=Matches(data, requested, result, evidence, vstore.missing),
        v_scenarios_read=reads,
        v_scenarios_unique=vstore.reads,
        v_bytes_read=nbytes,
        split_iterations=0,
        refine_rounds=0,
        distinguished=0,
        stage_seconds={"wall_s_split": t1 - t0, "wall_s_filter": t2 - t1},
    )
