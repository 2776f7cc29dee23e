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
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np
import pandas as pd

from trackctl.errors import InputError

__all__ = ["Engine", "LocalEngine", "SparkEngine", "make_engine", "SPLIT_COLUMNS", "VOTE_COLUMNS"]

SPLIT_COLUMNS = ["node", "cell", "eid"]
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
        self, eid: np.ndarray, scenario: np.ndarray, vids: Mapping[int, Sequence[str]]
    ) -> pd.DataFrame:
        """Count, per EID, how many of its evidence scenarios show each VID: ``(eid, vid, count)``
        sorted by eid, then count descending, then vid."""
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
        self, eid: np.ndarray, scenario: np.ndarray, vids: Mapping[int, Sequence[str]]
    ) -> pd.DataFrame:
        ev = pd.DataFrame({"eid": np.asarray(eid, np.int64), "s": np.asarray(scenario, np.int64)})
        keys = np.fromiter((s for s, v in vids.items() for _ in v), dtype=np.int64)
        # VIDs as integer codes: the join has one row per (evidence scenario, VID) - millions in
        # a city-size run - and strings there would cost ~60 bytes each
        codes, names = pd.factorize(
            np.array([x for v in vids.values() for x in v], dtype=object), sort=True
        )
        vdf = pd.DataFrame({"s": keys, "v": codes.astype(np.int64)})
        joined = ev.merge(vdf, on="s", how="inner")
        n = max(len(names), 1)
        key, count = np.unique(
            joined["eid"].to_numpy() * n + joined["v"].to_numpy(), return_counts=True
        )
        del joined
        counts = pd.DataFrame(
            {"eid": key // n, "vid": np.asarray(names, dtype=object)[key % n], "count": count}
        )
        return _sorted_vote(counts)

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
    """

    name = "spark"

    def __init__(self, master: str = "local[2]", partitions: int | None = None) -> None:
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
                self._session = (
                    SparkSession.builder.master(master)
                    .appName("trackctl-ev-match")
                    .config("spark.ui.enabled", "false")
                    .config("spark.ui.showConsoleProgress", "false")
                    .getOrCreate()
                )
                self._owned = True
        self.sc = self._session.sparkContext
        self.sc.setLogLevel("ERROR")
        self.partitions = partitions or self.sc.defaultParallelism

    def split(self, node: np.ndarray, eid: np.ndarray, listing: pd.DataFrame) -> pd.DataFrame:
        sc, p = self.sc, self.partitions
        # Preprocess output: the partition's sets ("P", node) and the window's scenarios
        # ("S", cell), each an EID set with a set id. Map: emit (eid, set id) for every member.
        part = sc.parallelize(
            list(zip(np.asarray(eid).tolist(), np.asarray(node).tolist(), strict=True)), p
        ).map(lambda r: (r[0], ("P", r[1])))
        scen = sc.parallelize(
            list(
                zip(
                    listing["eid"].astype(int).tolist(),
                    listing["cell"].astype(int).tolist(),
                    strict=True,
                )
            ),
            p,
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
            .collect()
        )
        df = pd.DataFrame(merged, columns=SPLIT_COLUMNS, dtype=np.int64)
        return _sorted_split(df)

    def vote(
        self, eid: np.ndarray, scenario: np.ndarray, vids: Mapping[int, Sequence[str]]
    ) -> pd.DataFrame:
        sc, p = self.sc, self.partitions
        # the V-scenarios read are shipped to every task once (a map-side join): each task
        # compares the VIDs of its EIDs' scenarios, parallel across EIDs (§3.2.4 C)
        table = sc.broadcast({int(s): tuple(v) for s, v in vids.items()})
        ev = sc.parallelize(
            list(zip(np.asarray(eid).tolist(), np.asarray(scenario).tolist(), strict=True)), p
        )
        counts = (
            ev.flatMap(lambda es: [((es[0], v), 1) for v in table.value.get(es[1], ())])
            .reduceByKey(operator.add, p)
            .map(lambda kv: (kv[0][0], kv[0][1], kv[1]))
            .collect()
        )
        table.unpersist()
        return _sorted_vote(pd.DataFrame(counts, columns=VOTE_COLUMNS))

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


def make_engine(name: str, master: str | None = None) -> Engine:
    """``local`` or ``spark`` (with ``master``, default ``local[2]``).

    Raises:
        InputError: unknown engine, or pyspark missing.
    """
    if name == "local":
        return LocalEngine()
    if name == "spark":
        return SparkEngine(master or "local[2]")
    raise InputError(f"--engine {name!r}: expected local or spark")
