"""Execution engines for the data-parallel steps of EV-Matching.

The matcher (:mod:`trackctl.evmatch.matcher`) drives the algorithm; an engine runs its three bulk
steps. Both engines return the same rows in the same (sorted) order, so the matcher's decisions,
and therefore the matches, are identical whichever engine ran them.

* ``split`` - one iteration of EID set splitting (dissertation Algorithm 3): the current partition
  and the selected E-scenarios of one window are EID sets; **map** emits ``(eid, set id)``, the
  shuffle groups by EID, **reduce** emits ``(set ids, eid)``, and **merge** groups EIDs by their
  set-id list: each group is one set of the new partition.
* ``vote`` - VID filtering, parallel across EIDs: for every (EID, evidence scenario) pair, the VIDs
  of the scenario's V-scenario are counted per EID.
* ``edp_select`` - the EDP baseline's per-EID scenario selection, one task per EID.
"""

from __future__ import annotations

import operator
import os
import sys
import warnings
from collections.abc import Callable, Collection, Mapping, Sequence
from typing import Any, Protocol

import numpy as np
import pandas as pd

from trackctl.errors import InputError

__all__ = ["Engine", "LocalEngine", "SparkEngine", "make_engine", "SPLIT_COLUMNS", "VOTE_COLUMNS"]

SPLIT_COLUMNS = ["node", "cell", "eid"]
TOP_VIDS = 2  # VID filtering needs the best VID and the runner-up
VOTE_CHUNK = 4_000_000  # (EID, VID) rows counted at a time by the local engine
VOTE_COLUMNS = ["eid", "vid", "count"]


class Engine(Protocol):
    """The bulk steps of EV-Matching."""

    name: str

    def split(self, node: np.ndarray, eid: np.ndarray, listing: pd.DataFrame) -> pd.DataFrame:
        """Split partition rows ``(node, eid)`` by one window's scenarios ``listing (eid, cell)``.

        Returns rows ``(node, cell, eid)`` sorted by all three; ``cell`` is -1 for an EID in no
        selected scenario; an EID listed in several cells (vague) gets one row per cell.
        """
        ...

    def vote(
        self,
        eid: np.ndarray,
        scenario: np.ndarray,
        vids: Mapping[int, Sequence[str]],
        exclude: Collection[str] = (),
        top: int = TOP_VIDS,
    ) -> pd.DataFrame:
        """Count, per EID, how many of its evidence scenarios show each VID not in ``exclude``,
        and keep the ``top`` VIDs per EID: ``(eid, vid, count)`` sorted by eid, then count
        descending, then vid."""
        ...

    def edp_select(
        self, targets: Sequence[int], select: Callable[[int], list[int]]
    ) -> list[list[int]]:
        """Run the per-EID baseline selection ``select`` for every target (in order)."""
        ...

    def close(self) -> None:
        """Release resources."""
        ...


def _sorted_split(df: pd.DataFrame) -> pd.DataFrame:
    return df.sort_values(SPLIT_COLUMNS, kind="stable").reset_index(drop=True)[SPLIT_COLUMNS]


def top_votes(df: pd.DataFrame, top: int) -> pd.DataFrame:
    """The first ``top`` rows per EID of a sorted vote table."""
    return df.groupby("eid", sort=False).head(top).reset_index(drop=True)


def _sorted_vote(df: pd.DataFrame) -> pd.DataFrame:
    if df.empty:
        return pd.DataFrame({"eid": [], "vid": [], "count": []}).astype(
            {"eid": np.int64, "vid": object, "count": np.int64}
        )
    df = df.astype({"eid": np.int64, "count": np.int64})
    df = df.sort_values(["eid", "count", "vid"], ascending=[True, False, True], kind="stable")
    return df.reset_index(drop=True)[VOTE_COLUMNS]


