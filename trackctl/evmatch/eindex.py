"""The E side of EV-Matching as set splitting and refining query it, in shards.

The matcher never walks the E table itself: it asks an :class:`EIndex` for one window's listings
(set splitting), for which (EID, scenario) pairs are inclusive (evidence), for each EID's next
evidence scenario (refining) and for EIDs listed in two places at once. Every question is answered
per :class:`EShard` (the listings of some windows, integer-coded with the log's global codes) and
the partial answers are combined on the driver by the same functions, so

* the local engine holds one shard with every window (:func:`local_index`), and
* the Spark engine holds one shard per group of windows on the executors, each built by the
  executor from the log's E chunks (:mod:`trackctl.evmatch.spark`); the driver only receives the
  answers (one window's listings, evidence lists, picks), never the E table.

Both therefore give the same answers, and the matches are identical whichever engine ran.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["ECatalog", "EShard", "EIndex", "local_index", "Pick"]

# a candidate scenario in the random window order: (rank of its window, cell, scenario id)
Pick = tuple[int, int, int]


@dataclass
class ECatalog:
    """What the driver knows of the E-observations: names and codes, not the listings.

    Attributes:
        eids: EID names, sorted; an EID's code is its index.
        cells: cell names, sorted; a cell's code is its index.
        windows_ns: window start times, sorted; a window's code is its index.
        window_ns: window length (ns).
        e_scenarios: number of (window, cell) E-scenarios that list at least one EID.
    """

    eids: np.ndarray
    cells: list[str]
    windows_ns: np.ndarray
    window_ns: int
    e_scenarios: int = 0

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    def scenario_id(self, w: np.ndarray | int, cell: np.ndarray | int) -> np.ndarray | int:
        return w * self.n_cells + cell

    def scenario_name(self, s: int) -> str:
        """``<cell>@<window start ns>`` (how matches name their evidence)."""
        w, c = divmod(int(s), self.n_cells)
        return f"{self.cells[c]}@{int(self.windows_ns[w])}"

    def eid_codes(self, names: Iterable[str]) -> tuple[np.ndarray, list[str]]:
        """Codes of the known names (in the given order) and the names that never appear."""
        names = list(names)
        idx = pd.Index(self.eids).get_indexer(names) if names else np.zeros(0, np.int64)
        missing = [n for n, i in zip(names, idx, strict=True) if i < 0]
        return idx[idx >= 0].astype(np.int64), missing


@dataclass
class EShard:
    """The E listings of some windows: parallel arrays sorted by (window, cell, EID).

    Attributes:
        w, cell, eid: integer codes (global: the catalog's).
        vague: the listing is in the vague zone.
        n_cells, n_eids: sizes of the code spaces.
        rank: each window's rank in the matcher's random window order (every window of the log).
    """

    w: np.ndarray
    cell: np.ndarray
    eid: np.ndarray
    vague: np.ndarray
    n_cells: int
    n_eids: int
    rank: np.ndarray
    _inc: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    @property
    def windows(self) -> np.ndarray:
        return np.unique(self.w)

    def _inclusive(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Inclusive listings as sorted keys (membership) and their scenarios grouped by EID in
        window order (with each EID's bounds); 12 bytes per listing plus 8 per EID, built with a
        few int64 temporaries (a city has tens of millions of listings)."""
        if self._inc is None:
            keep = np.flatnonzero(~self.vague)
            n_e = max(self.n_eids, 1)
            e = self.eid[keep]
            s = self.w[keep].astype(np.int64)
            s *= self.n_cells
            s += self.cell[keep]
            keys = s * n_e
            keys += e
            keys.sort()
            # group by EID, then window rank, then cell: one int64 key, one stable argsort
            n_s = max(len(self.rank), 1) * max(self.n_cells, 1)
            group = self.rank[s // max(self.n_cells, 1)] * max(self.n_cells, 1)
            group += s % max(self.n_cells, 1)
            group += e.astype(np.int64) * n_s
            by = np.argsort(group, kind="stable")
            del group
            small = np.int32 if not len(s) or s.max() < 2**31 else np.int64
            s_by = s[by].astype(small)
            bounds = np.searchsorted(e[by], np.arange(self.n_eids + 1))
            del by, s
            self._inc = (keys, s_by, bounds)
        return self._inc

    def listing(self, w: int) -> tuple[np.ndarray, np.ndarray]:
        """(EID, cell) of every listing in window ``w`` (empty when the shard lacks it)."""
        lo, hi = np.searchsorted(self.w, [w, w + 1])
        return self.eid[lo:hi].astype(np.int64), self.cell[lo:hi].astype(np.int64)

    def inclusive_hits(self, e: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Positions of the (EID, scenario) pairs that are inclusive listings of this shard
        (sparse: a shard holds few of the windows asked about)."""
        keys = self._inclusive()[0]
        if not len(keys):
            return np.zeros(0, np.int64)
        k = np.asarray(s, np.int64) * max(self.n_eids, 1) + np.asarray(e, np.int64)
        i = np.searchsorted(keys, k)
        return np.flatnonzero(keys[np.minimum(i, len(keys) - 1)] == k)

    def _of(self, e: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Scenario, window rank, cell and window of ``e``'s inclusive listings, in window
        order."""
        _, s_by, bounds = self._inclusive()
        s = s_by[bounds[e] : bounds[e + 1]].astype(np.int64)
        w = s // self.n_cells
        return s, self.rank[w], s % self.n_cells, w

    def with_inclusive(self, eids: np.ndarray) -> np.ndarray:
        """The EIDs of ``eids`` with at least one inclusive listing here."""
        bounds = self._inclusive()[2]
        eids = np.asarray(eids, np.int64)
        return eids[bounds[eids + 1] > bounds[eids]]

    def first_inclusive(self, eids: Iterable[int], k: int) -> dict[int, list[Pick]]:
        """Each EID's first ``k`` inclusive scenarios here, in window order."""
        out: dict[int, list[Pick]] = {}
        for e in eids:
            s, r, c, _ = self._of(int(e))
            if len(s):
                out[int(e)] = list(zip(r[:k].tolist(), c[:k].tolist(), s[:k].tolist(), strict=True))
        return out

    def extend_candidates(
        self,
        requests: Sequence[tuple[int, Sequence[int], int]],
        read: Collection[int],
        missing: Collection[int],
    ) -> dict[int, tuple[int, list[Pick], tuple[int, int, int, int]]]:
        """For each (EID, evidence, room) request: the fresh inclusive scenarios here already
        read (in window order, at most ``room``), and the best fresh one to read next: farthest
        in windows from the evidence, the earlier in window order on ties, as
        ``(gap, -rank, -cell, scenario)``. Merged across shards by :func:`merge_extend`."""
        out: dict[int, tuple[int, list[Pick], tuple[int, int, int, int]]] = {}
        for e, evidence, room in requests:
            s, r, c, w = self._of(int(e))
            if not len(s):
                continue
            have = set(evidence)
            fresh = np.array([x not in have and x not in missing for x in s.tolist()], bool)
            if not fresh.any():
                continue
            s, r, c, w = s[fresh], r[fresh], c[fresh], w[fresh]
            free = [
                (ri, ci, si)
                for ri, ci, si in zip(r.tolist(), c.tolist(), s.tolist(), strict=True)
                if si in read
            ]
            if evidence:
                used = np.asarray(evidence, np.int64) // self.n_cells
                gap = np.abs(w.astype(np.int64)[:, None] - used[None, :]).min(axis=1)
            else:
                gap = np.zeros(len(s), np.int64)
            i = int(np.argmax(gap))  # the first maximum: earliest in window order
            out[int(e)] = (room, free[:room], (int(gap[i]), -int(r[i]), -int(c[i]), int(s[i])))
        return out

    def inclusive_window_counts(self, eids: np.ndarray) -> dict[int, int]:
        """Windows of this shard in which each EID of ``eids`` is inclusive."""
        out = {}
        for e in np.asarray(eids).tolist():
            w = self._of(int(e))[3]
            if len(w):
                out[int(e)] = len(np.unique(w))
        return out

    def multi_counts(self) -> pd.DataFrame:
        """Per EID: windows here where it is inclusive in 2+ cells (``multi``); only EIDs with
        ``multi`` > 0."""
        keep = ~self.vague
        if not keep.any():
            return pd.DataFrame({"eid": [], "multi": []}, dtype=np.int64)
        per = (
            pd.DataFrame({"eid": self.eid[keep], "w": self.w[keep]})
            .groupby(["eid", "w"], sort=True)
            .size()
        )
        multi = (per >= 2).groupby(level="eid").sum()
        multi = multi[multi > 0]
        return pd.DataFrame(
            {"eid": multi.index.to_numpy(np.int64), "multi": multi.to_numpy(np.int64)}
        )


# A runner calls one EShard method with the given arguments on every shard (or on the shards
# holding one window) and returns the partial answers; the EIndex combines them. The Spark
# runner broadcasts the arguments (they can be millions of ids) instead of closing over them.
Runner = Callable[[str, tuple[Any, ...], int | None], list[Any]]
# A pair runner calls a shard method that answers per key (EID), merges the answers of all
# shards per key with ``merge`` and turns each into a list of ints with ``finish``; it returns
# the (key, int) pairs as two arrays. On Spark the merging runs on the executors (reduceByKey),
# so the driver receives one short answer per EID, not one per shard and EID.
PairRunner = Callable[
    [str, tuple[Any, ...], Callable[[Any, Any], Any], Callable[[Any], list[int]]],
    tuple[np.ndarray, np.ndarray],
]


def merge_extend(
    a: tuple[int, list[Pick], tuple[int, int, int, int]],
    b: tuple[int, list[Pick], tuple[int, int, int, int]],
) -> tuple[int, list[Pick], tuple[int, int, int, int]]:
    """Two shards' refining candidates for one EID: the read ones in window order (at most
    ``room``), and the better next one."""
    room = a[0]
    return room, sorted(a[1] + b[1])[:room], max(a[2], b[2])


def finish_extend(v: tuple[int, list[Pick], tuple[int, int, int, int]]) -> list[int]:
    """The scenarios refining adds: the already-read ones if any, else the best next one."""
    room, free, best = v
    return [p[2] for p in sorted(free)[:room]] if free else [best[3]]


class EIndex:
    """The E side, answered shard by shard (see the module docstring).

    Args:
        catalog: names and codes.
        run: calls a shard method on the shards: ``run(name, args, window)`` returns
            ``[shard.name(*args), ...]`` for every shard, or for the shards holding ``window``
            when it is not None.
        rank: each window's rank in the random window order.
        close: releases the shards (the Spark engine unpersists its RDD).
    """

    def __init__(
        self,
        catalog: ECatalog,
        run: Runner,
        rank: np.ndarray,
        close: Callable[[], None] | None = None,
        run_pairs: PairRunner | None = None,
    ) -> None:
        self.catalog = catalog
        self._run = run
        self.rank = rank
        self._close = close
        self._run_pairs = run_pairs or self._pairs_here

    def _pairs_here(
        self,
        name: str,
        args: tuple[Any, ...],
        merge: Callable[[Any, Any], Any],
        finish: Callable[[Any], list[int]],
    ) -> tuple[np.ndarray, np.ndarray]:
        """Keyed answers merged and finished in this process (the local engine)."""
        merged: dict[int, Any] = {}
        for part in self._run(name, args, None):
            for key, value in part.items():
                merged[key] = merge(merged[key], value) if key in merged else value
        pairs = [(k, x) for k, v in merged.items() for x in finish(v)]
        return (
            np.array([k for k, _ in pairs], np.int64),
            np.array([x for _, x in pairs], np.int64),
        )

    def close(self) -> None:
        if self._close is not None:
            self._close()

    def listing(self, w: int) -> tuple[np.ndarray, np.ndarray]:
        parts = self._run("listing", (w,), w)
        eid = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
        cell = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0, np.int64)
        return eid, cell

    def inclusive_mask(self, e: np.ndarray, s: np.ndarray) -> np.ndarray:
        e, s = np.asarray(e, np.int64), np.asarray(s, np.int64)
        if not len(e):
            return np.zeros(0, bool)
        out = np.zeros(len(e), bool)
        for hits in self._run("inclusive_hits", (e, s), None):
            out[hits] = True
        return out

    def with_inclusive(self, eids: np.ndarray) -> np.ndarray:
        """A mask over all EID codes: True for those of ``eids`` with an inclusive listing."""
        eids = np.asarray(eids, np.int64)
        found = np.zeros(len(self.catalog.eids), bool)
        for part in self._run("with_inclusive", (eids,), None):
            found[part] = True
        return found

    def first_inclusive(self, eids: Sequence[int], k: int) -> dict[int, list[int]]:
        merged: dict[int, list[Pick]] = {}
        for part in self._run("first_inclusive", (eids, k), None):
            for e, picks in part.items():
                merged.setdefault(e, []).extend(picks)
        return {e: [p[2] for p in sorted(picks)[:k]] for e, picks in merged.items()}

    def extend(
        self,
        requests: Mapping[int, Sequence[int]],
        read: Collection[int],
        missing: Collection[int],
        room: dict[int, int],
    ) -> dict[int, list[int]]:
        """The scenarios to add to each requesting EID's evidence (see
        :meth:`EShard.extend_candidates`): every fresh one already read, up to ``room[e]``, else
        the best one to read next. EIDs with nothing fresh are left out."""
        if not requests:
            return {}
        items = [(e, ev, room[e]) for e, ev in requests.items()]
        e_arr, s_arr = self._run_pairs(
            "extend_candidates", (items, read, missing), merge_extend, finish_extend
        )
        out: dict[int, list[int]] = {}
        for e, x in zip(e_arr.tolist(), s_arr.tolist(), strict=True):
            out.setdefault(e, []).append(x)
        return out

    def multi_located(self, min_windows: int = 2, min_share: float = 0.25) -> dict[int, str]:
        """EIDs inclusive in two or more cells in the same window, often: more than one device.

        One phone cannot spend most of a window in each of two cells (an inclusive zone means
        "most of the window here"), so an EID that does so in >= ``min_windows`` windows and in
        >= ``min_share`` of the windows it is inclusive in is carried by several devices (a
        cloned or colliding MAC, an IMSI shared by two people). Returns EID code -> the reason.
        """
        parts = [p for p in self._run("multi_counts", (), None) if len(p)]
        if not parts:
            return {}
        multi = pd.concat(parts).groupby("eid")["multi"].sum()
        flagged = multi[multi >= min_windows]
        if flagged.empty:
            return {}
        # the share needs every window where the EID is inclusive, in every shard
        totals = self._inclusive_windows(flagged.index.to_numpy(np.int64))
        out = {}
        for e, n in flagged.items():
            total = totals[int(e)]
            if n >= min_share * total:
                out[int(e)] = (
                    f"inclusive in 2+ cells at once in {int(n)} of its {total} "
                    "windows: more than one device carries this EID"
                )
        return out

    def _inclusive_windows(self, eids: np.ndarray) -> dict[int, int]:
        counts: dict[int, int] = {}
        for part in self._run("inclusive_window_counts", (eids,), None):
            for e, n in part.items():
                counts[e] = counts.get(e, 0) + n
        return counts


def local_index(catalog: ECatalog, rows: pd.DataFrame, rank: np.ndarray) -> EIndex:
    """One shard holding every window, queried in this process (the local engine)."""
    shard = EShard(
        w=rows["w"].to_numpy(np.int32),
        cell=rows["cell"].to_numpy(np.int32),
        eid=rows["eid"].to_numpy(np.int32),
        vague=rows["vague"].to_numpy(bool),
        n_cells=catalog.n_cells,
        n_eids=len(catalog.eids),
        rank=rank,
    )
    return EIndex(catalog, lambda name, args, _w: [getattr(shard, name)(*args)], rank)