class LocalEngine:
    """In-process engine: pandas joins and group-bys (vectorised, no Python loop per EID)."""

    name = "local"

    def split(self, node: np.ndarray, eid: np.ndarray, listing: pd.DataFrame) -> pd.DataFrame:
        part = pd.DataFrame({"node": np.asarray(node, np.int64), "eid": np.asarray(eid, np.int64)})
        lst = listing[["eid", "cell"]].astype(np.int64)
        # the join is the shuffle on EID; (node, cell) is each EID's signature = its new set
        out = part.merge(lst, on="eid", how="left")
        out["cell"] = out["cell"].fillna(-1).astype(np.int64)
        return _sorted_split(out)

    def vote(
        self,
        eid: np.ndarray,
        scenario: np.ndarray,
        vids: Mapping[int, Sequence[str]],
        exclude: Collection[str] = (),
        top: int = TOP_VIDS,
    ) -> pd.DataFrame:
        # VIDs as integer codes in name order, each scenario's VIDs as a range of one flat array
        # (CSR); the (EID, VID) rows are counted a few million at a time, EIDs never split
        # across chunks, and only each EID's top VIDs are kept: a city's evidence expands to
        # tens of millions of rows
        keys = np.fromiter(vids.keys(), dtype=np.int64, count=len(vids))
        lens = np.fromiter((len(v) for v in vids.values()), dtype=np.int64, count=len(vids))
        codes, names = pd.factorize(
            np.array([x for v in vids.values() for x in v], dtype=object), sort=True
        )
        names = np.asarray(names, dtype=object)
        starts = np.r_[0, np.cumsum(lens)[:-1]] if len(lens) else lens
        by_key = np.argsort(keys)
        keys, lens, starts = keys[by_key], lens[by_key], starts[by_key]
        # a set lookup per name: np.isin on object arrays compares every pair
        banned = exclude if isinstance(exclude, set | frozenset) else set(exclude)
        drop = np.fromiter((x in banned for x in names), bool, count=len(names))
        e = np.asarray(eid, np.int64)
        sc = np.asarray(scenario, np.int64)
        order = np.argsort(e, kind="stable")
        e, sc = e[order], sc[order]
        i = np.searchsorted(keys, sc)
        found = (i < len(keys)) & (keys[np.minimum(i, max(len(keys) - 1, 0))] == sc)
        e, i = e[found], i[found]
        n_per = lens[i] if len(i) else np.zeros(0, np.int64)
        parts = []
        lo = 0
        while lo < len(e):
            # the chunk ends at an EID boundary once VOTE_CHUNK rows are reached
            cum = np.cumsum(n_per[lo:])
            hi = lo + int(np.searchsorted(cum, VOTE_CHUNK, side="right")) + 1
            hi = min(max(hi, lo + 1), len(e))
            while hi < len(e) and e[hi] == e[hi - 1]:
                hi += 1
            parts.append(self._count(e[lo:hi], starts[i[lo:hi]], n_per[lo:hi], codes, drop, top))
            lo = hi
        if not parts:
            return _sorted_vote(pd.DataFrame(columns=VOTE_COLUMNS))
        counts = pd.concat(parts, ignore_index=True)
        counts["vid"] = names[counts["vid"].to_numpy(np.int64)]
        return counts[VOTE_COLUMNS]

    @staticmethod
    def _count(
        e: np.ndarray,
        start: np.ndarray,
        n: np.ndarray,
        codes: np.ndarray,
        drop: np.ndarray,
        top: int,
    ) -> pd.DataFrame:
        """Top ``top`` VID codes per EID for pairs whose scenarios' VIDs are
        ``codes[start:start+n]`` (code order = name order, so ties go to the smaller VID)."""
        rep = np.repeat(e, n)
        offsets = np.arange(len(rep)) - np.repeat(np.cumsum(n) - n, n)
        v = codes[np.repeat(start, n) + offsets].astype(np.int64)
        keep = ~drop[v]
        rep, v = rep[keep], v[keep]
        n_v = max(len(drop), 1)
        key, count = np.unique(rep * n_v + v, return_counts=True)
        ce, cv = key // n_v, key % n_v
        order = np.lexsort((cv, -count, ce))
        df = pd.DataFrame({"eid": ce[order], "vid": cv[order], "count": count[order]})
        return top_votes(df, top)

    def edp_select(
        self, targets: Sequence[int], select: Callable[[int], list[int]]
    ) -> list[list[int]]:
        return [select(int(t)) for t in targets]

    def close(self) -> None:
        pass


class SparkEngine:
    """Apache Spark engine (pyspark): the same steps as RDD map / groupByKey / reduceByKey.

    Args:
        master: Spark master URL (``local[N]`` or a cluster URL).
        partitions: RDD partitions per step (default: the context's default parallelism).
        conf: Spark properties for a new session (``spark.driver.memory``, ...), as
            ``spark-submit --conf`` takes them.
    """

    name = "spark"

    def __init__(
        self,
        master: str = "local[2]",
        partitions: int | None = None,
        conf: Mapping[str, str] | None = None,
    ) -> None:
        with warnings.catch_warnings():
            # pyspark warns about pandas >= 3 for its pandas API, which trackctl does not use
            warnings.filterwarnings("ignore", message=".*pandas >= 3.*")
            try:
                from pyspark.sql import SparkSession
            except ImportError as err:
                raise InputError(
                    "--engine spark needs pyspark (and Java 17+): pip install 'trackctl[spark]'"
                ) from err
            active = SparkSession.getActiveSession()
            if active is not None and active.sparkContext.master == master:
                self._session = active
                self._owned = False
            else:
                builder = (
                    SparkSession.builder.master(master)
                    .appName("trackctl-ev-match")
                    .config("spark.ui.enabled", "false")
                    .config("spark.ui.showConsoleProgress", "false")
                )
                if master.startswith("local") and "spark.pyspark.python" not in (conf or {}):
                    # local workers run this interpreter: the `python3` on PATH (what pyspark
                    # starts otherwise) may be one without numpy and pandas when trackctl runs
                    # from a virtual environment that is not activated. pyspark reads the
                    # worker's interpreter from the environment when the context starts.
                    os.environ.setdefault("PYSPARK_PYTHON", sys.executable)
                for key, value in (conf or {}).items():
                    builder = builder.config(key, value)
                self._session = builder.getOrCreate()
                self._owned = True
        self.sc = self._session.sparkContext
        self.sc.setLogLevel("ERROR")
        self.partitions = partitions or self.sc.defaultParallelism

    def split(self, node: np.ndarray, eid: np.ndarray, listing: pd.DataFrame) -> pd.DataFrame:
        sc, p = self.sc, self.partitions
        # Preprocess output: the partition's sets ("P", node) and the window's scenarios
        # ("S", cell), each an EID set with a set id. Map: emit (eid, set id) for every member.
        part = pairs_rdd(sc, eid, node, p).map(lambda r: (r[0], ("P", r[1])))
        scen = pairs_rdd(
            sc, listing["eid"].to_numpy(np.int64), listing["cell"].to_numpy(np.int64), p
        ).map(lambda r: (r[0], ("S", r[1])))

        def reduce_eid(item: tuple[int, Any]) -> list[tuple[tuple[int, int], int]]:
            # Reduce: one EID with all its set ids -> (set-id list, eid); an EID listed in several
            # cells (vague zone) goes to each of them, one not in the partition is dropped.
            e, ids = item
            nodes = sorted(i for kind, i in ids if kind == "P")
            cells = sorted({i for kind, i in ids if kind == "S"}) or [-1]
            return [((n, c), e) for n in nodes for c in cells]

        merged = (
            part.union(scen)
            .groupByKey(p)
            .flatMap(reduce_eid)
            .groupByKey(p)  # Merge: (set ids, EIDs) -> one set of the new partition
            .flatMap(lambda kv: [(kv[0][0], kv[0][1], e) for e in kv[1]])
        )
        return _sorted_split(collect_columns(merged, SPLIT_COLUMNS, (np.int64,) * 3))

    def vote(
        self,
        eid: np.ndarray,
        scenario: np.ndarray,
        vids: Mapping[int, Sequence[str]],
        exclude: Collection[str] = (),
        top: int = TOP_VIDS,
    ) -> pd.DataFrame:
        sc, p = self.sc, self.partitions
        # the V-scenarios read are shipped to every task once (a map-side join): each task
        # compares the VIDs of its EIDs' scenarios, parallel across EIDs (§3.2.4 C)
        table = sc.broadcast({int(s): tuple(v) for s, v in vids.items()})
        ev = pairs_rdd(sc, eid, scenario, p)
        pairs = ev.flatMap(lambda es: [((es[0], v), 1) for v in table.value.get(es[1], ())])
        counts = top_per_eid(pairs, p, exclude, top)
        table.unpersist()
        return _sorted_vote(counts)

    def edp_select(
        self, targets: Sequence[int], select: Callable[[int], list[int]]
    ) -> list[list[int]]:
        # one task per EID, as the paper adapts EDP to MapReduce; keys keep the input order
        rdd = self.sc.parallelize(list(enumerate(int(t) for t in targets)), self.partitions)
        out = rdd.map(lambda kv: (kv[0], select(kv[1]))).collect()
        return [sel for _, sel in sorted(out)]

    def close(self) -> None:
        if self._owned:
            self._session.stop()


def pairs_rdd(sc: Any, a: np.ndarray, b: np.ndarray, partitions: int) -> Any:
    """An RDD of ``(int, int)`` pairs shipped as numpy blocks (a Python tuple per pair on the
    driver would cost ~100 bytes each: a city's evidence has millions)."""
    block = np.stack([np.asarray(a, np.int64), np.asarray(b, np.int64)], axis=1)
    parts = np.array_split(block, max(partitions, 1)) if len(block) else [block]
    return sc.parallelize(parts, len(parts)).flatMap(
        lambda arr: zip(arr[:, 0].tolist(), arr[:, 1].tolist(), strict=True)
    )


def collect_columns(rdd: Any, columns: Sequence[str], dtypes: Sequence[Any]) -> pd.DataFrame:
    """Collect an RDD of tuples as one numpy column block per partition (not a list of tuples
    on the driver)."""

    def block(it: Any) -> list[list[np.ndarray]]:
        rows = list(it)
        return [[np.array([r[i] for r in rows], dtype=dt) for i, dt in enumerate(dtypes)]]

    blocks = rdd.mapPartitions(block).collect()
    return pd.DataFrame(
        {
            name: np.concatenate([b[i] for b in blocks]) if blocks else np.zeros(0, dt)
            for i, (name, dt) in enumerate(zip(columns, dtypes, strict=True))
        }
    )


def top_per_eid(pairs: Any, partitions: int, exclude: Collection[str], top: int) -> pd.DataFrame:
    """``((eid, vid), 1)`` records summed, then each EID's ``top`` VIDs outside ``exclude``
    (count descending, then VID), on the executors; returns ``(eid, vid, count)`` columns."""
    banned = frozenset(exclude)

    def best(item: tuple[int, Any]) -> list[tuple[int, str, int]]:
        e, vc = item
        ranked = sorted((v for v in vc if v[0] not in banned), key=lambda x: (-x[1], x[0]))
        return [(e, v, c) for v, c in ranked[:top]]

    ranked = (
        pairs.reduceByKey(operator.add, partitions)
        .map(lambda kv: (kv[0][0], (kv[0][1], kv[1])))
        .groupByKey(partitions)
        .flatMap(best)
    )
    return collect_columns(ranked, VOTE_COLUMNS, (np.int64, object, np.int64))


def make_engine(
    name: str, master: str | None = None, conf: Mapping[str, str] | None = None
) -> Engine:
    """``local`` or ``spark`` (with ``master``, default ``local[2]``, and Spark ``conf``).

    Raises:
        InputError: unknown engine, or pyspark missing.
    """
    if name == "local":
        return LocalEngine()
    if name == "spark":
        return SparkEngine(master or "local[2]", conf=conf)
    raise InputError(f"--engine {name!r}: expected local or spark")
